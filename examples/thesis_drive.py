#!/usr/bin/env python3
"""One motoreducer fitted to the thesis's Tables 5–9 together (``docs/thesis.md``).

The drive is the project's own (``docs/control.md``, "The cascade"): at each 10 kHz tick
the velocity PI ``u = Kp (v* − v_f) + I`` in drive units, clamped to ``±τ_max/c_u`` with
conditional-integration anti-windup, the torque reference ``c_u ū`` through the current
loop (a first-order lag, exact for the held reference, ``α = 1 − exp(−ω_i T)``), held
over the tick on the joint. ``v_f`` is the measured joint rate, optionally through a
first-order velocity filter of corner ω_v (``β = 1 − exp(−ω_v T)``; ∞ = no filter).
The load is a rigid inertia about the joint: the reflected rotor inertia J_m alone
(Tables 8, 9), or J_m plus a rigid link 2 with its payload and gravity at q0 = 0°, the
link horizontal (the rigid column of Tables 5–7). The same loop is simulated by this
script in numpy (vectorised over every table entry and frequency), so that a fit costs
seconds; the engine (``popup.Model`` with the fitted arm file) checks the result.

Measurement as the thesis defines it (chapter 6.1): the velocity reference is
``A sin ωt`` from rest; after settling, the first harmonic of the sampled joint rate is
taken over the last whole periods with Hann weights, gain = |first harmonic|/A (a
describing function once the torque limit acts); the cut-off is the first frequency,
going up, where the gain falls below 1/√2 (interpolated in log ω and dB).

Parameters fitted (``least_squares`` on ln(ours/thesis), covariance → 95 % intervals):

* ``a = c_u/J_m`` [rad/s² per drive unit]: the loop gain per Kp; Table 9's small-Kp slope.
* ``b = τ_max/J_m`` [rad/s²]: the acceleration at the torque limit; the 1 and 3 rad/s
  cut-offs (∝ b/A).
* ``ω_i`` [rad/s]: the current-loop bandwidth; it ends the Kp = 5000 loop's band at
  0.1 rad/s (707) far below a·Kp.
* ``J_m`` [kg·m²]: only the rigid column of Tables 5–7 sees it (J_m against the link's
  inertia).

Usage::

    python examples/thesis_drive.py          # fit + table (≈ 3–6 min on 2 shared cores)
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parent))
import thesis_data as td  # noqa: E402

T = 1e-4
"""Controller period = physics step [s] (10 kHz)."""
G = 9.81
R = 1.0 / math.sqrt(2.0)

# link 2 of popup-lab (reference-arm.md): tube 0.02 kg root (0.03 m) + 0.38 kg outer (0.57 m),
# radius 0.055 m, payload at the tip (0.6 m from the elbow axis)
LINK_R = 0.055
LINK_L = 0.6


def link_inertia(payload: float, scale: float = 1.0) -> Tuple[float, float]:
    """(J [kg·m²] about the elbow axis, gravity moment m·g·x_c [N·m] at q = 0) of popup-lab's
    link 2 with ``payload`` [kg] at its tip; ``scale`` multiplies the tube's mass."""
    def tube(m: float, l: float, x0: float) -> Tuple[float, float]:
        xc = x0 + l / 2
        return m * (LINK_R**2 / 2 + l**2 / 12) + m * xc**2, m * xc
    j1, s1 = tube(0.02 * scale, 0.03, 0.0)
    j2, s2 = tube(0.38 * scale, 0.57, 0.03)
    return j1 + j2 + payload * LINK_L**2, G * (s1 + s2 + payload * LINK_L)


@dataclass
class Drive:
    """A motoreducer: ``j_m`` reflected inertia [kg·m²], ``c_u`` torque per drive unit
    [N·m], ``tau_max`` [N·m], ``omega_i`` current-loop bandwidth [rad/s], ``omega_v``
    velocity-filter corner [rad/s] (inf: none)."""

    j_m: float
    c_u: float
    tau_max: float
    omega_i: float
    omega_v: float = math.inf

    @property
    def a(self) -> float:
        """c_u/J_m [rad/s² per drive unit]."""
        return self.c_u / self.j_m

    @property
    def b(self) -> float:
        """τ_max/J_m [rad/s²]."""
        return self.tau_max / self.j_m


