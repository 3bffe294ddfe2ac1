"""Synthetic measured runs: lab-style excitation, a (possibly modified) model as the
"real arm", sensor noise and encoder quantisation. Used by the tests of the diagnosis
(data with a hidden effect) and to make the bundled example run.

::

    t, q = popup.synth.lab_trajectory(duration=12.0, seed=1)
    truth = popup.Model("popup-lab", payload_kg=1.0).with_effect("joint_friction", tau_c=[1.5, 2.0, 0.8])
    run = popup.synth.measured_run(truth, t, q, "runs/friction", seed=1)
"""

from __future__ import annotations

import math
import os
from typing import Any, Callable, Dict, Mapping, Optional, Tuple, Union

import numpy as np

from .io import MeasuredRun, from_sim, read_run, write_run

__all__ = ["lab_trajectory", "measured_run", "reference_run", "NOISE", "ENCODER_RESOLUTION"]

#: Default sensor noise (standard deviation, white Gaussian) per channel group, SI units.
NOISE: Dict[str, float] = {"tau": 0.05, "ee": 2e-4, "imu": 0.02}
#: Encoder resolution at the joint output [rad]: a 14-bit motor encoder behind a 100:1 gear.
ENCODER_RESOLUTION: float = 2 * math.pi / (2**14 * 100)

_POSE0 = np.array([0.0, -math.pi / 2 + 0.6, 0.5])


def _min_jerk(q0: np.ndarray, q1: np.ndarray, s: np.ndarray) -> np.ndarray:
    s = np.clip(s, 0.0, 1.0)[:, None]
    return q0 + (q1 - q0) * (10 * s**3 - 15 * s**4 + 6 * s**5)


def lab_trajectory(duration: float = 12.0, rate: float = 500.0, *, seed: int = 0, amplitude: float = 1.0) -> Tuple[np.ndarray, np.ndarray]:
    """Encoder angles of a lab-style identification experiment [rad] at ``rate`` [Hz]:
    point-to-point minimum-jerk moves with holds (ring-down), a back-and-forth of q1
    (velocity reversals), and a chirp of q3 and q2 (0.2 → 3 Hz). Poses drawn with
    ``seed``; ``amplitude`` scales every excursion. Returns ``(t (N,), q (N, 3))``."""
    rng = np.random.default_rng(seed)
    n = int(round(duration * rate)) + 1
    t = np.arange(n) / rate
    q = np.tile(_POSE0, (n, 1))
    a = float(amplitude)
    # phase plan (fractions of the duration)
    T = duration
    segs = []
    pose = _POSE0.copy()
    t0 = 0.0
    # 1) two moves with holds
    for k in range(2):
        target = _POSE0 + a * rng.uniform([-0.5, -0.3, -0.5], [0.5, 0.3, 0.5])
        segs.append(("move", t0, t0 + 0.12 * T, pose.copy(), target.copy()))
        t0 += 0.12 * T
        segs.append(("hold", t0, t0 + 0.08 * T, target.copy(), target.copy()))
        t0 += 0.08 * T
        pose = target
    # 2) back and forth of q1 (velocity reversals), q2 slowly
    segs.append(("reverse", t0, t0 + 0.25 * T, pose.copy(), pose.copy()))
    t0 += 0.25 * T
    # 3) chirp of q3 and q2
    segs.append(("chirp", t0, t0 + 0.25 * T, pose.copy(), pose.copy()))
    t0 += 0.25 * T
    # 4) return and hold
    segs.append(("move", t0, t0 + 0.06 * T, pose.copy(), _POSE0.copy()))
    t0 += 0.06 * T
    segs.append(("hold", t0, T + 1.0, _POSE0.copy(), _POSE0.copy()))
    for kind, ta, tb, qa, qb in segs:
        m = (t >= ta) & (t < tb)
        if not m.any():
            continue
        s = (t[m] - ta) / (tb - ta)
        if kind in ("move", "hold"):
            q[m] = _min_jerk(qa, qb, s)
        elif kind == "reverse":
            w = 2 * math.pi * 0.6
            env = np.sin(math.pi * s) ** 2
            q[m] = qa + np.column_stack([0.4 * a * env * np.sin(w * (t[m] - ta)), 0.1 * a * env * np.sin(0.5 * w * (t[m] - ta)), 0.0 * s])
        elif kind == "chirp":
            f = 0.2 + (3.0 - 0.2) * s / 2
            ph = 2 * math.pi * f * (t[m] - ta)
            env = np.sin(math.pi * s) ** 2
            q[m] = qa + np.column_stack([0.0 * s, 0.05 * a * env * np.sin(ph), 0.15 * a * env * np.sin(ph)])
    return t, q


