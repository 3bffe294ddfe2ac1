"""The thesis's closed-loop simulations on ``popup-lab``: chapter 7 simulations 1–7 and
chapter 8, each without and with the vibration-damping PIDs, in ONE table plus plots.

Reconstruction
--------------
We do not have the thesis text, only its summary ("chapter 7 simulations 1–7: one link and
whole arm, step with 2 s delay and square-wave references, with and without gravity,
payload 2 kg, q0 = 0° or (0°, 90°, 0°); chapter 8: Cartesian target, q0 = (0°, 60°, −120°),
payloads 0, 1, 2 kg"). The scenarios below are a faithful *reconstruction* of that summary,
not a transcription: amplitudes, square-wave periods and durations are our choices.

====  =====================================================================================
id    scenario
====  =====================================================================================
1     one link: q3 steps 0 → 0.2 rad at t = 2 s (q1, q2 held), no gravity, q0 = 0
2     one link: q3 step as 1, gravity, q0 = (0, 90°, 0) (arm straight up)
3     one link: q3 square wave 0 / 0.2 rad, period 6 s, from t = 2 s, gravity, q0 = (0, 90°, 0)
4     whole arm: q1, q2, q3 all step by +0.2 rad at t = 2 s, no gravity, q0 = 0
5     whole arm: step as 4, gravity, q0 = (0, 90°, 0)
6     whole arm: square wave 0 / +0.2 rad on q1, q2, q3 (period 6 s, from 2 s), no gravity, q0 = 0
7     whole arm: square wave as 6, gravity, q0 = (0, 90°, 0)
8     chapter 8: Cartesian target, q0 = (0, 60°, −120°), gravity, payload 0 (8a), 1 (8b),
      2 kg (8c), the chapter-8 gains (velocity Kp = 1000, Ki = 10), 15 s (the
      Jacobian-transpose law with the default ``cart_k = 4`` converges slowly). The thesis's
      target (−0.8, −0.8, 0.9) m is 1.446 m from the shoulder, outside this model's 1.2 m
      reach (the 7-DOF chain of thesis Table 4): the run raises
      :class:`popup.UnreachableError`, which the script prints and records (row
      ``8-thesis``); the runs use the target in the same direction at 1.0 m from the
      shoulder centre, (−0.553, −0.553, 0.623) m.
====  =====================================================================================

Chapter 7 runs carry a 2 kg payload (the model default); all run at 30 kPa, physics step
dt = 1e-4 s, controller at 10 kHz with the thesis's cascade gains (position Kp 20, Ki 0.25;
velocity Kp 5000, Ki 100 in chapter 7), the motoreducer torque limit 66.83 N·m and the fault
policy ``wrinkle = "continue"`` (wrinkling alarms are logged and counted, the motion goes on).

Damping variants (one batch per scenario, ``Model.rollout_task`` on all cores):

``off``
    ``damp_kp = 0`` (with ``damp_ki = damp_kd = 0`` the PID output is exactly zero: the
    same as the PIDs off).
``on``
    ``Controller(damping=True)`` with the library's default gains (``damp_kp = (0.01, 0.04,
    0.04)``, ``damp_ki = damp_kd = 0``). The joint-1 PID (input: difference of the two
    links' lateral IMU signals) has a pose-dependent margin: with the arm horizontal
    (q0 = 0) its stability limit is ≈ 0.03 (at 0.04 scenarios 4 and 6 ended in a limit
    cycle at the torque limit), and with the arm up a positive gain slowly *destabilises*
    the lateral modes (the base yaw barely moves the tips there); 0.01 damps the horizontal
    case and stays stable upright. Joints 2 and 3 use 0.04 (limit ≈ 0.08). A pose-scheduled
    joint-1 gain would be the real fix.

Metrics (one row per run)
-------------------------
``t_move``
    Start of the motion: the first reference change (2 s for steps and square waves), 0 for
    the Cartesian runs.
``settling_s``
    Settling time of the end effector (motion-capture point, origin of frame 7). For each
    *segment* (from a reference change to the next one or to the end of the run) the
    plateau ``ee_f`` is the mean end-effector position over the segment's last 0.25 s and
    the *move* is ``|ee_f − ee(start of segment)|``; the tolerance is
    ``max(2 % of the move, 5 mm)`` (whichever is larger: 5 mm for the one-link moves of
    ~0.12 m, ~8 mm for the whole-arm moves, ~28 mm for the 1.4 m Cartesian move); the
    segment's settling time is the time from its start until ``|ee − ee_f|`` stays below the
    tolerance for the rest of the segment, provided it then stays in the band for at least
    1 s before the segment ends (more than two periods of the slowest bending mode; else an
    oscillation that happens to pass near the plateau at the very end would count as
    settled). Steps and Cartesian runs
    have one segment; square waves report the worst segment. NaN (``n.s.``) means "did not
    settle within the segment" (3 s for the square waves, 6 s for the steps).
``rms_bending_rad`` / ``peak_bending_rad``
    RMS over the samples from ``t_move`` on, and peak over the whole run, of the four
    bending channels d11 d12 d21 d22 together [rad] (static gravity sag included).
``rms_vib_bending_rad``
    The same RMS of the bending minus its final value (mean over the last 1 s): the
    vibration alone, without the static sag.
``peak_tip_accel_ms2``
    Peak of ``|f₂(t) − f₂(0)|``, f₂ the IMU 2 (tip of link 2) specific force [m/s²] (it
    also contains the turning of gravity in the IMU frame, ~2 m/s² for a 0.2 rad tilt).
``peak_torque_nm``
    Peak of the motor-torque channels tau1..3 over the run [N·m] (holding torque included).
    The channel is the torque at the joint output acting on the link, ``M q̈ + b`` of the
    bare chain: it also carries the reaction of the reflected rotor inertia (0.05 kg·m²), so
    it can exceed the drive's 66.83 N·m while the drive's own torque is clamped.
``sat_s``
    Time the drive's torque command sat at the 66.83 N·m limit [s].
``steady_offset_m``
    ``|ee − FK_rigid(q_enc)|``, FK_rigid the 7-DOF chain with its bending joints at 0
    (``Model.end_effector``) at the encoder angles, averaged over the last 2 s with a Hann
    window (which removes what is left of the oscillation far better than a plain mean)
    [m]: the tip sag the encoders cannot see.
``wrinkle_alarms``
    Number of wrinkling-alarm episodes (bending moment above M_w, classical coefficient).

Claims checked on the table (PASS/FAIL with numbers, written into ``table.md``), for the
default damping gains: (a) damping lowers RMS bending, peak
torque and peak tip acceleration in every chapter-7 scenario; (b) gravity leaves a steady
bending offset (> 1 mm with gravity, < 0.5 mm without); (c) chapter 8: damping helps for
every payload 0, 1, 2 kg (same three metrics). A failed claim is printed with its numbers
and a one-line explanation; the scenarios are not tuned to make claims pass. The exit code
is 0 either way.

Usage::

    python examples/thesis_scenarios.py [--out out/thesis_scenarios] [--quick]

``run(out_dir, quick=False)`` returns the table as a DataFrame; ``claims(df)`` the claims as
``(name, ok, detail)``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # type: ignore[import-untyped]  # noqa: E402

import popup  # noqa: E402
from popup.control import Controller, Phase, Task, const, square, step  # noqa: E402

DEG = math.pi / 180
AMP = 0.2  # step / square amplitude [rad]
DELAY = 2.0  # step delay [s]
SQ_PERIOD = 6.0  # square-wave period [s]
TAU_MAX = 66.83  # motoreducer torque limit [N·m] (library default)
THESIS_TARGET = (-0.8, -0.8, 0.9)  # chapter-8 Cartesian target [m]
TARGET_REACH = 1.0  # distance of the reachable target from the shoulder centre [m]
CH8_GAINS = {"vel_kp": 1000.0, "vel_ki": 10.0}
VARIANTS: List[Tuple[str, Dict[str, Any]]] = [
    ("off", {"damp_kp": 0.0}),
    ("on", {}),
]
SAMPLE_RATE = 1000.0  # output rate [Hz]
TOL_REL, TOL_ABS = 0.02, 0.005  # settling band: max(2 % of the move, 5 mm)
MIN_IN_BAND = 1.0  # a segment counts as settled only if it then stays in the band >= 1 s [s]
OFFSET_ZERO = 5e-4  # "no steady offset" threshold [m]
OFFSET_GRAVITY = 1e-3  # "steady offset" threshold with gravity [m]


@dataclass
class Scenario:
    """One thesis scenario (its damping variants and payloads run as one batch)."""

    sid: str
    description: str
    gravity: bool
    q0: Tuple[float, float, float]
    duration: float
    track: Optional[List[Any]] = None  # three reference signals
    edges: List[float] = field(default_factory=list)  # reference-change times [s]
    cartesian: Optional[Tuple[float, float, float]] = None
    payloads: Sequence[float] = (2.0,)
    gains: Dict[str, Any] = field(default_factory=dict)


def reachable_target() -> Tuple[float, float, float]:
    """The thesis's chapter-8 target direction at ``TARGET_REACH`` from the shoulder centre
    (the base origin for popup-lab: d1 = 0)."""
    u = np.asarray(THESIS_TARGET, dtype=float) / np.linalg.norm(THESIS_TARGET)
    return tuple(float(v) for v in TARGET_REACH * u)  # type: ignore[return-value]


def scenarios(quick: bool = False) -> List[Scenario]:
    """The reconstructed chapter-7 and chapter-8 scenarios (shorter runs with ``quick``)."""
    delay = 0.5 if quick else DELAY
    period = 2.0 if quick else SQ_PERIOD
    d_step = 3.0 if quick else 8.0
    d_sq = delay + 2 * period if quick else 11.0  # square: edges at 2, 5, 8 s, 3 s after the last
    d_cart = 4.0 if quick else 15.0
    up = (0.0, 90 * DEG, 0.0)
    zero = (0.0, 0.0, 0.0)

    def stp(q: float) -> Any:
        return step(q, q + AMP, delay)

    def sq(q: float) -> Any:
        return square(q, q + AMP, period, delay)

    sq_edges = [float(e) for e in np.arange(delay, d_sq - 1e-9, period / 2)]
    one = "one link (q3 moves, q1 q2 held)"
    whole = "whole arm (q1 q2 q3 all move)"
    st = f"step +{AMP} rad at {delay:g} s"
    sw = f"square 0/+{AMP} rad, period {period:g} s from {delay:g} s"
    rec = "[reconstruction]"
    tgt = reachable_target()
    return [
        Scenario("1", f"ch7 sim 1 {rec}: {one}, {st}, no gravity, q0=0", False, zero, d_step, [const(0), const(0), stp(0)], [delay]),
        Scenario("2", f"ch7 sim 2 {rec}: {one}, {st}, gravity, q0=(0,90°,0)", True, up, d_step, [const(0), const(up[1]), stp(0)], [delay]),
        Scenario("3", f"ch7 sim 3 {rec}: {one}, {sw}, gravity, q0=(0,90°,0)", True, up, d_sq, [const(0), const(up[1]), sq(0)], sq_edges),
        Scenario("4", f"ch7 sim 4 {rec}: {whole}, {st}, no gravity, q0=0", False, zero, d_step, [stp(0), stp(0), stp(0)], [delay]),
        Scenario("5", f"ch7 sim 5 {rec}: {whole}, {st}, gravity, q0=(0,90°,0)", True, up, d_step, [stp(0), stp(up[1]), stp(0)], [delay]),
        Scenario("6", f"ch7 sim 6 {rec}: {whole}, {sw}, no gravity, q0=0", False, zero, d_sq, [sq(0), sq(0), sq(0)], sq_edges),
        Scenario("7", f"ch7 sim 7 {rec}: {whole}, {sw}, gravity, q0=(0,90°,0)", True, up, d_sq, [sq(0), sq(up[1]), sq(0)], sq_edges),
        Scenario(
            "8",
            f"ch8 {rec}: Cartesian target ({tgt[0]:.3f}, {tgt[1]:.3f}, {tgt[2]:.3f}) m = thesis target "
            f"{THESIS_TARGET} m (unreachable: 1.446 m > 1.2 m reach) scaled to {TARGET_REACH:g} m from the shoulder; "
            "q0=(0,60°,-120°), gravity, vel Kp 1000 Ki 10",
            True,
            (0.0, 60 * DEG, -120 * DEG),
            d_cart,
            cartesian=tgt,
            edges=[0.0],
            payloads=(0.0, 1.0, 2.0),
            gains=dict(CH8_GAINS),
        ),
    ]


# ---------------------------------------------------------------- metrics
def _segment_settling(t: np.ndarray, ee: np.ndarray, t0: float, t1: float) -> float:
    """Settling time of the segment [t0, t1) (see the module docstring); NaN: not settled."""
    seg = (t >= t0 - 1e-9) & (t < t1 - 1e-9)
    ts, es = t[seg], ee[seg]
    ee_f = es[ts >= ts[-1] - 0.25].mean(axis=0)
    tol = max(TOL_REL * float(np.linalg.norm(ee_f - es[0])), TOL_ABS)
    out = np.flatnonzero(np.linalg.norm(es - ee_f, axis=1) >= tol)
    if out.size == 0:
        return 0.0
    t_in = float(ts[out[-1] + 1]) if out[-1] + 1 < len(ts) else math.inf
    if ts[-1] - t_in < MIN_IN_BAND:  # in the band only by chance at the very end
        return math.nan
    return t_in - t0


def metrics(model: popup.Model, r: Any, edges: Sequence[float]) -> Dict[str, Any]:
    """The table's metrics for one closed-loop run ``r`` (see the module docstring)."""
    ok = np.isfinite(r.time)
    t, ee, bend, imu2, tau, q = r.time[ok], r.ee[ok], r.bending[ok], r.imu2[ok], r.tau[ok], r.q[ok]
    t_move = float(edges[0])
    ends = list(edges[1:]) + [t[-1] + 1e-6]
    settle = [_segment_settling(t, ee, a, b) for a, b in zip(edges, ends)]
    after = t >= t_move - 1e-9
    final_bend = bend[t >= t[-1] - 1.0].mean(axis=0)
    # steady offset: Hann-weighted mean of ee − rigid FK over the last 2 s
    last = t >= t[-1] - 2.0
    mi = list(model.core.motor_index)
    qc = np.zeros(len(model.joint_names))
    offs = []
    for qi, ei in zip(q[last], ee[last]):
        qc[mi] = qi
        offs.append(ei - model.end_effector(qc.tolist()))
    w = np.hanning(int(last.sum()) + 2)[1:-1]
    offset = float(np.linalg.norm(np.average(np.asarray(offs), axis=0, weights=w)))
    return {
        "settling_s": math.nan if any(math.isnan(s) for s in settle) else max(settle),
        "rms_bending_rad": float(np.sqrt(np.mean(bend[after] ** 2))),
        "rms_vib_bending_rad": float(np.sqrt(np.mean((bend[after] - final_bend) ** 2))),
        "peak_bending_rad": float(np.max(np.abs(bend))),
        "peak_tip_accel_ms2": float(np.max(np.linalg.norm(imu2 - imu2[0], axis=1))),
        "peak_torque_nm": float(np.max(np.abs(tau))),
        "sat_s": float(np.sum(np.any(np.abs(r.tau_cmd[ok]) >= TAU_MAX * (1 - 1e-9), axis=1)) / SAMPLE_RATE),
        "steady_offset_m": offset,
        "wrinkle_alarms": len(r.alarms),
        "status": r.status,
    }


