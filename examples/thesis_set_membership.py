"""The thesis's set-membership identification (chapter 3), end to end, and a Monte Carlo
check of the output-error scheme where the truth is known.

The thesis identified the end-effector x of the arm from q2, q̇2, q3, q̇3 as a black box:
four second-order transfer functions G1..G4 with a bounded output error |ε(t)| <= 5 mm,
solved with SparsePOP (convex relaxations of the polynomial problem): "Out of memory"
after hours, even for the simplified problem. Here (``docs/setmembership.md``):

A. the thesis's problem on a PRBM simulation of popup-lab (encoder replay of a multisine
   of q2 and q3 about the lab pose, 100 Hz, 20 s = 2000 samples, ±1 mm uniform sensor
   noise on x): the output-error intervals at 5 mm and at tighter bounds, the exact ARX
   intervals of the same orders, and what an impossible bound (below the noise) says;
B. a Monte Carlo check on simulated output-error data with a known truth (two inputs,
   second-order G's, uniform noise): coverage of the truth and interval widths against
   the spread of the estimates, over many noise realisations.

Run from the repository root (1 to 1.5 min on 2 cores; plots go to ``out/``)::

    python examples/thesis_set_membership.py [--runs 50] [--quick]
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np
from scipy.signal import lfilter

import popup
from popup import setmembership as sm

OUT = "out"


def part_a(n: int) -> None:
    print(f"== A. the thesis's problem: x from q2, dq2, q3, dq3 ({n} samples of a PRBM simulation)")
    model = popup.Model("popup-lab", payload_kg=1.0)
    t, q = sm.multisine(n, 100.0, amplitude=0.05, f_max=1.0, seed=0)
    t0 = time.perf_counter()
    res = model.replay(t, q, sample_rate=100.0)
    print(f"simulation: {len(res)} samples at 100 Hz in {time.perf_counter() - t0:.2f} s; "
          f"x spans [{res.channel('ee_x').min():.4f}, {res.channel('ee_x').max():.4f}] m")
    data = sm.iddata(res, "ee_x", sm.THESIS_INPUTS)
    data.y = data.y + np.random.default_rng(1).uniform(-1e-3, 1e-3, len(data))  # ±1 mm sensor noise
    thesis = sm.oe(nb=2, nf=2, nk=0, inputs=sm.THESIS_INPUTS, output="ee_x")
    print(f"structure: {thesis.describe()}, {thesis.n_params} parameters")

    r5 = sm.oe_pui(data, thesis, 0.005)
    print(f"\n-- output error, eps = 5 mm: feasible; minimal bound of the estimated denominators "
          f"eps_min = {r5.eps_min * 1e3:.3f} mm; {r5.n_lp} LPs, {len(r5.iterations) - 1} denominator iterations, "
          f"{r5.solve_time:.2f} s")
    with_pd = r5.to_pandas()
    print(with_pd[["lower", "upper", "center", "cond_lower", "cond_upper"]].to_string(float_format=lambda v: f"{v:.5g}"))
    print("   (cond_*: exact numerator intervals given the estimated denominators F^)")

    rows = []
    for eps in (0.005, 0.003, 0.002, 1.2 * r5.eps_min):
        r = r5 if eps == 0.005 else sm.oe_pui(data, thesis, eps)
        f_w = float(np.max(r.width[:8]))
        b_w = float(np.median(r.width[8:16]))
        rows.append((eps, r.eps_min, f_w, b_w, r.width[-1], r.solve_time))
    print("\n-- the same at tighter bounds (the set shrinks towards the minimal bound):")
    print(f"{'eps mm':>8} {'eps_min mm':>10} {'max f width':>12} {'median b width':>15} {'c width mm':>11} {'time s':>7}")
    for eps, em, fw, bw, cw, ts in rows:
        print(f"{eps * 1e3:8.3f} {em * 1e3:10.3f} {fw:12.4g} {bw:15.4g} {cw * 1e3:11.3f} {ts:7.2f}")

    arx = sm.arx(2, 2, 0, inputs=sm.THESIS_INPUTS, output="ee_x", offset=True)
    ra = sm.pui(data, arx, 0.005)
    print(f"\n-- equation error (ARX, same orders), |e| <= 5 mm on the equation error: exact, {ra.n_lp} LPs, "
          f"{ra.solve_time:.2f} s, eps_min = {ra.eps_min * 1e3:.3f} mm, Chebyshev radius {ra.radius:.3f}")
    print(ra.to_pandas()[["lower", "upper", "center"]].to_string(float_format=lambda v: f"{v:.5g}"))

    try:
        sm.oe_pui(data, thesis, 0.0008)
    except sm.InfeasibleError as e:
        print(f"\n-- eps = 0.8 mm (below the ±1 mm noise):\n{e}")
    os.makedirs(OUT, exist_ok=True)
    fig = r5.plot()
    fig.savefig(os.path.join(OUT, "setmembership_thesis.png"), dpi=110)
    fig = ra.plot()
    fig.savefig(os.path.join(OUT, "setmembership_thesis_arx.png"), dpi=110)
    print(f"\nplots: {OUT}/setmembership_thesis.png, {OUT}/setmembership_thesis_arx.png")


def _den(r: float, w: float) -> list:
    return [-2.0 * r * math.cos(w), r * r]


def part_b(runs: int, n: int, sweep: int) -> None:
    s = sm.oe(nb=2, nf=2, nk=0, inputs=["u1", "u2"], output="y")
    truth = np.array([*_den(0.9, 0.3), *_den(0.8, 0.6), 0.5, 0.3, -0.4, 0.2, 0.1])
    delta = 0.05
    print(f"\n== B. Monte Carlo: {s.describe()}, truth known, {runs} noise realisations of {n} samples, "
          f"e ~ U(-{delta}, {delta}), eps = {delta}")
    rng_u = np.random.default_rng(0)
    cov_given = np.zeros(s.n_params)
    cov = np.zeros(s.n_params)
    cov_fhat = np.zeros(s.n_params)
    centres, widths, cond_w, sweep_w = [], [], [], []
    t0 = time.perf_counter()
    infeasible = 0
    last = None
    n_sweep = min(10, runs)
    outside = 0
    for k in range(runs):
        u = lfilter([0.2], [1.0, -0.8], rng_u.standard_normal((n, 2)), axis=0)
        u[0] = 0.0
        e = np.random.default_rng(1000 + k).uniform(-delta, delta, n)
        y = sm.simulate(s, truth, u, e)
        given = sm.oe_pui((y, u), s, delta, denominators=[truth[:2], truth[2:4]])
        cov_given += given.contains(truth)
        try:
            r = sm.oe_pui((y, u), s, delta)
        except sm.InfeasibleError:
            infeasible += 1
            continue
        cov += r.contains(truth)
        centres.append(r.center)
        widths.append(r.width)
        cond_w.append(np.r_[np.full(4, np.nan), r.conditional.width])
        cov_fhat[4:] += (r.conditional.lower <= truth[4:]) & (truth[4:] <= r.conditional.upper)
        if k < n_sweep:  # the same data with a sweep of denominators verified by exact LPs
            rs = sm.oe_pui((y, u), s, delta, sweep=sweep)
            if rs.sweep is not None and rs.sweep["feasible"]:
                sweep_w.append((rs.sweep["upper"] - rs.sweep["lower"]) / r.width)
                outside += int(np.sum((rs.sweep["lower"] < r.lower - 1e-12) | (rs.sweep["upper"] > r.upper + 1e-12)))
        last = r
    took = time.perf_counter() - t0
    ok = runs - infeasible
    C = np.array(centres)
    W = np.array(widths)
    print(f"{runs} runs in {took:.1f} s; the scheme found a feasible denominator in {ok}/{runs}")
    print(f"{'parameter':>9} {'truth':>8} {'cover given F':>13} {'cover scheme':>12} {'cover given F^':>14} {'mean width':>10} "
          f"{'given-F^ width':>14} {'verified/width':>14} {'MC std':>8} {'MC range':>8} {'width/std':>9} {'width/range':>11}")
    SW = np.array(sweep_w) if sweep_w else None
    for i, name in enumerate(s.names):
        cw = np.nanmean(np.array(cond_w)[:, i]) if i >= 4 else float("nan")
        sw = float(np.mean(SW[:, i])) if SW is not None else float("nan")
        cf = f"{cov_fhat[i] / max(ok, 1):14.2f}" if i >= 4 else f"{'':>14}"
        print(f"{name:>9} {truth[i]:8.4f} {cov_given[i] / runs:13.2f} {cov[i] / max(ok, 1):12.2f} {cf} {W[:, i].mean():10.4g} "
              f"{cw:14.4g} {sw:14.3f} {C[:, i].std():8.4g} {np.ptp(C[:, i]):8.4g} {W[:, i].mean() / C[:, i].std():9.2f} "
              f"{W[:, i].mean() / np.ptp(C[:, i]):11.2f}")
    print("cover given F: the exact intervals with the true denominators (a guarantee: 1.00);")
    print("cover scheme: the reported intervals (estimated F^, first-order joint intervals, an approximation);")
    print("cover given F^: the exact numerator intervals given the estimated denominators alone;")
    print(f"verified/width: width of the hull of points verified feasible by exact LPs (sweep of {sweep} denominators, an")
    print(f"  inner bound of the exact intervals) over the reported width without the sweep, mean of the first {n_sweep} runs;")
    print(f"  verified end points outside the reported intervals: {outside} (of {2 * s.n_params * len(sweep_w)})")
    print("MC std / range: spread of the Chebyshev centres over the realisations.")
    if last is not None:
        fig = last.plot(truth=truth)
        fig.savefig(os.path.join(OUT, "setmembership_montecarlo.png"), dpi=110)
        print(f"plot of the last run: {OUT}/setmembership_montecarlo.png")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=50, help="Monte Carlo realisations")
    ap.add_argument("--samples", type=int, default=2000, help="samples of the PRBM simulation (part A)")
    ap.add_argument("--quick", action="store_true", help="10 runs, 1000 samples")
    a = ap.parse_args()
    if a.quick:
        a.runs, a.samples = 10, 1000
    t0 = time.perf_counter()
    part_a(a.samples)
    part_b(a.runs, 500, sweep=20)
    print(f"\ntotal {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