def measured_run(
    truth: Any,
    t: np.ndarray,
    q: np.ndarray,
    path: Union[str, "os.PathLike[str]"],
    *,
    seed: int = 0,
    noise: Optional[Mapping[str, float]] = None,
    encoder_resolution: Optional[float] = ENCODER_RESOLUTION,
    disturbance: Optional[Callable[[np.ndarray], Dict[str, np.ndarray]]] = None,
    description: str = "",
    overwrite: bool = True,
) -> MeasuredRun:
    """Simulate ``truth`` (a :class:`popup.Model`, possibly with effects the analyst does
    not know about) replaying the encoder angles ``q`` at times ``t``, add white sensor
    noise (``noise``: std per group ``tau``, ``ee``, ``imu``; default :data:`NOISE`) and
    quantise the encoder columns, write the run to ``path`` and read it back.

    The experiment file declares only what a lab would know: arm, payload, pressures;
    the truth's effects are recorded in its description and in ``[truth]`` keys of the
    description only (never read by the tools). ``disturbance(t) -> {channel: values}``
    adds an unmodelled signal (e.g. a periodic disturbance) to measured channels.
    """
    rng = np.random.default_rng(seed)
    res = truth.replay(t, q, sample_rate=float(round(1.0 / float(np.median(np.diff(t))))))
    df = from_sim(res)
    nz = dict(NOISE if noise is None else noise)
    for c in df.columns:
        if c.startswith("tau"):
            s = nz.get("tau", 0.0)
        elif c.startswith("ee_"):
            s = nz.get("ee", 0.0)
        elif c.startswith("imu"):
            s = nz.get("imu", 0.0)
        else:
            s = 0.0
        if s > 0:
            df[c] = df[c].to_numpy() + rng.normal(0.0, s, len(df))
    if disturbance is not None:
        for c, v in disturbance(df["t"].to_numpy()).items():
            df[c] = df[c].to_numpy() + np.asarray(v, dtype=float)
    if encoder_resolution:
        for j in range(3):
            df[f"q{j + 1}"] = np.round(np.asarray(q[:, j]) / encoder_resolution) * encoder_resolution
    df = df.drop(columns=[c for c in ("dq1", "dq2", "dq3") if c in df.columns])
    exp = df.attrs["experiment"]
    hidden = truth.effects
    exp["description"] = (description + " " if description else "") + (
        f"synthetic run (seed {seed}); hidden effects: {hidden if hidden else 'none'}"
    )
    write_run(path, exp, df, overwrite=overwrite)
    return read_run(path)


def reference_run(
    truth: Any,
    t: np.ndarray,
    ref_q: np.ndarray,
    path: Union[str, "os.PathLike[str]"],
    *,
    controller: Any = None,
    seed: int = 0,
    noise: Optional[Mapping[str, float]] = None,
    encoder_resolution: Optional[float] = ENCODER_RESOLUTION,
    description: str = "",
    overwrite: bool = True,
) -> MeasuredRun:
    """A synthetic ``replay = "reference"`` run: ``truth`` (a :class:`popup.Model` whose
    ``dt`` divides the controller period, possibly with hidden effects) runs closed loop
    tracking the position references ``ref_q`` (N, 3) [rad] given at ``t`` (N,) [s] with
    ``controller`` (a :class:`popup.control.Controller`; default thesis gains) from rest at
    ``ref_q[0]``; sensor noise and encoder quantisation as :func:`measured_run`. The run
    declares the controller in its ``[controller]`` table and the references as
    ``ref_q1..3``; the hidden effects only in its description."""
    from .control import Controller, Phase, Task, samples

    rng = np.random.default_rng(seed)
    t = np.asarray(t, dtype=np.float64)
    ref_q = np.asarray(ref_q, dtype=np.float64)
    ctl = controller if controller is not None else Controller()
    task = Task([Phase("moving", name="Replay", track=[samples(t - t[0], ref_q[:, j]) for j in range(3)], until={"max_time": math.inf})], ctl, faults={"wrinkle": "continue"})
    rate = float(round(1.0 / float(np.median(np.diff(t)))))
    res = truth.run_task(task, duration=float(t[-1] - t[0]), q0=ref_q[0], sample_rate=rate)
    df = from_sim(res)
    df["t"] = df["t"].to_numpy() + t[0]
    nz = dict(NOISE if noise is None else noise)
    for c in df.columns:
        grp = "tau" if c.startswith("tau") else "ee" if c.startswith("ee_") else "imu" if c.startswith("imu") else None
        s = nz.get(grp, 0.0) if grp else 0.0
        if s > 0:
            df[c] = df[c].to_numpy() + rng.normal(0.0, s, len(df))
    if encoder_resolution:
        for j in range(3):
            df[f"q{j + 1}"] = np.round(df[f"q{j + 1}"].to_numpy() / encoder_resolution) * encoder_resolution
    df = df.drop(columns=[c for c in ("dq1", "dq2", "dq3") if c in df.columns])
    exp = df.attrs["experiment"]
    exp["controller"] = ctl.to_dict()
    exp["description"] = (description + " " if description else "") + (
        f"synthetic closed-loop run (seed {seed}); hidden effects: {truth.effects if truth.effects else 'none'}"
    )
    write_run(path, exp, df, overwrite=overwrite)
    return read_run(path)