# ---------------------------------------------------------------- runs
def _models(dt: float = 1e-4) -> Dict[bool, popup.Model]:
    return {True: popup.Model("popup-lab", dt=dt), False: popup.Model("popup-lab", dt=dt, gravity=False)}


def _task(sc: Scenario) -> Task:
    phase = Phase("moving", track=sc.track) if sc.cartesian is None else Phase("moving", cartesian=sc.cartesian)
    return Task([phase], Controller(damping=True, gains=dict(sc.gains)), faults={"wrinkle": "continue"})


def run_scenario(models: Dict[bool, popup.Model], sc: Scenario) -> Tuple[List[Dict[str, Any]], Any, List[Tuple[float, str]]]:
    """Run one scenario with every damping variant and payload as one batch; returns the
    table rows, the batch and the (payload, variant) of each batch entry."""
    model = models[sc.gravity]
    keys = [(p, v) for p in sc.payloads for v, _ in VARIANTS]
    gains = [dict(VARIANTS[i % len(VARIANTS)][1]) for i in range(len(keys))]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", popup.PopupWarning)  # wrinkle alarms: counted, not printed
        batch = model.rollout_task(_task(sc), duration=sc.duration, q0=sc.q0, payload_kg=[p for p, _ in keys], gains=gains, sample_rate=SAMPLE_RATE)
    rows = []
    for b, (pay, var) in enumerate(keys):
        sid = sc.sid if len(sc.payloads) == 1 else sc.sid + "abc"[list(sc.payloads).index(pay)]
        row = {
            "scenario": sid,
            "description": sc.description,
            "payload_kg": pay,
            "gravity": "on" if sc.gravity else "off",
            "damping": var,
            "damp_kp": "/".join(f"{g:g}" for g in batch.gains[b][12:15]),
        }
        row.update(metrics(model, batch[b], sc.edges))
        rows.append(row)
    return rows, batch, keys


