#!/usr/bin/env python3
"""Fit the motoreducer defaults to the velocity-loop frequency responses of the thesis.

Experiment ("one link – one motoreducer", thesis Tables 5–9): the elbow q3 drives link 2
with the 2 kg payload, q1 and q2 get a zero velocity reference, gravity is off, the arm
starts at rest at q0 = (0, π/2, 0). The velocity reference of q3 is a sine of amplitude A
[rad/s] and frequency ω [rad/s] (stepped sines: one run per frequency, from rest). After a
few settling periods the measured joint rate dq3 is fitted over whole periods by least
squares with ``sin ωt, cos ωt, 1``. The gain is the **first-harmonic amplitude ratio**
``|dq3(ω)| / A``: once the torque limit is reached the response is no longer sinusoidal,
and this is the describing-function gain (not an rms ratio). The −3 dB cut-off is the
first frequency, going up, at which this gain falls below 1/√2 (log grid, a finer grid
inside the bracket, log-ω/dB interpolation). The script also reports the band edge (the
last downward crossing) and the dips below −3 dB under it: the flexible link 2 (PRBM
bending joints, locked-motor modes 15 and 71 rad/s with 2 kg) puts anti-resonance notches
into the elbow's response.

Fits (ω_i = ``current_bandwidth`` is held; its effect is printed):

* ``linear``: c_u (``torque_per_unit``) alone, so that the band edge at A = 0.1 rad/s is
  707 rad/s (small-signal regime, τ_max does not act), by a secant on ln c_u.
* ``c_u + τ_max``: then τ_max (``tau_max``) to the cut-offs 151 / 49 rad/s at A = 1 / 3
  rad/s (Kp = 5000, Ki = 100), c_u from the linear fit (it alone sets the A = 0.1 cut-off;
  a joint 2-parameter search finds the same τ_max and lets c_u drift on the A = 1/3
  residuals): minimum of Σ (ln ω_sim/ω_thesis)² by a log grid and a compass search (the
  cut-off jumps where a dip closes, so no gradient method).

Then the Kp trend of Table 9 (Kp = 500 … 10000 at A = 0.1 rad/s), each frequency one
``rollout_task`` batched over Kp. ``--armature`` rebuilds the arm with another reflected
rotor inertia (all three joints) to show what limits the fit.

Usage::

    python examples/fit_motoreducer.py            # fits + tables (≈ 1.5–2 min on 2 cores)
    python examples/fit_motoreducer.py --quick    # only the current defaults (< 40 s)

Writes ``out/fit_motoreducer.md``.
"""

from __future__ import annotations

import argparse
import math
import sys
import os
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

import popup

from popup.control import Controller, Phase, Task, const, sine

sys.path.insert(0, str(Path(__file__).resolve().parent))
import thesis_data  # noqa: E402  (the thesis's numbers, one copy)

THESIS = {a: thesis_data.TABLES_5_7[2.0]["prbm"][a] for a in (0.1, 1.0, 3.0)}  # Table 5, PRBM column
"""Thesis cut-offs [rad/s] of the velocity loop at Kp = 5000, Ki = 100, by reference amplitude [rad/s]."""
KP_TREND = (500.0, 1000.0, 2000.0, 5000.0, 10000.0)
KP, KI = 5000.0, 100.0
Q0 = (0.0, math.pi / 2, 0.0)
R = 1.0 / math.sqrt(2.0)
FS = 10_000.0  # sample rate [Hz] = controller rate
FAULTS = {"wrinkle": "continue", "saturation": "continue", "contact": "continue"}
CURRENT = {"torque_per_unit": 0.1014, "tau_max": 66.83, "current_bandwidth": 6283.0}
"""``Motoreducer::DEFAULT`` (c_u [N·m/unit], τ_max [N·m], ω_i [rad/s]); --quick checks these."""


# ----------------------------------------------------------------------------- model
def make_model(armature: Optional[float] = None) -> popup.Model:
    """popup-lab, 2 kg payload, gravity off, dt = 1e-4 s (the 10 kHz controller period);
    ``armature`` [kg·m²] replaces the reflected rotor inertia of the three motor joints."""
    if armature is None:
        return popup.Model("popup-lab", dt=1e-4, gravity=False)
    base = popup.Model("popup-lab", dt=1e-4, gravity=False)
    text = base.arm.to_toml()
    key = "armature_kgm2 = "
    i = text.index(key)
    j = text.index("\n", i)
    text = text[:i] + f"{key}[{armature}, {armature}, {armature}]" + text[j:]
    fd, path = tempfile.mkstemp(suffix=".toml")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        return popup.Model(path, dt=1e-4, gravity=False)
    finally:
        os.unlink(path)


