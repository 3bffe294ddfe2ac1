"""Speed and memory of set-membership identification on the thesis's problem (issue 9).

The thesis (chapter 3) identified the end-effector x of the arm from q2, q̇2, q3, q̇3 as a
black box: four second-order transfer functions G1..G4, output error |ε(t)| <= 5 mm,
solved with SparsePOP (convex relaxations of the polynomial problem) and ran out of
memory after hours, even for the simplified problem. Here the same problem on N samples
of a PRBM simulation of popup-lab (encoder replay of a multisine of q2 and q3 about the
lab pose, 100 Hz, payload 1 kg, ±1 mm uniform sensor noise on x), for growing N:

* ``OE``  — the thesis's structure, :func:`popup.setmembership.oe_pui` (equation-error
  start, sequential-LP denominator, exact numerator LPs, first-order joint intervals);
* ``ARX`` — the equation-error structure of the same orders, exact PUI (2p + 2 LPs).

Every N runs in a fresh process so that its peak resident memory (``ru_maxrss``) is its
own; ``RSS`` is the process's peak resident set, ``ΔRSS`` its growth during the timed
identification (HiGHS's own C++ memory shows only there), ``traced`` the peak of
Python/NumPy allocations (tracemalloc) in a second, untimed pass (tracemalloc slows
allocation-heavy code several-fold, so the times come from the first pass). Target: N = 2000 in under a
minute on 2 cores. Prints everything, asserts nothing::

    python benchmarks/bench_setmembership.py                       # N = 250 ... 4000
    python benchmarks/bench_setmembership.py --sizes 2000 --threads 1
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
import tracemalloc

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from machine import cpu_model, load_str, ncores  # noqa: E402


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: kB


def one(n: int, a: argparse.Namespace) -> dict:
    import numpy as np

    import popup
    from popup import setmembership as sm

    t0 = time.perf_counter()
    model = popup.Model("popup-lab", payload_kg=1.0)
    t, q = sm.multisine(n, a.rate, amplitude=a.amplitude, f_max=a.fmax, seed=a.seed)
    res = model.replay(t, q, sample_rate=a.rate)
    d = sm.iddata(res, "ee_x", sm.THESIS_INPUTS)
    d.y = d.y + np.random.default_rng(a.seed + 1).uniform(-a.noise_mm * 1e-3, a.noise_mm * 1e-3, len(d))
    t_sim = time.perf_counter() - t0
    rss0 = _rss_mb()
    out: dict = {"n": n, "sim_s": t_sim, "rss_before_mb": rss0}
    threads = a.threads or None

    arx = sm.arx(2, 2, 0, inputs=sm.THESIS_INPUTS, output="ee_x", offset=True)
    s = sm.oe(nb=2, nf=2, nk=0, inputs=sm.THESIS_INPUTS, output="ee_x")

    def run_arx() -> dict:
        t0 = time.perf_counter()
        try:
            r = sm.pui(d, arx, a.eps, threads=threads)
            return {"s": time.perf_counter() - t0, "lps": r.n_lp, "eps_min": r.eps_min, "feasible": True}
        except sm.InfeasibleError as e:
            return {"s": time.perf_counter() - t0, "lps": 1, "eps_min": e.eps_min, "feasible": False}

    def run_oe() -> dict:
        t0 = time.perf_counter()
        try:
            r = sm.oe_pui(d, s, a.eps, threads=threads)
            return {"s": time.perf_counter() - t0, "lps": r.n_lp, "eps_min": r.eps_min, "feasible": True,
                    "iterations": len(r.iterations) - 1, "threads": r.threads,
                    "c": list(r.intervals["c"]), "f_q2_1": list(r.intervals["f_q2_1"]),
                    "b_q2_0": list(r.intervals["b_q2_0"]),
                    "cond_b_q2_0": [float(r.conditional.lower[0]), float(r.conditional.upper[0])],
                    "unbounded": int(np.sum(~np.isfinite(r.width)))}
        except sm.InfeasibleError as e:
            return {"s": time.perf_counter() - t0, "lps": -1, "eps_min": e.eps_min, "feasible": False}

    # timed pass (tracemalloc slows allocation-heavy code several-fold: not on here)
    out["arx"] = run_arx()
    out["oe"] = run_oe()
    out["rss_peak_mb"] = _rss_mb()
    # memory pass: the peak of Python/NumPy allocations
    traced = 0.0
    if not a.no_traced:
        for f in (run_arx, run_oe):
            tracemalloc.start()
            f()
            traced = max(traced, tracemalloc.get_traced_memory()[1] / 2**20)
            tracemalloc.stop()
    out["traced_mb"] = traced
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="250,500,1000,2000,4000", help="comma-separated N")
    ap.add_argument("--eps", type=float, default=0.005, help="output-error bound [m] (thesis: 5 mm)")
    ap.add_argument("--threads", type=int, default=0, help="LP threads (0: every core)")
    ap.add_argument("--rate", type=float, default=100.0, help="sample rate [Hz]")
    ap.add_argument("--amplitude", type=float, default=0.05, help="multisine peak per joint [rad]")
    ap.add_argument("--fmax", type=float, default=1.0, help="highest multisine frequency [Hz]")
    ap.add_argument("--noise-mm", type=float, default=1.0, help="uniform sensor noise on x, ± [mm]")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-traced", action="store_true", help="skip the tracemalloc pass (half the run time)")
    ap.add_argument("--one", type=int, default=0, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.one:
        print(json.dumps(one(a.one, a)))
        return
    import popup
    import scipy

    print(f"machine: {cpu_model()}, {ncores()} usable cores; {load_str()}")
    print(f"popup {popup.__version__} ({popup.build_profile}), scipy {scipy.__version__} (HiGHS via linprog), python {sys.version.split()[0]}")
    print(f"problem: x (ee_x) from q2, dq2, q3, dq3 of popup-lab (PRBM, encoder replay, multisine {a.amplitude} rad up to "
          f"{a.fmax} Hz, {a.rate:g} Hz, +-{a.noise_mm} mm noise), bound {a.eps * 1e3:g} mm; LP threads {a.threads or 'all'}")
    print()
    hdr = (f"{'N':>6} | {'sim s':>6} | {'ARX s':>6} {'LPs':>4} {'eps_min mm':>10} | {'OE s':>6} {'iters':>5} {'LPs':>4} "
           f"{'eps_min mm':>10} {'feasible':>8} | {'traced MB':>9} | {'RSS MB':>7} {'dRSS MB':>7}")
    print(hdr)
    print("-" * len(hdr))
    rows = []
    for n in [int(x) for x in a.sizes.split(",") if x.strip()]:
        cmd = [sys.executable, os.path.abspath(__file__), "--one", str(n)] + [
            f"--eps={a.eps}", f"--threads={a.threads}", f"--rate={a.rate}", f"--amplitude={a.amplitude}",
            f"--fmax={a.fmax}", f"--noise-mm={a.noise_mm}", f"--seed={a.seed}"] + (["--no-traced"] if a.no_traced else [])
        p = subprocess.run(cmd, capture_output=True, text=True)
        if p.returncode != 0:
            print(f"{n:>6} | failed: {p.stderr.strip().splitlines()[-1] if p.stderr.strip() else p.returncode}")
            continue
        r = json.loads(p.stdout.strip().splitlines()[-1])
        rows.append(r)
        ar, o = r["arx"], r["oe"]
        traced = r["traced_mb"]
        print(f"{n:>6} | {r['sim_s']:6.2f} | {ar['s']:6.2f} {ar['lps']:>4} {ar['eps_min'] * 1e3:10.4f} | {o['s']:6.2f} "
              f"{o.get('iterations', '-'):>5} {o['lps']:>4} {o['eps_min'] * 1e3:10.4f} {str(o['feasible']):>8} | {traced:9.1f} | "
              f"{r['rss_peak_mb']:7.0f} {r['rss_peak_mb'] - r['rss_before_mb']:7.0f}")
    print()
    for r in rows:
        o = r["oe"]
        if o["feasible"]:
            print(f"N = {r['n']}: OE c in [{o['c'][0]:.5f}, {o['c'][1]:.5f}] m, f_q2_1 in [{o['f_q2_1'][0]:.4g}, {o['f_q2_1'][1]:.4g}], "
                  f"b_q2_0 in [{o['b_q2_0'][0]:.4g}, {o['b_q2_0'][1]:.4g}] (given F^: [{o['cond_b_q2_0'][0]:.4g}, "
                  f"{o['cond_b_q2_0'][1]:.4g}]); {o['unbounded']} unbounded")
    print(f"\n{load_str()} (at the end)")


if __name__ == "__main__":
    main()