@dataclass
class Case:
    """One curve: load inertia ``j_load`` [kg·m²] on top of J_m, gravity moment ``mgx``
    [N·m] (0: none), velocity PI ``kp``, ``ki``, amplitude ``amp`` [rad/s]."""

    name: str
    j_load: float
    mgx: float
    kp: float
    ki: float
    amp: float
    target: float


def cases_t5_9(ki_rule: str = "ratio", gravity: bool = True, tube_scale: float = 1.0) -> List[Case]:
    """The thesis's motoreducer entries: Table 8 (alone), Table 9 (alone, A = 1 rad/s,
    Ki = Kp/50 with ``ki_rule="ratio"`` — the tuning's ratio 5000/100 — or 100 with
    ``"fixed"``), and the rigid column of Tables 5–7 (popup-lab's link 2 with its tube
    mass × ``tube_scale``, + payload)."""
    out: List[Case] = []
    for a, w in td.TABLE8.items():
        out.append(Case(f"T8 A={a:g}", 0.0, 0.0, td.VEL_KP, td.VEL_KI, a, w))
    for kp, w in td.TABLE9.items():
        ki = kp / 50.0 if ki_rule == "ratio" else td.VEL_KI
        out.append(Case(f"T9 Kp={kp:g}", 0.0, 0.0, kp, ki, td.TABLE9_AMPLITUDE, w))
    for tab, m in ((5, 2.0), (6, 1.0), (7, 0.0)):
        jl, mgx = link_inertia(m, tube_scale)
        for a, w in td.TABLES_5_7[m]["rigid"].items():
            out.append(Case(f"T{tab} rigid A={a:g}", jl, mgx if gravity else 0.0, td.VEL_KP, td.VEL_KI, a, w))
    return out


# ----------------------------------------------------------------------------- linear loop
def linear_frf(d: Drive, c: Case, omegas: np.ndarray) -> np.ndarray:
    """Exact small-signal FRF v/v* of the discrete loop (no torque limit) at ``omegas``
    [rad/s]; state (v_k, I_k, τ_{k−1}, v_f,k−1), output the sampled rate v_k."""
    J = d.j_m + c.j_load
    al = 1 - math.exp(-d.omega_i * T)
    be = 1.0 if math.isinf(d.omega_v) else 1 - math.exp(-d.omega_v * T)
    A = np.zeros((4, 4))
    B = np.zeros(4)
    for col in range(5):
        s = np.zeros(4)
        r = 0.0
        if col < 4:
            s[col] = 1.0
        else:
            r = 1.0
        v, I, tau, vf = s
        vf1 = (1 - be) * vf + be * v
        e = r - vf1
        u = c.kp * e + I
        tau1 = (1 - al) * tau + al * d.c_u * u
        nxt = np.array([v + T * tau1 / J, I + c.ki * T * e, tau1, vf1])
        if col < 4:
            A[:, col] = nxt
        else:
            B = nxt
    Cv = np.array([1.0, 0, 0, 0])
    z = np.exp(1j * np.asarray(omegas) * T)
    return np.array([Cv @ np.linalg.solve(zz * np.eye(4) - A, B) for zz in z])


def first_crossing(w: np.ndarray, g: np.ndarray) -> float:
    """First downward crossing of 1/√2 in ``g`` over ascending ``w`` (log-ω/dB
    interpolation); 0 if already below at w[0], inf if never."""
    if g[0] < R:
        return 0.0
    for i in range(len(w) - 1):
        if g[i] >= R > g[i + 1]:
            d0, d1, dr = 20 * math.log10(g[i]), 20 * math.log10(g[i + 1]), 20 * math.log10(R)
            return float(math.exp(math.log(w[i]) + (d0 - dr) / (d0 - d1) * math.log(w[i + 1] / w[i])))
    return math.inf


def linear_cutoff(d: Drive, c: Case, lo: float = 1e-2, hi: float = 2e4) -> float:
    """Small-signal cut-off [rad/s] of the discrete loop (dense log grid)."""
    w = np.geomspace(lo, hi, 600)
    return first_crossing(w, np.abs(linear_frf(d, c, w)))