def inertias(model: popup.Model) -> Tuple[float, float]:
    """(J33, J_hf) at q0 [kg·m²]: the rigid inertia M[q3, q3] (armature included) and the
    inertia the elbow sees far above the bending modes, 1/(M⁻¹)[q3, q3] (all other joints
    free: link 2 decouples behind its bending joints)."""
    q = model.rest_state(Q0)
    M = model.mass_matrix(q.tolist())
    i = model.joint_names.index("q3")
    return float(M[i, i]), float(1.0 / np.linalg.inv(M)[i, i])


# ----------------------------------------------------------------------------- measurement
@dataclass
class Settings:
    """Run lengths: settle ``max(settle_periods·T, settle_s)``, then fit over
    ``max(window_periods·T, window_s)``, both rounded up to whole periods T = 2π/ω."""

    settle_periods: int = 3
    settle_s: float = 0.15
    window_periods: int = 3
    window_s: float = 0.1
    threads: int = 2


FAST = Settings()
ACCURATE = Settings(settle_periods=5, settle_s=1.0, window_periods=6, window_s=0.4)


def _task(motor: Mapping[str, float], amplitude: float, omega: float) -> Task:
    ph = Phase("phase", name="sine", velocity=[const(0.0), const(0.0), sine(amplitude, omega / (2 * math.pi))], until={"max_time": 1e9})
    return Task([ph], Controller(motor=dict(motor), gains={"vel_kp": KP, "vel_ki": KI}), faults=dict(FAULTS))


def first_harmonic(t: np.ndarray, y: np.ndarray, omega: float) -> complex:
    """Least-squares fit ``y ≈ a sin ωt + b cos ωt + c``; returns ``a + i b`` (amplitude
    ``|a + i b|``: the first harmonic; the other harmonics and the offset are left out)."""
    X = np.column_stack([np.sin(omega * t), np.cos(omega * t), np.ones_like(t)])
    c, *_ = np.linalg.lstsq(X, y, rcond=None)
    return complex(c[0], c[1])


Job = Tuple[Mapping[str, float], Sequence[float], float, float]  # (motor, kps, A, ω)


def _one(model: popup.Model, job: Job, st: Settings) -> np.ndarray:
    """First-harmonic gains of dq3 at one frequency, one per Kp (one batched run)."""
    motor, kps, amplitude, omega = job
    T = 2 * math.pi / omega
    n_set = max(st.settle_periods, math.ceil(st.settle_s / T))
    n_win = max(st.window_periods, math.ceil(st.window_s / T))
    dur = (n_set + n_win) * T
    b = model.rollout_task(
        _task(motor, amplitude, omega),
        duration=dur + 2.0 / FS,
        q0=Q0,
        sample_rate=FS,
        gains=[{"vel_kp": float(k), "vel_ki": KI} for k in kps],
        threads=1,
    )
    t = b.time[0]
    sel = (t >= n_set * T - 0.5 / FS) & (t < dur - 0.5 / FS)
    out = np.full(len(kps), np.nan)
    for j in range(len(kps)):
        if b.status[j] == "completed":
            out[j] = abs(first_harmonic(t[sel], b.dq[j, sel, 2], omega)) / amplitude
    return out


def measure(model: popup.Model, jobs: Sequence[Job], st: Settings = FAST) -> List[np.ndarray]:
    """Gains for ``jobs``, one run each on a thread pool (the core releases the GIL). The
    frequency lives in the task's signal, so frequencies are separate runs; Kp values are
    a batch (``gains=[...]``) within one run."""
    with ThreadPoolExecutor(max(1, st.threads)) as ex:
        return list(ex.map(lambda j: _one(model, j, st), jobs))


NOTCH = 1.2
"""Dips below −3 dB narrower than this frequency ratio (hi/lo) are anti-resonance notches:
listed, but not taken as the cut-off."""