def unreachable_row(models: Dict[bool, popup.Model], quick: bool) -> Dict[str, Any]:
    """Try the thesis's chapter-8 target as is: it must fail with UnreachableError."""
    sc = Scenario("8-thesis", "", True, (0.0, 60 * DEG, -120 * DEG), 1.0 if quick else 15.0, cartesian=THESIS_TARGET, gains=dict(CH8_GAINS))
    row: Dict[str, Any] = {
        "scenario": "8-thesis",
        "description": f"ch8 with the thesis's target {THESIS_TARGET} m as is (1.446 m from the shoulder)",
        "payload_kg": 2.0,
        "gravity": "on",
        "damping": "-",
        "damp_kp": "",
    }
    try:
        models[True].run_task(_task(sc), duration=sc.duration, q0=sc.q0)
    except popup.UnreachableError as e:
        print(f"chapter 8, thesis target {THESIS_TARGET} m: UnreachableError (expected):\n  {e}")
        row["status"] = f"UnreachableError: {e}"
        return row
    row["status"] = "ran (NOT expected: the target is outside the 1.2 m reach)"
    print("chapter 8, thesis target: no UnreachableError raised (unexpected)")
    return row


COLUMNS = [
    "scenario",
    "description",
    "payload_kg",
    "gravity",
    "damping",
    "damp_kp",
    "settling_s",
    "rms_bending_rad",
    "rms_vib_bending_rad",
    "peak_bending_rad",
    "peak_tip_accel_ms2",
    "peak_torque_nm",
    "sat_s",
    "steady_offset_m",
    "wrinkle_alarms",
    "status",
]