# ----------------------------------------------------------------------------- simulation
def simulate_gains(d: Drive, cases: Sequence[Case], omegas: Sequence[np.ndarray], settle: int = 3, window: int = 3, min_s: float = 0.1) -> List[np.ndarray]:
    """First-harmonic gains |v(ω)|/A of the discrete loop with the torque limit, for every
    case and each frequency of its grid, all in one vectorised time loop. Each run starts
    at rest, the integrator and the current loop at the gravity holding torque (bumpless);
    the harmonic is taken with Hann weights over ``window`` periods (≥ ``min_s``) after
    ``settle`` periods (≥ ``min_s``)."""
    idx = np.concatenate([[k] * len(w) for k, w in enumerate(omegas)])
    om = np.concatenate([np.asarray(w, float) for w in omegas])
    cs = [cases[k] for k in idx]
    J = np.array([d.j_m + c.j_load for c in cs])
    mgx = np.array([c.mgx for c in cs])
    kp = np.array([c.kp for c in cs])
    ki = np.array([c.ki for c in cs])
    amp = np.array([c.amp for c in cs])
    per = 2 * math.pi / om
    t0 = np.maximum(settle * per, min_s)
    t0 = np.ceil(t0 / per) * per
    tw = np.ceil(np.maximum(window * per, min_s) / per) * per
    t1 = t0 + tw
    n = int(math.ceil(t1.max() / T)) + 1
    al = 1 - math.exp(-d.omega_i * T)
    be = 1.0 if math.isinf(d.omega_v) else 1 - math.exp(-d.omega_v * T)
    lim = d.tau_max / d.c_u
    q = np.zeros_like(om)
    v = np.zeros_like(om)
    vf = np.zeros_like(om)
    tau = mgx.copy()
    I = mgx / d.c_u
    acc_c = np.zeros(len(om), complex)
    wsum = np.zeros_like(om)
    for k in range(n):
        t = k * T
        # window weight and harmonic accumulation of the sampled rate
        x = (t - t0) / tw
        inside = (x >= 0) & (x < 1)
        if inside.any():
            wgt = np.where(inside, np.sin(np.pi * x) ** 2, 0.0)
            acc_c += wgt * v * np.exp(-1j * om * t)
            wsum += wgt
        # velocity PI with clamp and conditional integration
        vf = vf + be * (v - vf)
        e = amp * np.sin(om * t) - vf
        u = kp * e + I
        ub = np.clip(u, -lim, lim)
        frz = (ub != u) & (e * u > 0)
        I = np.where(frz, I, I + ki * T * e)
        # current loop and the rigid load, torque held over the tick
        tau = tau + al * (d.c_u * ub - tau)
        acc = (tau - mgx * np.cos(q)) / J
        q = q + T * v + 0.5 * T * T * acc
        v = v + T * acc
    g = 2 * np.abs(acc_c) / np.maximum(wsum, 1e-300) / amp
    out, i = [], 0
    for w in omegas:
        out.append(g[i : i + len(w)])
        i += len(w)
    return out


def grid_around(target: float, span: float = 2.2, n: int = 11) -> np.ndarray:
    """Log grid [rad/s] from target/span to target·span."""
    return np.geomspace(target / span, target * span, n)


SIM_MIN = 8.0
"""Cases whose thesis cut-off is below this [rad/s] use the linear loop (Table 9, Kp = 1
and 10: the torque limit cannot act at such rates, and simulating periods of 1–13 s
costs minutes); the report checks that the limit does not act there."""


def cutoffs(d: Drive, cases: Sequence[Case], span: float = 1.8, n: int = 9) -> np.ndarray:
    """Cut-off [rad/s] of every case: simulated with the torque limit, or the linear loop
    for the slow ones (:data:`SIM_MIN`)."""
    res = np.full(len(cases), np.nan)
    sim = [k for k, c in enumerate(cases) if c.target >= SIM_MIN]
    grids = [grid_around(cases[k].target, span, n) for k in sim]
    gains = simulate_gains(d, [cases[k] for k in sim], grids)
    for k, w, g in zip(sim, grids, gains):
        res[k] = first_crossing(w, g)
        if res[k] in (0.0, math.inf):  # outside the grid: widen once
            w2 = grid_around(cases[k].target, span**2.5, 2 * n)
            res[k] = first_crossing(w2, simulate_gains(d, [cases[k]], [w2])[0])
    for k, c in enumerate(cases):
        if c.target < SIM_MIN:
            res[k] = linear_cutoff(d, c)
    return res