@dataclass
class Cutoff:
    """A measured −3 dB cut-off of the first-harmonic gain."""

    amplitude: float
    first: float
    """The cut-off [rad/s]: the first downward crossing of 1/√2, not counting notches
    narrower than :data:`NOTCH` (0: already below at the lowest frequency; inf: never
    below)."""
    strict: float
    """The first downward crossing, notches included [rad/s]."""
    edge: float
    """Last downward crossing (band edge) [rad/s]."""
    dips: List[Tuple[float, float]] = field(default_factory=list)
    """Intervals below 1/√2 under the band edge [rad/s]."""
    omegas: np.ndarray = field(default_factory=lambda: np.zeros(0))
    gains: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def gain_min(self, below: float) -> float:
        """Smallest measured gain under ``below`` [rad/s]."""
        g = self.gains[self.omegas < below]
        return float(g.min()) if len(g) else math.nan


def _cross(w0: float, g0: float, w1: float, g1: float) -> float:
    """Log-ω, dB interpolation of the 1/√2 crossing between two points."""
    d0, d1, dr = 20 * math.log10(g0), 20 * math.log10(g1), 20 * math.log10(R)
    return float(math.exp(math.log(w0) + (d0 - dr) / (d0 - d1) * math.log(w1 / w0)))


def _crossings(w: np.ndarray, g: np.ndarray) -> List[Tuple[int, int]]:
    """(i, direction) for each crossing between w[i] and w[i+1] (−1 down, +1 up)."""
    out = []
    for i in range(len(w) - 1):
        if g[i] >= R > g[i + 1]:
            out.append((i, -1))
        elif g[i] < R <= g[i + 1]:
            out.append((i, +1))
    return out


def analyse(amplitude: float, w: np.ndarray, g: np.ndarray) -> Cutoff:
    """First crossing, band edge and dips of a sampled gain curve."""
    o = np.argsort(w)
    w, g = np.asarray(w)[o], np.asarray(g)[o]
    cr = _crossings(w, g)
    pts = [(_cross(w[i], g[i], w[i + 1], g[i + 1]), d) for i, d in cr]
    downs = [x for x, d in pts if d < 0]
    strict = 0.0 if g[0] < R else (downs[0] if downs else math.inf)
    edge = math.inf if g[-1] >= R else (downs[-1] if downs else 0.0)
    dips, lo = [], (float(w[0]) if g[0] < R else None)
    for x, d in pts:
        if d < 0:
            lo = x
        elif lo is not None:
            dips.append((lo, x))
            lo = None
    wide = [a for a, b in dips if b / a >= NOTCH or a == w[0]]
    first = 0.0 if g[0] < R else (wide[0] if wide else edge)
    return Cutoff(amplitude, first, strict, edge, dips, w, g)


def grid(w_lo: float = 8.0, w_hi: float = 6000.0, n: int = 17) -> np.ndarray:
    """Log-spaced frequencies [rad/s]."""
    return np.geomspace(w_lo, w_hi, n)


def cutoffs(
    model: popup.Model,
    motor: Mapping[str, float],
    amplitudes: Sequence[float],
    *,
    kp: float = KP,
    omegas: Optional[np.ndarray] = None,
    refine: int = 2,
    st: Settings = FAST,
) -> Dict[float, Cutoff]:
    """Cut-offs of the q3 velocity loop at gain ``kp`` for several reference amplitudes:
    a log grid for all amplitudes in one pool, then ``refine`` frequencies inside the
    brackets of the first crossing and of the band edge."""
    w = grid() if omegas is None else np.asarray(omegas, dtype=float)
    jobs: List[Job] = [(motor, [kp], a, float(x)) for a in amplitudes for x in w]
    g = np.array([r[0] for r in measure(model, jobs, st)]).reshape(len(amplitudes), len(w))
    res = {a: analyse(a, w, g[k]) for k, a in enumerate(amplitudes)}
    if refine > 0:
        extra: List[Tuple[float, float]] = []
        for a, c in res.items():
            downs = [i for i, d in _crossings(c.omegas, c.gains) if d < 0]
            for i in sorted({downs[0], downs[-1]} if downs else set()):
                extra += [(a, float(x)) for x in np.geomspace(c.omegas[i], c.omegas[i + 1], refine + 2)[1:-1]]
        if extra:
            ge = measure(model, [(motor, [kp], a, x) for a, x in extra], st)
            for a in amplitudes:
                we = [x for (b, x) in extra if b == a]
                gg = [r[0] for (b, _), r in zip(extra, ge) if b == a]
                c = res[a]
                res[a] = analyse(a, np.concatenate([c.omegas, we]), np.concatenate([c.gains, gg]))
    return res


