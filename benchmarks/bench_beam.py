#!/usr/bin/env python
"""Cost per step of beam links against their element count (issue 6).

    python benchmarks/bench_beam.py            # about 1 min on 2 cores
    python benchmarks/bench_beam.py --quick    # about 15 s: fewer repeats, shorter runs
    python benchmarks/bench_beam.py --doc      # also write the section 'bench_beam' of docs/beam_vs_prbm.md

`popup-lab`, 2 kg, torque-driven (holding torques), one run on one thread
(``Model.simulate``), for the PRBM (n = 0), link 2 a beam of n = 1..6 elements (link 1
PRBM) and both links beams of n = 1..3 elements each (the chain holds at most 31 joints:
3 motors + 4 per element), with RK4 and with the semi-implicit integrator. Beam material:
the thesis's 0.557 GPa / 1.2 mm / λ = 3.896e-4 s.

Cost per step = (t(2N steps) − t(N steps)) / N, each time the best of R repeats (repeats
go round all rows in turn), so the fixed cost of a call (rest state, step check, Python
wrapper) drops out. t is the CPU time of the calling thread (``time.thread_time``: a
single run executes on it), which a shared machine's load does not inflate by the time
spent waiting for a core; the wall clock (``time.perf_counter``) is printed beside it. The cost does not depend on dt; each
row runs at a dt its integrator accepts (the largest the step check allows, at most 0.1
ms), with output only at the start and the end. Then a least-squares line
cost = a + b·(elements) per family, its R² and the largest relative deviation from it.
Prints everything and asserts nothing.
"""

from __future__ import annotations

import argparse
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
import math
import platform
import sys
import time
from typing import Dict, List, Tuple

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import popup  # noqa: E402
from machine import cpu_model, load_str, ncores  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "beam_vs_prbm.md")


def stable_dt(model: popup.Model, dt_max: float = 1e-4) -> float:
    """The largest round dt <= dt_max the step check accepts at rest (10 % margin)."""
    stable = model.stable_dt()
    if stable >= model.dt:
        return dt_max
    lim = 0.9 * stable
    # a "round" step: 1, 2 or 5 × 10^k below the limit
    k = math.floor(math.log10(lim))
    for mant in (5, 2, 1):
        if mant * 10**k <= lim:
            return float(mant * 10**k)
    return float(10**k)


def build(elements: Tuple[int, int], integrator: str) -> popup.Model:
    def mk(dt: float) -> popup.Model:
        m = popup.Model("popup-lab", payload_kg=2.0, dt=dt, integrator=integrator)
        if any(elements):
            m = m.with_effect("higher_bending_modes", elements=list(elements))
        return m

    m = mk(1e-4)
    dt = stable_dt(m)
    return m if dt == 1e-4 else mk(dt)


def line_fit(x: np.ndarray, y: np.ndarray) -> Tuple[float, float, float, float]:
    b, a = np.polyfit(x, y, 1)
    pred = a + b * x
    ss = float(np.sum((y - y.mean()) ** 2))
    r2 = 1.0 - float(np.sum((y - pred) ** 2)) / ss if ss > 0 else 1.0
    dev = float(np.max(np.abs(y - pred) / y))
    return float(a), float(b), r2, dev