# ----------------------------------------------------------------------------- fit
@dataclass
class Fit:
    """A least-squares fit: the drive, the parameter names/values with 95 % intervals,
    the cases and their residuals ln(ours/thesis)."""

    drive: Drive
    names: List[str]
    x: np.ndarray
    ci: np.ndarray
    cases: List[Case]
    ours: np.ndarray
    cost: float

    def table(self) -> List[Tuple[str, float, float, float]]:
        """(entry, thesis, ours, ratio) rows."""
        return [(c.name, c.target, float(o), float(o / c.target)) for c, o in zip(self.cases, self.ours)]


def drive_from(x: Sequence[float], names: Sequence[str], base: Drive) -> Drive:
    """A drive from log-parameters ``x`` (ln of a, b, ω_i, J_m, ω_v as named)."""
    p = dict(zip(names, np.exp(np.asarray(x))))
    j_m = p.get("j_m", base.j_m)
    a = p.get("a", base.a)
    b = p.get("b", base.b)
    return Drive(j_m=j_m, c_u=a * j_m, tau_max=b * j_m, omega_i=p.get("omega_i", base.omega_i), omega_v=p.get("omega_v", base.omega_v))


def fit(cases: Sequence[Case], base: Drive, names: Sequence[str] = ("a", "b", "omega_i", "j_m"), weights: Optional[np.ndarray] = None, log: bool = True, max_nfev: int = 24) -> Fit:
    """Least squares on ln(cut-off ours/thesis) over ``cases``, parameters ``names`` in log
    space (``a``, ``b``, ``omega_i``, ``j_m``, ``omega_v``) from ``base``; 95 % intervals from
    the Jacobian (σ² = cost/(n − p), t-quantile)."""
    from scipy.stats import t as student

    wts = np.ones(len(cases)) if weights is None else np.asarray(weights, float)
    tg = np.array([c.target for c in cases])

    def resid(x: np.ndarray) -> np.ndarray:
        o = cutoffs(drive_from(x, names, base), cases)
        o = np.where(np.isfinite(o) & (o > 0), o, tg * 10)
        r = wts * np.log(o / tg)
        if log:
            print("   ", " ".join(f"{n}={v:.4g}" for n, v in zip(names, np.exp(x))), f"cost={0.5 * float(r @ r):.4g}", flush=True)
        return r

    x0 = np.log([{"a": base.a, "b": base.b, "omega_i": base.omega_i, "j_m": base.j_m, "omega_v": base.omega_v}[n] for n in names])
    sol = least_squares(resid, x0, diff_step=5e-3, x_scale=1.0, max_nfev=max_nfev, xtol=1e-4, ftol=1e-4)
    m, p = len(cases), len(names)
    dof = max(m - p, 1)
    s2 = 2 * sol.cost / dof
    try:
        cov = np.linalg.inv(sol.jac.T @ sol.jac) * s2
        se = np.sqrt(np.diag(cov))
    except np.linalg.LinAlgError:
        se = np.full(p, np.inf)
    q = student.ppf(0.975, dof)
    ci = np.exp(np.column_stack([sol.x - q * se, sol.x + q * se]))
    d = drive_from(sol.x, names, base)
    ours = cutoffs(d, cases)
    return Fit(d, list(names), np.exp(sol.x), ci, list(cases), ours, float(sol.cost))


def motor_cases(ki_rule: str = "ratio") -> List[Case]:
    """Tables 8 and 9 only (the motoreducer alone)."""
    return [c for c in cases_t5_9(ki_rule) if c.name.startswith(("T8", "T9"))]


def rigid_cases(gravity: bool = True, tube_scale: float = 1.0) -> List[Case]:
    """The rigid column of Tables 5–7 (link 2's tube mass × ``tube_scale``)."""
    return [c for c in cases_t5_9(gravity=gravity, tube_scale=tube_scale) if "rigid" in c.name]