def cutoff(model: popup.Model, motor: Mapping[str, float], kp: float, amplitude: float, **kw) -> Cutoff:
    """The −3 dB cut-off of the q3 velocity loop (``.first`` [rad/s]; ``.edge``, ``.dips``
    and the sampled curve too) at velocity gain ``kp`` and reference amplitude
    ``amplitude`` [rad/s], first-harmonic gain (see the module docstring)."""
    return cutoffs(model, motor, [amplitude], kp=kp, **kw)[amplitude]


TREND_W = (5.0, 12000.0)


def kp_trend(model: popup.Model, motor: Mapping[str, float], amplitude: float = 0.1, kps: Sequence[float] = KP_TREND, st: Settings = FAST) -> Dict[float, Cutoff]:
    """Cut-offs for several Kp at one amplitude: each frequency is one run batched over Kp
    (``gains=[{"vel_kp": ...}, ...]``), on a denser grid instead of a refinement round."""
    w = grid(TREND_W[0], TREND_W[1], 29)
    g = np.array(measure(model, [(motor, list(kps), amplitude, float(x)) for x in w], st))  # (nw, nkp)
    return {k: analyse(amplitude, w, g[:, j]) for j, k in enumerate(kps)}


# ----------------------------------------------------------------------------- fits
def loss(c: Mapping[float, Cutoff], which: str = "first") -> float:
    """Σ (ln ω_sim/ω_thesis)² over the amplitudes (a cut-off of 0 or inf counts as a factor
    10 off)."""
    s = 0.0
    for a, target in THESIS.items():
        x = getattr(c[a], which)
        s += (math.log(x / target) if 0 < x < math.inf else math.log(10.0)) ** 2
    return s


def fit_linear(model: popup.Model, base: Mapping[str, float], target: float = THESIS[0.1], amplitude: float = 0.1, log: bool = True) -> Tuple[Dict[str, float], Cutoff]:
    """c_u such that the band edge at ``amplitude`` is ``target`` (secant on ln c_u from the
    estimate target·J_hf/Kp; τ_max and ω_i from ``base``)."""
    _, j_hf = inertias(model)
    w = np.geomspace(target / 2.5, target * 2.5, 11)

    def edge(c: float) -> Tuple[float, Cutoff]:
        cc = cutoffs(model, dict(base, torque_per_unit=c), [amplitude], omegas=w, refine=3, st=ACCURATE)[amplitude]
        if log:
            print(f"    c_u={c:.5g}: band edge {fmt(cc.edge)} rad/s", flush=True)
        return cc.edge, cc

    x0 = math.log(target * j_hf / KP)
    e0, c0 = edge(math.exp(x0))
    x1 = x0 + math.log(target / e0)
    e1, c1 = edge(math.exp(x1))
    for _ in range(3):
        if abs(math.log(e1 / target)) < 2e-3 or e1 == e0:
            break
        x2 = x1 + (math.log(target) - math.log(e1)) * (x1 - x0) / (math.log(e1) - math.log(e0))
        x0, e0, c0 = x1, e1, c1
        x1 = x2
        e1, c1 = edge(math.exp(x1))
    return dict(base, torque_per_unit=float(math.exp(x1))), c1


def fit_tau(model: popup.Model, base: Mapping[str, float], *, log: bool = True) -> Tuple[Dict[str, float], int]:
    """τ_max minimising Σ (ln ω_sim/ω_thesis)² at A = 1 and 3 rad/s with c_u, ω_i from
    ``base`` (c_u alone sets the small-signal cut-off at A = 0.1): a log grid 4…64 N·m, then
    a compass search on ln τ_max with halving steps. The cut-off jumps where a dip closes,
    so no gradient method."""
    amps = [a for a in THESIS if a > 0.1]
    cache: Dict[float, float] = {}

    def ev(lt: float) -> float:
        key = round(lt, 5)
        if key not in cache:
            mot = dict(base, tau_max=float(math.exp(lt)))
            cs = cutoffs(model, mot, amps)
            cache[key] = sum(math.log(cs[a].first / THESIS[a]) ** 2 if 0 < cs[a].first < math.inf else math.log(10.0) ** 2 for a in amps)
            if log:
                f = " ".join(f"{fmt(cs[a].first):>6}" for a in amps)
                print(f"    tau_max={mot['tau_max']:.4g}: cut-offs {f} (A = {', '.join(f'{a:g}' for a in amps)})  loss {cache[key]:.3f}", flush=True)
        return cache[key]

    lts = np.log(np.geomspace(4.0, 64.0, 5))
    best = float(min(lts, key=ev))
    step = float(lts[1] - lts[0]) / 2
    for _ in range(4):
        for d in (1, -1):
            while ev(best + d * step) < ev(best):
                best += d * step
        step /= 2
    return dict(base, tau_max=float(math.exp(best))), len(cache)