def main(argv: List[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="3 repeats, 5k steps")
    ap.add_argument("--doc", action="store_true", help="write the section 'bench_beam' of docs/beam_vs_prbm.md")
    a = ap.parse_args(argv)
    reps = 3 if a.quick else 5
    nsteps = 5_000 if a.quick else 20_000
    t0 = time.perf_counter()
    print("=" * 96)
    print("popup beam links: cost per step vs element count")
    print("=" * 96)
    print(f"date     : {time.strftime('%Y-%m-%d %H:%M:%S')}")
    print(f"CPU      : {cpu_model()}")
    print(f"cores    : {ncores()} usable")
    print(f"load     : {load_str()}  (at the start)")
    print(f"platform : {platform.platform()}; Python {platform.python_version()}")
    print(f"popup    : {popup.__version__} (build_profile={popup.build_profile})")
    print(f"method   : cost/step = (t(2N) − t(N))/N, N = {nsteps} steps, best of {reps}; torque-driven, 2 kg, one thread")
    print("           t = CPU time of the calling thread (the run executes on it); the wall clock is printed beside it")

    rows_spec = [("PRBM", (0, 0))] + [(f"link 2 beam({n})", (0, n)) for n in range(1, 7)] + [(f"both beam({n})", (n, n)) for n in range(1, 4)]
    integrators = ["rk4", "semi_implicit"]
    models: Dict[Tuple[str, str], popup.Model] = {}
    for name, el in rows_spec:
        for integ in integrators:
            models[(name, integ)] = build(el, integ)
    best: Dict[Tuple[str, str, int], float] = {}
    best_cpu: Dict[Tuple[str, str, int], float] = {}
    for _ in range(reps):
        for key, m in models.items():
            tau = m.holding_torque()
            for mult in (1, 2):
                dur = mult * nsteps * m.dt
                s = time.perf_counter()
                c = time.thread_time()
                m.simulate(tau, duration=dur, sample_rate=1.0 / dur)
                ec = time.thread_time() - c
                e = time.perf_counter() - s
                k = (key[0], key[1], mult)
                best[k] = min(best.get(k, math.inf), e)
                best_cpu[k] = min(best_cpu.get(k, math.inf), ec)
    wall: Dict[Tuple[str, str], float] = {}
    res: Dict[Tuple[str, str], float] = {}
    for key in models:
        wall[key] = (best[(key[0], key[1], 2)] - best[(key[0], key[1], 1)]) / nsteps
        res[key] = (best_cpu[(key[0], key[1], 2)] - best_cpu[(key[0], key[1], 1)]) / nsteps

    print()
    print("cost per step: CPU time of the calling thread (time.thread_time; the run executes on it), and in brackets")
    print("the wall clock (time.perf_counter), which on a shared machine also counts the time spent waiting for a core")
    hdr = f"{'model':<16} {'elements':>8} {'nv':>4}" + "".join(f" | {i + ' dt':>16} {'µs/step':>8} {'(wall)':>8} {'steps/s':>10}" for i in integrators)
    print(hdr)
    print("-" * len(hdr))
    table_md = ["| model | elements | joints nv | " + " | ".join(f"{i}: dt | µs/step (wall) | steps/s | CPU s per simulated s" for i in integrators) + " |",
                "|---|---|---|" + "---|---|---|---|" * len(integrators)]
    for name, el in rows_spec:
        nv = len(models[(name, integrators[0])].joint_names)
        line = f"{name:<16} {sum(el):>8} {nv:>4}"
        cells = [name, str(sum(el)), str(nv)]
        for integ in integrators:
            c = res[(name, integ)]
            w = wall[(name, integ)]
            dt = models[(name, integ)].dt
            line += f" | {dt:>16.3g} {c * 1e6:>8.2f} {w * 1e6:>8.2f} {1 / c:>10.3g}"
            cells += [f"{dt:.3g} s", f"{c * 1e6:.2f} ({w * 1e6:.2f})", f"{1 / c / 1e3:.1f} k", f"{c / dt:.3g}"]
        print(line)
        table_md.append("| " + " | ".join(cells) + " |")

    print()
    print("linear fit cost = a + b·elements (µs), R², largest |relative deviation| from the line;")
    print("quadratic fit a + b·n + c·n² (R²), and the exponent p of cost ∝ nv^p (log-log fit over the joint count nv)")
    fits: Dict[Tuple[str, str], Tuple[float, float, float, float, float, float, float]] = {}
    fit_md = ["| family | integrator | a [µs] | b [µs / element] | R² (line) | max deviation from the line | R² (quadratic), c [µs/element²] | p in cost ∝ nv^p |",
              "|---|---|---|---|---|---|---|---|"]
    for fam, names in (("link 2 beam(n), n = 0..6", ["PRBM"] + [f"link 2 beam({n})" for n in range(1, 7)]),
                       ("both beam(n), total 2n = 0..6", ["PRBM"] + [f"both beam({n})" for n in range(1, 4)])):
        xel = np.array([sum(dict(rows_spec)[n]) for n in names], dtype=float)
        for integ in integrators:
            y = np.array([res[(n, integ)] for n in names]) * 1e6
            a_, b_, r2, dev = line_fit(xel, y)
            # the same with the beams only (n >= 1), the PRBM row has another code path
            a1, b1, r21, dev1 = line_fit(xel[1:], y[1:])
            c2 = np.polyfit(xel, y, 2)
            pred2 = np.polyval(c2, xel)
            r2q = 1.0 - float(np.sum((y - pred2) ** 2)) / float(np.sum((y - y.mean()) ** 2))
            nvs = np.array([len(models[(n, integ)].joint_names) for n in names], dtype=float)
            pexp = float(np.polyfit(np.log(nvs), np.log(y), 1)[0])
            print(f"  {fam:<32} {integ:<14} a = {a_:6.2f}  b = {b_:5.2f}  R² = {r2:.4f}  max dev {dev * 100:4.1f} %   "
                  f"(beams only: a = {a1:.2f}, b = {b1:.2f}, R² = {r21:.4f}, max dev {dev1 * 100:.1f} %); "
                  f"quadratic R² = {r2q:.4f}, c = {c2[0]:.3f}; p = {pexp:.2f}")
            fits[(fam, integ)] = (a_, b_, r2, r2q, float(c2[0]), pexp, dev1)
            fit_md.append(f"| {fam} | {integ} | {a_:.2f} | {b_:.2f} | {r2:.4f} | {dev * 100:.1f} % (beams only: b = {b1:.2f}, R² = {r21:.4f}, {dev1 * 100:.1f} %) "
                          f"| {r2q:.4f}, {c2[0]:.3f} | {pexp:.2f} |")
    secs = time.perf_counter() - t0
    print()
    print(f"load     : {load_str()}  (at the end); {secs:.0f} s")
    if a.doc:
        md = [
            "## Cost per step vs element count\n",
            f"Generated by `python benchmarks/bench_beam.py --doc` ({time.strftime('%Y-%m-%d')}, {secs:.0f} s; {cpu_model()}, "
            f"{ncores()} cores, shared: load average {', '.join(f'{x:.1f}' for x in os.getloadavg())} at the end; "
            f"popup {popup.__version__} {popup.build_profile}). `popup-lab`, 2 kg, torque-driven with holding torques, one run, "
            f"one thread; cost per step = (t(2N) − t(N))/N with N = {nsteps}, best of {reps}, t the CPU time of the calling "
            f"thread (`time.thread_time`; wall clock `time.perf_counter` in brackets); the dt of each row is the largest "
            f"round step ≤ 0.1 ms its integrator accepts (the cost per step does not depend on it). Material 0.557 GPa / "
            f"1.2 mm / λ = 3.896e-4 s.\n",
        ]
        md += table_md
        md.append("")
        md += fit_md
        md.append("")
        fam = "link 2 beam(n), n = 0..6"
        a_r, b_r, r2_r, r2q_r, c_r, p_r, dev_r = fits[(fam, "rk4")]
        a_s, b_s, r2_s, r2q_s, c_s, p_s, dev_s = fits[(fam, "semi_implicit")]
        n6 = "link 2 beam(6)"
        md.append(
            f"**Reading.** RK4 steps an arm with beam links by the articulated-body algorithm "
            f"(`popup_core::dynamics::articulated`, O(nv)): each element adds {b_r:.1f} µs per step, a line fits the beam "
            f"rows with R² = {r2_r:.3f} overall (beams only: largest deviation {dev_r * 100:.1f} %), cost ∝ nv^{p_r:.2f}; "
            f"what curvature is left (c = {c_r:.2f} µs per element²) is the dense beam-force blocks K_φφ + C_φφ̇, "
            f"O(dof²) per link (`cargo run --release -p popup-core --example step_cost` breaks a step down into the "
            f"solver, the beam forces, CRBA and Cholesky, and fits the solver alone against nv). The "
            f"semi-implicit step solves (M + h C) with the dense Rayleigh block C_φ, which no O(nv) recursion takes, so "
            f"it stays on CRBA + Cholesky: {b_s:.2f} µs per element in a line (R² = {r2_s:.3f}, quadratic R² = "
            f"{r2q_s:.4f}), nv^{p_s:.2f}. Per simulated second the integrators differ more than per step, because "
            f"explicit RK4 must shrink dt with the element count (stiffness-proportional damping makes the top "
            f"finite-element modes stiff): link 2 beam(6) costs {res[(n6, 'rk4')] / models[(n6, 'rk4')].dt:.2f} s of CPU "
            f"per simulated second with RK4 at {models[(n6, 'rk4')].dt:.3g} s against "
            f"{res[(n6, 'semi_implicit')] / models[(n6, 'semi_implicit')].dt:.3f} s semi-implicit at "
            f"{models[(n6, 'semi_implicit')].dt:.3g} s.\n"
        )
        popup.report.write_section(DOC, "bench_beam", "\n".join(md) + "\n")
        print(f"wrote section 'bench_beam' of {os.path.relpath(DOC, ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