def run(out_dir: Any = "out/thesis_scenarios", quick: bool = False) -> pd.DataFrame:
    """Run every scenario; write ``table.csv``, ``table.md`` (with the claims) and the
    figures into ``out_dir``; return the table (one row per run, plus row ``8-thesis``)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    models = _models()
    rows: List[Dict[str, Any]] = []
    runs = []
    for sc in scenarios(quick):
        r, batch, keys = run_scenario(models, sc)
        rows += r
        runs.append((sc, batch, keys))
        print(f"scenario {sc.sid}: {len(batch)} runs of {sc.duration:g} s ({time.perf_counter() - t0:.1f} s so far)")
    rows.append(unreachable_row(models, quick))
    df = pd.DataFrame(rows, columns=COLUMNS)
    df.to_csv(out / "table.csv", index=False)
    _plots(runs, out)
    _write_markdown(df, claims(df), out / "table.md", time.perf_counter() - t0, quick)
    return df


# ---------------------------------------------------------------- claims
def _pairs(df: pd.DataFrame, variant: str) -> pd.DataFrame:
    """One row per scenario with the ``off`` and ``variant`` values side by side."""
    off = df[df["damping"] == "off"]
    on = df[df["damping"] == variant]
    return off.merge(on, on="scenario", suffixes=("_off", "_on")).set_index("scenario")


def _fmt(x: Any, nd: int = 4) -> str:
    if isinstance(x, (float, np.floating)):
        return "n.s." if math.isnan(x) else f"{x:.{nd}g}"
    return str(x)


_DAMP_KEYS = [("rms_bending_rad", "RMS bending"), ("peak_torque_nm", "peak torque"), ("peak_tip_accel_ms2", "peak tip accel")]


def _damping_claim(p: pd.DataFrame) -> Tuple[bool, str, List[str]]:
    ok = True
    worse: List[str] = []
    lines = []
    for sid, r in p.iterrows():
        parts = []
        for k, lab in _DAMP_KEYS:
            a, b = float(r[f"{k}_off"]), float(r[f"{k}_on"])
            if not b < a:
                ok = False
                worse.append(f"{sid}:{lab}")
            parts.append(f"{lab} {a:.4g}→{b:.4g} ({100 * (b - a) / a:+.0f} %)")
        a, b = float(r["rms_vib_bending_rad_off"]), float(r["rms_vib_bending_rad_on"])
        parts.append(f"[vibration RMS {a:.4g}→{b:.4g} ({100 * (b - a) / a:+.0f} %)]")
        lines.append(f"    {sid}: " + ", ".join(parts))
    detail = "\n".join(lines)
    if worse:
        detail += "\n    not lowered: " + ", ".join(worse)
    return ok, detail, worse


def _why(p: pd.DataFrame, worse: List[str]) -> str:
    """A short explanation for the metrics that damping does not lower."""
    why = []
    unst = [str(sid) for sid, r in p.iterrows() if r["sat_s_on"] > 2 * r["sat_s_off"] + 0.2]
    if unst:
        why.append(
            f"in {', '.join(unst)} the joint-1 damping PID is beyond its stability limit with the arm "
            "horizontal: a limit cycle at the 66.83 N·m torque limit raises bending, tip acceleration and torque"
        )
    if any("peak torque" in w for w in worse):
        why.append(
            "peak torque: with damping the peak is a spike 20–50 ms after the step / Cartesian start (joint 2), when "
            "the damping PIDs react to the reaction accelerations of the start and add to the velocity error of a "
            "loop with Kp 5000 (1000 in ch8); the later oscillating torques are lower with damping (torque.png)"
        )
    if any("peak tip accel" in w and w.split(":")[0] not in unst for w in worse):
        why.append(
            "peak tip accel: reached 10–40 ms after the start (initial jerk of the reference), before the "
            "13.5 rad/s low-pass damping loop can act; damping only shortens the ring-down after it"
        )
    if any("RMS bending" in w and w.split(":")[0] not in unst for w in worse):
        why.append("RMS bending: dominated by the static gravity sag, which damping cannot change (see the vibration RMS)")
    return "; ".join(why) or "see the numbers"


def claims(df: pd.DataFrame) -> List[Tuple[str, bool, str]]:
    """The thesis's qualitative claims checked on the table: (name, ok, detail), for the
    default damping gains."""
    out: List[Tuple[str, bool, str]] = []
    out_c: List[Tuple[str, bool, str]] = []
    is8 = lambda p: p.index.str.startswith("8")  # noqa: E731
    for variant, label in (("on", "default damping gains"),):
        p = _pairs(df, variant)
        if p.empty:
            continue
        ok, det, worse = _damping_claim(p[~is8(p)])
        out.append((f"(a) [{label}] damping lowers RMS bending, peak torque and peak tip acceleration in every chapter-7 scenario", ok, det + ("" if ok else "\n    why: " + _why(p[~is8(p)], worse))))
        ok, det, worse = _damping_claim(p[is8(p)])
        out_c.append((f"(c) [{label}] chapter 8: damping helps for every payload 0, 1, 2 kg (RMS bending, peak torque, peak tip accel)", ok, det + ("" if ok else "\n    why: " + _why(p[is8(p)], worse))))
    d = df[df["damping"].isin([v for v, _ in VARIANTS])]
    lines = []
    ok_b = True
    for grav, cond, need in (("on", lambda x: x > OFFSET_GRAVITY, "> 1 mm"), ("off", lambda x: x < OFFSET_ZERO, "< 0.5 mm")):
        if not d[d["gravity"] == grav]["settling_s"].notna().any():
            ok_b = False
            lines.append(f"    gravity {grav}: no run settled, nothing to check")
        for var, _ in VARIANTS:
            s = d[(d["gravity"] == grav) & (d["damping"] == var)].set_index("scenario")
            settled = s["settling_s"].notna()
            bad = [str(i) for i, x in s[settled]["steady_offset_m"].items() if not cond(x)]
            ok_b &= not bad
            lines.append(
                f"    gravity {grav:3s} damping {var:8s}: "
                + ", ".join(f"{i} {x * 1e3:.3f}{'' if st else '*'}" for (i, x), st in zip(s["steady_offset_m"].items(), settled))
                + f" mm{f'   <- settled but not {need}: ' + ', '.join(bad) if bad else ''}"
            )
    lines.append(
        "    (* = did not settle: its 'offset' is vibration still ringing at the end of the run, not a steady value; "
        "the claim is checked on the settled runs)"
    )
    det = "\n".join(lines)
    if not ok_b:
        det += "\n    why: see the runs marked; without gravity nothing loads the links at rest"
    out.append(("(b) gravity leaves a steady bending offset (> 1 mm with gravity, < 0.5 mm without; runs that settled)", ok_b, det))
    return out + out_c


# ---------------------------------------------------------------- output
def _md_table(df: pd.DataFrame) -> str:
    cols = list(df.columns)
    head = "| " + " | ".join(cols) + " |\n|" + "|".join("---" for _ in cols) + "|\n"
    lines = []
    for _, r in df.iterrows():
        cells = []
        for c in cols:
            v = r[c]
            if isinstance(v, (float, np.floating)) and math.isnan(v):
                cells.append("n.s." if c == "settling_s" and r["damping"] != "-" else "")
            elif c == "steady_offset_m":
                cells.append(f"{v * 1e3:.3f} mm")
            elif isinstance(v, (float, np.floating)):
                cells.append(_fmt(v))
            else:
                cells.append(str(v).replace("|", "\\|").replace("\n", " "))
        lines.append("| " + " | ".join(cells) + " |")
    return head + "\n".join(lines) + "\n"


def _write_markdown(df: pd.DataFrame, cl: List[Tuple[str, bool, str]], path: Path, wall: float, quick: bool) -> None:
    md = ["# Thesis scenarios on popup-lab (chapter 7 simulations 1–7, chapter 8)", ""]
    md.append(
        "Reconstructed scenarios (the thesis text is not available: amplitudes, periods and durations are our "
        "choices; see the docstring of `examples/thesis_scenarios.py`). Damping: off = `damp_kp` 0, on = library "
        "default (`damp_kp` = 0.01, 0.04, 0.04). Settling: time until "
        "|ee − ee_final| stays below max(2 % of the move, 5 mm) (square waves: worst half-period; n.s. = not "
        "settled); RMS bending from the move start, all four bending channels (vib: minus the final bending); tip "
        "accel = |IMU 2 specific force − its initial value|; peak torque = joint-output torque channel (includes the "
        "rotor-inertia reaction, can exceed the 66.83 N·m drive limit); sat = time the drive command sat at 66.83 N·m; "
        "steady offset = |ee − rigid FK(encoders)|, Hann-weighted over the last 2 s."
    )
    md.append("")
    md.append(f"{'**Quick mode** (short runs, not the reference numbers). ' if quick else ''}Wall time {wall:.1f} s.")
    md.append("")
    md.append(_md_table(df))
    md.append("## Claims")
    md.append("")
    for name, ok, det in cl:
        md.append(f"- **{'PASS' if ok else 'FAIL'}** {name}")
        md.append("")
        md.append("```")
        md.append(det)
        md.append("```")
        md.append("")
    md.append("Figures: `bending.png`, `ee_settling.png`, `torque.png`, `tip_accel.png`.")
    path.write_text("\n".join(md) + "\n")


_STYLE = {"off": ("0.6", "off"), "on": ("C3", "on (default)")}


def _plots(runs: List[Tuple[Scenario, Any, List[Tuple[float, str]]]], out: Path) -> None:
    panels = []
    for sc, batch, keys in runs:
        for pay in sc.payloads:
            tag = sc.sid if len(sc.payloads) == 1 else f"{sc.sid}{'abc'[list(sc.payloads).index(pay)]} ({pay:g} kg)"
            panels.append((tag, sc.edges[-1], {v: batch[i] for i, (p, v) in enumerate(keys) if p == pay}))
    n, ncol = len(panels), 2
    nrow = (n + ncol - 1) // ncol

    def grid(title: str, fn: Any, ylabel: str, fname: str) -> None:
        fig, axes = plt.subplots(nrow, ncol, figsize=(12, 2.3 * nrow), squeeze=False)
        for ax, (tag, t_last, rs) in zip(axes.ravel(), panels):
            fn(ax, rs, t_last)
            ax.set_title(f"scenario {tag}", fontsize=9)
            ax.set_ylabel(ylabel, fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
        for ax in axes.ravel()[n:]:
            ax.set_visible(False)
        axes.ravel()[0].legend(fontsize=7, loc="best")
        for ax in axes[-1]:
            ax.set_xlabel("t [s]", fontsize=8)
        fig.suptitle(title)
        fig.tight_layout()
        fig.savefig(out / fname, dpi=110)
        plt.close(fig)

    def bending(ax: Any, rs: Dict[str, Any], t_last: float) -> None:
        j = int(np.argmax(np.max(np.abs(rs["off"].bending), axis=0)))
        for v, r in rs.items():
            c, lab = _STYLE[v]
            ax.plot(r.time, r.bending[:, j], color=c, lw=0.7, label=lab)
        ax.text(0.99, 0.05, ["d11", "d12", "d21", "d22"][j], transform=ax.transAxes, ha="right", fontsize=8)

    def ee_err(ax: Any, rs: Dict[str, Any], t_last: float) -> None:
        tol = TOL_ABS
        for v, r in rs.items():
            c, lab = _STYLE[v]
            ref = r.ee[r.time >= r.time[-1] - 0.25].mean(axis=0)
            ax.semilogy(r.time, np.maximum(np.linalg.norm(r.ee - ref, axis=1), 1e-5), color=c, lw=0.7, label=lab)
            tol = max(tol, TOL_REL * float(np.linalg.norm(ref - r.ee[np.searchsorted(r.time, t_last - 1e-9)])))
        ax.axhline(tol, color="k", ls=":", lw=0.7)

    def torque(ax: Any, rs: Dict[str, Any], t_last: float) -> None:
        which = []
        for v, r in rs.items():
            c, lab = _STYLE[v]
            j = int(np.argmax(np.max(np.abs(r.tau), axis=0)))
            ax.plot(r.time, r.tau[:, j], color=c, lw=0.6, label=lab)
            which.append(f"{v}: tau{j + 1}")
        ax.text(0.99, 0.04, ", ".join(which), transform=ax.transAxes, ha="right", fontsize=7)
        ax.axhline(TAU_MAX, color="k", ls=":", lw=0.6)
        ax.axhline(-TAU_MAX, color="k", ls=":", lw=0.6)

    def accel(ax: Any, rs: Dict[str, Any], t_last: float) -> None:
        for v, r in rs.items():
            c, lab = _STYLE[v]
            ax.plot(r.time, np.linalg.norm(r.imu2 - r.imu2[0], axis=1), color=c, lw=0.6, label=lab)

    grid("Largest bending channel (of the undamped run): damping off / on", bending, "bending [rad]", "bending.png")
    grid("End-effector distance to its final position (dotted: settling band of the last segment)", ee_err, "|ee - ee_f| [m]", "ee_settling.png")
    grid("Largest motor torque channel (dotted: 66.83 N·m drive limit)", torque, "torque [N·m]", "torque.png")
    grid("Tip acceleration |f2 - f2(0)|", accel, "[m/s²]", "tip_accel.png")


# ---------------------------------------------------------------- main
def main(argv: Optional[Sequence[str]] = None) -> int:
    ap = argparse.ArgumentParser(description="Thesis chapter 7 simulations 1–7 and chapter 8 with and without vibration damping.")
    ap.add_argument("--out", default="out/thesis_scenarios", help="output directory (default out/thesis_scenarios)")
    ap.add_argument("--quick", action="store_true", help="short runs (for tests)")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    df = run(a.out, quick=a.quick)
    show = df.drop(columns=["description"]).copy()
    show["status"] = show["status"].str.slice(0, 40)
    with pd.option_context("display.width", 250, "display.max_columns", 30):
        print(show.to_string(index=False))
    print("\nclaims:")
    for name, ok, det in claims(df):
        print(f"{'PASS' if ok else 'FAIL'}  {name}\n{det}")
    print(f"\nwrote {a.out}/table.csv, table.md, bending.png, ee_settling.png, torque.png, tip_accel.png; {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