# ----------------------------------------------------------------------------- report
def fmt(x: float, lo: float = 8.0, hi: float = 6000.0) -> str:
    if x == 0:
        return f"<{lo:g}"
    if math.isinf(x):
        return f">{hi:g}"
    return f"{x:.0f}"


def _dips(c: Cutoff) -> str:
    return ", ".join(f"{lo:.0f}–{hi:.0f}" for lo, hi in c.dips) or "–"


def amp_table(rows: Mapping[str, Mapping[float, Cutoff]]) -> List[str]:
    """Markdown: thesis vs each parameter set, first crossing / band edge (dips)."""
    out = ["| A [rad/s] | thesis | " + " | ".join(f"{n}: cut-off / edge (dips) [rad/s]" for n in rows) + " |", "|---|---|" + "---|" * len(rows)]
    for a, target in THESIS.items():
        cells = [f"**{fmt(c[a].first)}** / {fmt(c[a].edge)} ({_dips(c[a])})" for c in rows.values()]
        out.append(f"| {a:g} | {target:.0f} | " + " | ".join(cells) + " |")
    return out


def kp_table(rows: Mapping[str, Mapping[float, Cutoff]], cu: float, J: float, j_hf: float) -> List[str]:
    """Markdown: cut-off vs Kp, with the rigid and high-frequency small-signal estimates
    c_u·Kp/J for the fitted c_u."""
    out = ["| Kp | " + " | ".join(f"{n}: cut-off / edge (dips) [rad/s]" for n in rows) + " | c_u·Kp/J33 (fit) | c_u·Kp/J_hf (fit) |"]
    out.append("|---|" + "---|" * (len(rows) + 2))
    for k in KP_TREND:
        out.append(
            f"| {k:g} | "
            + " | ".join(f"**{fmt(r[k].first, *TREND_W)}** / {fmt(r[k].edge, *TREND_W)} ({_dips(r[k])})" for r in rows.values())
            + f" | {cu * k / J:.0f} | {cu * k / j_hf:.0f} |"
        )
    return out


def _motor_str(m: Mapping[str, float]) -> str:
    return f"c_u = {m['torque_per_unit']:.4g} N·m/unit, τ_max = {m['tau_max']:.4g} N·m, ω_i = {m['current_bandwidth']:.4g} rad/s"