def implied_jm(motor: Drive, cases: Sequence[Case], grid: Optional[np.ndarray] = None) -> np.ndarray:
    """For each case, the reflected inertia J_m [kg·m²] that alone puts its cut-off on the
    thesis's number, c_u/J_m and τ_max/J_m held at ``motor``'s (log interpolation on a grid
    of J_m, one simulation for all; nan where the grid does not bracket it)."""
    grid = np.geomspace(0.02, 20.0, 16) if grid is None else grid
    cut = np.array([cutoffs(Drive(j, motor.a * j, motor.b * j, motor.omega_i, motor.omega_v), cases) for j in grid])  # (ng, nc)
    out = np.full(len(cases), np.nan)
    for k, c in enumerate(cases):
        y = np.log(cut[:, k] / c.target)
        for i in range(len(grid) - 1):
            if np.isfinite(y[i]) and np.isfinite(y[i + 1]) and y[i] * y[i + 1] <= 0 and y[i] != y[i + 1]:
                out[k] = float(np.exp(np.log(grid[i]) + y[i] / (y[i] - y[i + 1]) * np.log(grid[i + 1] / grid[i])))
                break
    return out


@dataclass
class DriveReport:
    """Everything the report prints about Tables 5–9: the motoreducer fit (Tables 8–9),
    the J_m fit (rigid column of Tables 5–7), each rigid entry's own J_m, Table 9 with
    Ki = 100 held, and the rigid column without gravity."""

    motor: Fit
    jm: Fit
    jm_each: np.ndarray
    t9_fixed_ki: np.ndarray
    rigid_nograv: np.ndarray


BASE = Drive(j_m=1.0, c_u=0.52, tau_max=86.0, omega_i=400.0)
"""Start of the fit: J_m = 1 (Tables 8–9 see only c_u/J_m and τ_max/J_m); a ≈ 0.56 from
Table 9's Kp = 10 and 100, b ≈ 83 rad/s² from the 1 and 3 rad/s cut-offs (bang-bang first
harmonic (4/π)·b/ω = A/√2), rounded towards an earlier run's optimum to save evaluations."""


def run(log: bool = False, tube_scale: float = 1.0) -> DriveReport:
    """The two-stage fit (≈ 2–5 min on 2 shared cores); ``tube_scale``: link 2's tube mass
    in the rigid column's load, × popup-lab's (the link fit's, for popup-lab-thesis)."""
    motor = fit(motor_cases(), BASE, names=("a", "b", "omega_i"), log=log)
    rc = rigid_cases(tube_scale=tube_scale)
    each = implied_jm(motor.drive, rc)
    start = Drive(float(np.nanmedian(each)), 0, 0, motor.drive.omega_i)
    start = Drive(start.j_m, motor.drive.a * start.j_m, motor.drive.b * start.j_m, motor.drive.omega_i)
    jm = fit(rc, start, names=("j_m",), log=log)
    fixed = np.array([linear_cutoff(motor.drive, c) for c in motor_cases("fixed") if c.name.startswith("T9") and c.target < SIM_MIN])
    nog = cutoffs(jm.drive, rigid_cases(gravity=False, tube_scale=tube_scale))
    return DriveReport(motor, jm, each, fixed, nog)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tube-scale", type=float, default=1.0, help="link 2's tube mass in the rigid load, x popup-lab's (docs/thesis.md uses the link fit's 0.274)")
    args = ap.parse_args()
    t0 = time.time()
    r = run(log=True, tube_scale=args.tube_scale)
    for f in (r.motor, r.jm):
        for n, x, (lo, hi) in zip(f.names, f.x, f.ci):
            print(f"{n} = {x:.4g}  [{lo:.4g}, {hi:.4g}]")
        for row in f.table():
            print("%-16s thesis %7.2f ours %7.2f ratio %.3f" % row)
    print("J_m per rigid entry:", np.round(r.jm_each, 3))
    print("T9 Kp=1,10 with Ki=100:", np.round(r.t9_fixed_ki, 2))
    print("rigid without gravity:", np.round(r.rigid_nograv, 1))
    print(r.jm.drive)
    print(f"{time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()