def main() -> None:
    ap = argparse.ArgumentParser(description="Fit the motoreducer defaults to the thesis's velocity-loop cut-offs (Tables 5–9).")
    ap.add_argument("--quick", action="store_true", help="only measure the current defaults at the three amplitudes")
    ap.add_argument("--armature", type=float, default=None, help="replace the reflected rotor inertia of the motor joints [kg·m²]")
    ap.add_argument("--out", default="out/fit_motoreducer.md")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    FAST.threads = ACCURATE.threads = args.threads
    t0 = time.time()
    model = make_model(args.armature)
    J, j_hf = inertias(model)
    modes = model.locked_modes(Q0)
    arm = "" if args.armature is None else f" (armature {args.armature:g} kg·m² instead of 0.05)"
    print(f"J33 = {J:.4f} kg·m², J_hf = {j_hf:.4f} kg·m²; bending modes (motors locked) {np.round(modes, 1)} rad/s{arm}")
    lines = [
        "# Motoreducer fit: velocity-loop cut-offs (thesis Tables 5–9)",
        "",
        "Generated by `examples/fit_motoreducer.py`. Experiment: elbow q3 drives link 2 + 2 kg payload, q1/q2 at zero "
        f"velocity reference, gravity off, q0 = (0, π/2, 0){arm}; J33 = {J:.4f} kg·m² (rigid, armature included), "
        f"J_hf = {j_hf:.4f} kg·m² (elbow inertia far above the bending modes); locked-motor bending modes "
        f"{', '.join(f'{m:.1f}' for m in modes)} rad/s. Kp = {KP:g}, Ki = {KI:g}, 10 kHz controller, sampled at 10 kHz. "
        "Gain = first-harmonic amplitude ratio |dq3(ω)|/A (describing function); **cut-off = first −3 dB crossing**, "
        f"not counting notches narrower than {NOTCH:g}:1 in frequency (anti-resonances of link 2; all dips are listed); "
        "edge = last downward crossing, dips = bands below −3 dB under the edge.",
        "",
    ]
    cur = cutoffs(model, CURRENT, list(THESIS))
    print("current defaults:", _motor_str(CURRENT))
    for a, c in cur.items():
        print(f"  A={a:g}: cut-off {fmt(c.first)}  edge {fmt(c.edge)}  dips [{_dips(c)}]  (thesis {THESIS[a]:.0f})")
    if args.quick:
        lines += [f"## Current defaults (`--quick`): {_motor_str(CURRENT)}", "", *amp_table({"current": cur}), "", f"Wall time {time.time() - t0:.0f} s."]
        _write(args.out, lines)
        print(f"wall {time.time() - t0:.1f} s")
        return

    print("fit 1 (linear): c_u for a 707 rad/s band edge at A = 0.1 rad/s (tau_max, omega_i held)")
    lin, lin_c = fit_linear(model, CURRENT)
    print(f"  -> {_motor_str(lin)}  [{time.time() - t0:.0f} s]")
    print("fit 2: tau_max to 151/49 rad/s at A = 1/3 rad/s with c_u from fit 1")
    full, nev = fit_tau(model, lin)
    print(f"  -> {_motor_str(full)}, {nev} evaluations  [{time.time() - t0:.0f} s]")

    sets = {"current": CURRENT, "fit 1 (linear)": lin, "fit 2 (c_u + τ_max)": full}
    acc = {n: cutoffs(model, m, list(THESIS), st=ACCURATE) for n, m in sets.items()}  # re-measured, long settling
    sens = {wi: cutoffs(model, dict(lin, current_bandwidth=wi), [0.1], omegas=np.geomspace(250, 2000, 10), refine=3)[0.1].edge for wi in (2000.0, math.inf)}
    trends = {n: kp_trend(model, sets[n]) for n in ("current", "fit 2 (c_u + τ_max)")}
    print(f"  tables  [{time.time() - t0:.0f} s]")

    lines += [
        "## Fitted values",
        "",
        f"* current defaults: {_motor_str(CURRENT)}",
        f"* fit 1 (linear: band edge 707 rad/s at A = 0.1): {_motor_str(lin)}",
        f"* fit 2 (c_u from fit 1, τ_max: min Σ ln²(ω_sim/ω_thesis) at A = 1, 3): {_motor_str(full)} ({nev} evaluations)",
        "",
        "Σ ln²(ω_sim/ω_thesis) over the three amplitudes (long settling): "
        + ", ".join(f"{n} {loss(c):.3f}" for n, c in acc.items())
        + f" (a factor 2 off at one amplitude is {math.log(2) ** 2:.2f}).",
        "",
        "## Cut-off vs amplitude (Kp = 5000; long settling)",
        "",
        *amp_table(acc),
        "",
        f"Fit 1 at A = 0.1: smallest gain under the edge {acc['fit 1 (linear)'][0.1].gain_min(acc['fit 1 (linear)'][0.1].edge):.3f} "
        f"(1/√2 = {R:.3f}); ω_i sensitivity of its band edge: {fmt(sens[2000.0])} rad/s at ω_i = 2000, "
        f"{fmt(sens[math.inf])} at ω_i = ∞ (vs {fmt(acc['fit 1 (linear)'][0.1].edge)} at {lin['current_bandwidth']:.4g}).",
        "",
        "## Cut-off vs Kp (A = 0.1 rad/s; Table 9 trend)",
        "",
        *kp_table(trends, full["torque_per_unit"], J, j_hf),
        "",
        f"Wall time {time.time() - t0:.0f} s.",
    ]
    print("\n".join(lines))
    _write(args.out, lines)


def _write(path: str, lines: List[str]) -> None:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text("\n".join(lines) + "\n")
    print(f"wrote {p}")


if __name__ == "__main__":
    main()
