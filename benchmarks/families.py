"""Test families of lab-style measured runs for the diagnosis, from two engines.

Each run is what a lab would record on an arm whose physics the analyst does not fully
know: an encoder-replay experiment (motor angles, motor torques, tip IMUs, motion-capture
end effector, optionally pressures) with sensor noise, encoder quantisation, a sample rate
of 200/500/1000 Hz (optionally jittered stamps), a channel set, NaN dropouts, and a hidden
truth (one effect, a pair, none, or a disturbance outside the effect library), driven by
one of three kinds of trajectory (:data:`STYLES`: a lab plan of min-jerk moves, reversals,
a chirp and a sweep; trapezoidal-velocity point-to-point moves; a multisine). The run
folder (``experiment.toml`` + ``measurements.csv``, :func:`popup.io.write_run`) declares
only what a lab knows (arm ``popup-lab``, payload, pressures, ``replay = "encoder"``);
the truth is recorded in the description only (``truth = {json}``).

Two engines make the "real arm":

* ``popup``: ``popup.Model(...).with_effects(truth)`` replays the excitation (RK4 at
  dt = 0.5 ms, output at 2 kHz, interpolated to the stamps) - popup's own effect code.
* ``mujoco``: an MJCF of the same arm (:mod:`mjcf`'s construction from the arm file,
  extended here) simulated by MuJoCo (``RK4``, dt = 1e-4 s; the servo reference and the
  effect forces are set at every RK4 stage by ``mjcb_control``), the motors driven by a
  stiff PD servo that tracks the excitation (the encoder records the motor angle the servo actually reached; the torque channel is
  the force the actuator actually applied, minus the rotor's armature·q̈ - popup's
  convention, docs/engine.md); every effect is written in MuJoCo's own terms, never with
  popup's code:

  ==================== ===================================================================
  joint_friction       Coulomb + viscous + Stribeck as ``qfrc_applied`` on the motor dofs
                       from the motor velocity (sign smoothed over 3 mrad/s, not popup's 10)
  payload_mass         a different payload mass (and centre) in the MJCF
  sensor_delay         the IMU / mocap / torque channels recorded at t - delay
  torsion              an extra hinge about the link axis at the link root (massless body,
                       ``stiffness`` k_t, ``damping`` c_t)
  higher_bending_modes 2 universal joints per link, at the root and at mid-length, with the
                       springs split 2k (root) / k/2 (mid): the split that matches both the
                       tip deflection and the tip rotation of a continuous cantilever under a
                       tip force (popup splits 1.25k / 1.25k); damping split alike; then all
                       four springs of both links scaled together so that the arm's static
                       tip sag (horizontal pose) equals the one-joint arm's
  air_drag             quadratic drag per unit length on every tube piece (8 points per
                       outer piece) as ``xfrc_applied``
  backlash             a rotor body (motor dof, armature, servo, encoder) and, beside it on
                       the same axis, the link-side hinge (its own angle, with 0.1 kg·m² of
                       gear output inertia that turns with the link: the two-mass flexible
                       joint of Spong; until session 67 this inertia sat on the play
                       coordinate, the link angle minus the rotor's, a kinetic energy no
                       gear has, which popup's law could not replay on a compliant gear:
                       the truth's ``gear`` says which), coupled by a dead-zone gear
                       contact on the play q_link − q_rotor; the torque channel reads the
                       torque between the gear's output and the link (a joint torque
                       sensor: the contact torque less J_out·q̈_link, as popup's rigid
                       flanks and the arm without play read it) (K = 1e7 N·m/rad,
                       1000 N·m·s/rad, in contact only; in half the "above" runs a compliant
                       gear, ``gear_k`` 1e4-1e5 N·m/rad at damping ratio 0.2-0.5) - link side free inside the gap,
                       resting against the side its load pushes it to; with ``held`` (the
                       ``backlash_held`` family) no play dof: the servo tracks the play
                       operator of the reference (started centred) and the encoder records
                       the servo angle minus the play, the motor side
  pressure_leak        p(t) = p0·exp(-rate·t): ``jnt_stiffness``/``dof_damping`` of the
                       bending joints set from the arm's k(p), c(p) table every 1 ms (and
                       the p1 p2 channels, when recorded, show p(t))
  wrinkling            a smooth softening spring law (softplus knee of width 5 % of M_w) as
                       ``qfrc_applied`` on each root universal joint
  disturbance          a periodic torque on one bending joint (outside the library)
  ==================== ===================================================================

  ``actuator_saturation`` is not made with MuJoCo: in an encoder replay a torque-limited
  motor simply follows a different path, the encoder records it, and the torque channel
  equals the inverse dynamics of the recorded motion - there is nothing to diagnose. (popup
  models it as a clipped torque reading; that family exists for the popup engine.)

::

    import families
    runs = families.make_family("joint_friction", "mujoco", n=4, seed=1, out_dir="out/fam")
    for path, truth in runs: ...

Everything is deterministic from ``seed`` (NumPy ``SeedSequence`` of the seed, the family
and the run index).
"""

from __future__ import annotations

import copy
import json
import math
import os
import sys
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import popup  # noqa: E402
import mjcf  # noqa: E402  (benchmarks/mjcf.py: the arm-file → MJCF construction)

__all__ = [
    "ENGINES",
    "EFFECT_FAMILIES",
    "FAMILY_KINDS",
    "RunSpec",
    "excitation",
    "excitation_of",
    "STYLES",
    "make_stamps",
    "simulate_popup",
    "MujocoArm",
    "simulate_mujoco",
    "measure",
    "write",
    "make_run",
    "make_family",
    "family_specs",
    "engine_agreement",
    "read_truth",
    "popup_effects",
    "effect_size",
    "member_size",
    "inf_to_str",
    "encoder_resolution",
    "check_rates",
    "pose_range",
    "NOISE",
    "GROUPS",
    "LIBRARY",
    "NEEDS_TORQUE",
    "OTHER_RATES",
    "CHANNEL_SETS",
    "BIASES",
    "MEAS_ORDER",
    "OUT_CHANNELS",
    "SERVO_W",
    "FRICTION_VEPS",
    "BACKLASH_OUT",
    "GEAR_MODEL",
]

ENGINES = ("popup", "mujoco")
NOISE: Dict[str, float] = dict(popup.synth.NOISE)
#: The channel groups (:data:`NOISE`'s keys) and their channels.
GROUPS = {"tau": ["tau1", "tau2", "tau3"], "ee": ["ee_x", "ee_y", "ee_z"], "imu": [f"imu{i}_a{c}" for i in (1, 2) for c in "xyz"]}
ENCODER_RESOLUTION = popup.synth.ENCODER_RESOLUTION
LIBRARY = list(popup.effects.EFFECT_NAMES)
#: effects each engine can make (MuJoCo: see the module docstring for actuator_saturation)
EFFECT_FAMILIES: Dict[str, List[str]] = {
    "popup": list(LIBRARY),
    "mujoco": [e for e in LIBRARY if e != "actuator_saturation"],
}
#: other families: ``backlash_held`` is backlash with the link side held in its gap (a play
#: operator), the law popup tries as an alternative of the free gear
FAMILY_KINDS = ("nominal", "pairs", "disturbance", "backlash_held", *LIBRARY)
CHANNEL_SETS = ("full", "no_mocap", "no_torque", "pressure_noisy")


OTHER_RATES = (100.0, 250.0)
"""Sample rates [Hz] outside the default cycle (200/500/1000 Hz), for ``family_specs(rates=...)``
(``bench_diagnosis_families.py --rates``): a lab logging at 100 Hz sees a second bending
mode near its Nyquist frequency, at 250 Hz an encoder's steps 4 ms apart."""
MEAS_ORDER = ["t", "q1", "q2", "q3", "tau1", "tau2", "tau3", "ee_x", "ee_y", "ee_z",
              "imu1_ax", "imu1_ay", "imu1_az", "imu2_ax", "imu2_ay", "imu2_az", "p1", "p2"]
OUT_CHANNELS = MEAS_ORDER[1:16]  # what both engines simulate (the pressures are p(t))
PRESSURE_NOISE_PA = 50.0
MJ_DT = 1e-4
POPUP_TRUTH_DT = 5e-4


def _seq(seed: int, *keys: Any) -> np.random.SeedSequence:
    """A SeedSequence from the seed and any keys (strings hashed with crc32: stable)."""
    ent = [int(seed) & 0xFFFFFFFF]
    for k in keys:
        ent.append(zlib.crc32(str(k).encode()) if not isinstance(k, (int, np.integer)) else int(k) & 0xFFFFFFFF)
    return np.random.SeedSequence(ent)


def _rng(seed: int, *keys: Any) -> np.random.Generator:
    return np.random.default_rng(_seq(seed, *keys))


# ============================================================================ excitation
Q_LO = np.array([-1.2, -1.45, -1.0])
Q_HI = np.array([1.2, 0.5, 1.3])


def pose_range(wrinkle: bool = False) -> Tuple[np.ndarray, np.ndarray]:
    """Joint range [rad] of the excitations; ``wrinkle``: q2, q3 near horizontal (large
    bending moments)."""
    lo, hi = Q_LO.copy(), Q_HI.copy()
    if wrinkle:
        lo[1], hi[1] = -0.35, 0.25
        lo[2], hi[2] = -0.4, 0.4
    return lo, hi


@dataclass
class Excitation:
    """A smooth (C2) motor trajectory, evaluated anywhere: a min-jerk path through
    waypoints (moves and ring-down holds) plus windowed oscillations (velocity
    reversals, chirps, sweeps) with sin² envelopes."""

    duration: float
    times: np.ndarray  # waypoint times (K,)
    poses: np.ndarray  # waypoints (K, 3)
    osc: List[Dict[str, Any]]  # {t0, t1, joint, amp, f0, f1}
    plan: List[str]

    def __call__(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        k = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.times) - 2)
        ta, tb = self.times[k], self.times[k + 1]
        s = np.clip((t - ta) / np.maximum(tb - ta, 1e-12), 0.0, 1.0)
        h = 10 * s**3 - 15 * s**4 + 6 * s**5
        q = self.poses[k] + (self.poses[k + 1] - self.poses[k]) * h[:, None]
        for o in self.osc:
            m = (t > o["t0"]) & (t < o["t1"])
            if not m.any():
                continue
            tt = t[m] - o["t0"]
            T = o["t1"] - o["t0"]
            env = np.sin(np.pi * tt / T) ** 2
            f = o["f0"] + (o["f1"] - o["f0"]) * tt / (2 * T)  # linear chirp: phase 2π(f0 t + (f1-f0) t²/2T)
            finst = o["f0"] + (o["f1"] - o["f0"]) * tt / T
            # the amplitude falls as 1/(1 + f²) (f in Hz: bounded acceleration, and smooth so
            # that q stays C2): the sweep crosses the first bending mode (2.4-3.2 Hz with
            # 1-2 kg), where ζ ≈ 2 % amplifies ~25×
            amp = o["amp"] * 2.0 / (1.0 + finst**2) if o["f1"] != o["f0"] else o["amp"]
            q[m, o["joint"]] += amp * env * np.sin(2 * np.pi * f * tt)
        return q


def excitation(duration: float, seed: int, *, amplitude: float = 1.0, pose0: Optional[Sequence[float]] = None,
               wrinkle: bool = False) -> Excitation:
    """A lab identification experiment of ``duration`` [s] drawn from ``seed``: a random
    start pose (held 0.5 s: the run starts at rest), then a shuffled plan of blocks -
    point-to-point moves with ring-down holds, back-and-forth of q1 and of q2/q3
    (velocity reversals), a chirp of q2+q3 up to 2.5-4 Hz (amplitude ∝ 1/(1 + f²)), a
    large slow sweep of q1 out of the vertical plane - and a final hold. ``amplitude`` scales every excursion.
    ``wrinkle``: poses near horizontal (large bending moments)."""
    rng = _rng(seed, "excitation")
    a = float(amplitude)
    lo, hi = pose_range(wrinkle)
    p0 = np.array(pose0, dtype=float) if pose0 is not None else rng.uniform(lo * 0.7, hi * 0.7)
    blocks = ["move", "move", "rev_q1", "rev_q23", "chirp", "sweep_q1"]
    if duration >= 14:
        blocks += ["move", "rev_q23"]
    order = list(rng.permutation(blocks))
    hold0, holdN = 0.5, max(0.8, 0.06 * duration)
    # short runs (quick tests) get fewer blocks rather than frantic ones (>= ~1.4 s each)
    order = order[:int(np.clip((duration - hold0 - holdN) / 1.4, 2, len(order)))]
    weights = {"move": 1.6, "rev_q1": 2.0, "rev_q23": 1.6, "chirp": 2.4, "sweep_q1": 2.0}
    total = sum(weights[b] for b in order)
    scale = (duration - hold0 - holdN) / total
    times, poses, osc = [0.0, hold0], [p0, p0], []
    t0, pose = hold0, p0.copy()

    def clamp(p: np.ndarray) -> np.ndarray:
        return np.clip(p, lo, hi)

    for b in order:
        T = weights[b] * scale
        if b == "move":
            tgt = clamp(pose + a * rng.uniform([-0.6, -0.4, -0.6], [0.6, 0.4, 0.6]))
            tm = T * rng.uniform(0.45, 0.6)
            times += [t0 + tm, t0 + T]
            poses += [tgt, tgt]
            pose = tgt
        elif b == "sweep_q1":
            # out of plane: q1 swings by a large angle and comes back (two reversals)
            amp = a * rng.uniform(0.5, 0.9) * rng.choice([-1.0, 1.0])
            tgt = clamp(pose + np.array([amp, 0.0, 0.0]))
            times += [t0 + 0.5 * T, t0 + T]
            poses += [tgt, pose.copy()]
        else:
            if b == "rev_q1":
                specs = [(0, a * rng.uniform(0.25, 0.4), rng.uniform(0.4, 0.75), None), (1, a * rng.uniform(0.05, 0.1), rng.uniform(0.2, 0.4), None)]
            elif b == "rev_q23":
                j = int(rng.integers(1, 3))
                specs = [(j, a * rng.uniform(0.15, 0.3), rng.uniform(0.4, 0.8), None)]
            else:  # chirp of q2 and q3 together, 0.2 Hz -> 2.5..4 Hz
                f1 = rng.uniform(2.5, 4.0)
                specs = [(1, a * rng.uniform(0.03, 0.06), 0.2, f1), (2, a * rng.uniform(0.1, 0.18), 0.2, f1)]
            for j, amp, f0, f1 in specs:
                osc.append({"t0": t0, "t1": t0 + T, "joint": j, "amp": float(amp), "f0": float(f0), "f1": float(f0 if f1 is None else f1)})
            times += [t0 + T]
            poses += [pose.copy()]
        t0 += T
    times += [duration + 1.0]  # the final hold (ring-down)
    poses += [pose]
    return Excitation(duration=float(duration), times=np.array(times), poses=np.array(poses), osc=osc, plan=[str(b) for b in order])


#: Excitation styles (:func:`excitation_of`): ``lab`` (:func:`excitation`: min-jerk moves,
#: reversals, a chirp, a sweep), ``trapezoid`` (:class:`TrapezoidMoves`: point-to-point moves
#: with trapezoidal velocity profiles, as a motion controller plans them) and ``multisine``
#: (:class:`MultiSine`: a Schroeder-phased multisine on every joint at once).
STYLES = ("lab", "trapezoid", "multisine")


@dataclass
class TrapezoidMoves:
    """Point-to-point moves as an industrial motion controller plans them: every joint on
    a trapezoidal velocity profile (acceleration steps of ``a_max`` [rad/s²], cruise at
    ``v_max`` [rad/s]), the joints synchronised to the slowest, dwells of 0.3-1.2 s
    between moves (ring-down); moves, there-and-back moves (velocity reversals) and q1
    alone there and back (out of plane). C1 only: q̈ jumps at each phase change."""

    duration: float
    p0: np.ndarray
    moves: List[Tuple[float, np.ndarray, np.ndarray, float, float]]  # (t0, start, delta, t_acc, t_cruise)
    a_max: float
    plan: List[str] = field(default_factory=list)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        q = np.tile(self.p0, (t.size, 1))
        for t0, start, delta, ta, tc in self.moves:
            T = 2 * ta + tc
            s = np.clip(t - t0, 0.0, T)
            # the path parameter u in [0, 1]: accelerate, cruise, decelerate (u'' = ±1/(ta (ta + tc)))
            a = 1.0 / (ta * (ta + tc))
            u = np.where(s < ta, 0.5 * a * s**2,
                         np.where(s < ta + tc, 0.5 * a * ta**2 + a * ta * (s - ta),
                                  1.0 - 0.5 * a * np.maximum(T - s, 0.0) ** 2))
            on = t >= t0
            q[on] = start[None, :] + delta[None, :] * u[on, None]
        return q


def trapezoid_moves(duration: float, seed: int, *, amplitude: float = 1.0, wrinkle: bool = False) -> TrapezoidMoves:
    """A :class:`TrapezoidMoves` experiment of ``duration`` [s] drawn from ``seed``."""
    rng = _rng(seed, "trapezoid")
    lo, hi = pose_range(wrinkle)
    a_max = float(rng.uniform(2.5, 6.0)) * max(amplitude, 0.5)
    v_max = float(rng.uniform(0.6, 1.4)) * amplitude
    p0 = rng.uniform(lo * 0.7, hi * 0.7)
    pose, t, moves, plan = p0.copy(), 0.5, [], []

    def profile(d: float) -> Tuple[float, float]:
        ta = v_max / a_max
        if d < v_max * ta:  # a triangle: never reaches v_max
            return math.sqrt(d / a_max), 0.0
        return ta, (d - v_max * ta) / v_max

    while t < duration - 1.5:
        kind = str(rng.choice(["move", "there_and_back", "q1_there_and_back"]))
        if kind == "q1_there_and_back":
            delta = np.array([rng.uniform(0.4, 0.9) * amplitude * rng.choice([-1.0, 1.0]), 0.0, 0.0])
        elif kind == "there_and_back":
            delta = 0.6 * amplitude * rng.uniform([-0.7, -0.45, -0.7], [0.7, 0.45, 0.7])
        else:
            delta = amplitude * rng.uniform([-0.7, -0.45, -0.7], [0.7, 0.45, 0.7])
        delta = np.clip(pose + delta, lo, hi) - pose
        d = float(np.max(np.abs(delta)))
        if d < 1e-3:
            continue
        ta, tc = profile(d)
        legs = [delta] if kind == "move" else [delta, -delta]
        dwell = [float(rng.uniform(0.3, 1.2)) for _ in legs]
        if t + len(legs) * (2 * ta + tc) + sum(dwell[:-1]) > duration - 0.8:
            break
        for leg, dw in zip(legs, dwell):
            moves.append((t, pose.copy(), leg, ta, tc))
            pose = pose + leg
            t += 2 * ta + tc + dw
        plan.append(kind)
    return TrapezoidMoves(duration=float(duration), p0=p0, moves=moves, a_max=a_max, plan=plan)


@dataclass
class MultiSine:
    """A Schroeder-phased multisine on every joint at once (the system-identification
    classic): ``freqs`` [Hz] log-spaced over 0.1-3.5 Hz per joint, amplitudes ∝ 1/(1 + f²),
    around a random pose, faded in and out over 1 s (the run starts and ends at rest)."""

    duration: float
    p0: np.ndarray
    comps: List[Tuple[int, float, float, float]]  # (joint, f [Hz], amplitude [rad], phase)
    plan: List[str] = field(default_factory=lambda: ["multisine"])

    def __call__(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        def ramp(x: np.ndarray) -> np.ndarray:
            x = np.clip(x, 0.0, 1.0)
            return 10 * x**3 - 15 * x**4 + 6 * x**5
        env = ramp(t - 0.5) * ramp(self.duration - 0.5 - t)
        q = np.tile(self.p0, (t.size, 1))
        for j, f, a, ph in self.comps:
            q[:, j] += a * env * np.sin(2 * np.pi * f * t + ph)
        return q


def multisine(duration: float, seed: int, *, amplitude: float = 1.0, wrinkle: bool = False) -> MultiSine:
    """A :class:`MultiSine` experiment of ``duration`` [s] drawn from ``seed``."""
    rng = _rng(seed, "multisine")
    lo, hi = pose_range(wrinkle)
    p0 = 0.5 * (lo + hi) + rng.uniform(-0.2, 0.2, 3) * (hi - lo)
    comps = []
    total = np.array([0.45, 0.2, 0.4]) * amplitude  # peak excursion budget per joint [rad]
    total = np.minimum(total, 0.95 * np.minimum(p0 - lo, hi - p0))  # the sum of the amplitudes stays in range
    for j in range(3):
        n = int(rng.integers(5, 9))
        f = np.exp(np.linspace(math.log(rng.uniform(0.08, 0.15)), math.log(rng.uniform(2.5, 3.5)), n))
        a = 1.0 / (1.0 + f**2)
        a *= total[j] / a.sum()
        k = np.arange(n)
        ph = -np.pi * k * (k + 1) / n + rng.uniform(0, 2 * np.pi)  # Schroeder phases: a low crest factor
        comps += [(j, float(fi), float(ai), float(p)) for fi, ai, p in zip(f, a, ph)]
    return MultiSine(duration=float(duration), p0=p0, comps=comps)


def excitation_of(style: str, duration: float, seed: int, *, amplitude: float = 1.0, wrinkle: bool = False) -> Any:
    """The excitation of ``style`` (:data:`STYLES`): a callable t [s] → q (N, 3) [rad]."""
    if style == "lab":
        return excitation(duration, seed=seed, amplitude=amplitude, wrinkle=wrinkle)
    if style == "trapezoid":
        return trapezoid_moves(duration, seed, amplitude=amplitude, wrinkle=wrinkle)
    if style == "multisine":
        return multisine(duration, seed, amplitude=amplitude, wrinkle=wrinkle)
    raise ValueError(f"excitation style {style!r}: expected one of {STYLES}")


def make_stamps(duration: float, rate: float, jitter: float, rng: np.random.Generator, grid: float = MJ_DT) -> np.ndarray:
    """Sample instants [s] at ``rate`` [Hz] over ``duration``, each moved by a Gaussian
    jitter of ``jitter`` × the period (clipped at ±0.35 periods), on the ``grid`` (a
    10 kHz clock). Strictly increasing."""
    n = int(round(duration * rate)) + 1
    per = 1.0 / rate
    base = np.arange(n) * per
    if jitter > 0:
        base = base + np.clip(rng.normal(0.0, jitter * per, n), -0.35 * per, 0.35 * per)
        base[0] = 0.0
    idx = np.round(base / grid).astype(np.int64)
    idx = np.clip(idx, 0, int(round(duration / grid)))
    idx = np.unique(idx)
    return idx / round(1.0 / grid)


# ============================================================================ run spec
@dataclass
class RunSpec:
    """Everything that makes one run (the truth and the lab conditions)."""

    engine: str
    family: str
    index: int
    seed: int
    effects: Dict[str, Dict[str, Any]] = field(default_factory=dict)  # engine-specific truth
    disturbance: Optional[Dict[str, Any]] = None
    level: str = "above"
    payload_kg: float = 1.0
    pressure_pa: Tuple[float, float] = (30e3, 30e3)
    duration: float = 10.0
    rate: float = 500.0
    jitter: float = 0.0
    amplitude: float = 1.0
    style: str = "lab"  # the excitation (STYLES)
    wrinkle_poses: bool = False
    noise_scale: float = 1.0
    noise_lowpass_hz: float = 0.0  # IMU and torque noise through a 1-pole low-pass (0: white)
    encoder_bits: int = 14
    channels: str = "full"
    dropouts: bool = False
    biases: Dict[str, float] = field(default_factory=dict)  # a constant per channel (sensor biases; BIASES)
    effect_sigma: Dict[str, float] = field(default_factory=dict)  # filled by make_run
    member_sigma: Dict[str, float] = field(default_factory=dict)  # pairs: filled by make_run (member_size)
    near_target_sigma: Optional[float] = None  # filled by calibrate_near

    @property
    def name(self) -> str:
        return f"{self.engine}-{self.family}-{self.index:03d}"

    def truth(self) -> Dict[str, Any]:
        d = asdict(self)
        if not d["member_sigma"]:
            del d["member_sigma"]  # only pairs have one (truths made before session 65 have none)
        bl = self.effects.get("backlash") or {}
        held = list(bl.get("held", [])) + [0.0] * 3
        if self.engine == "mujoco" and any(float(g) > 0 and not held[i] for i, g in enumerate(bl.get("gap", []))):
            d["gear"] = GEAR_MODEL  # some joint's link side is free in its gap: the two-mass gear
        d["hidden"] = sorted(self.effects)
        d["kind"] = ("nominal" if self.family == "nominal" else "disturbance" if self.family == "disturbance"
                     else "pair" if self.family == "pairs" else "effect")
        return json.loads(json.dumps(d, default=_json_default))


def _json_default(o: Any) -> Any:
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)


def inf_to_str(v: Any) -> Any:
    if isinstance(v, float) and math.isinf(v):
        return "inf"
    if isinstance(v, (list, tuple)):
        return [inf_to_str(x) for x in v]
    if isinstance(v, dict):
        return {k: inf_to_str(x) for k, x in v.items()}
    return v


# ============================================================================ popup engine
def popup_effects(effects: Mapping[str, Mapping[str, Any]]) -> Dict[str, Dict[str, Any]]:
    return {e: {k: (np.array(v, dtype=float) if isinstance(v, (list, tuple)) else v) for k, v in p.items()} for e, p in effects.items()}


def simulate_popup(spec: RunSpec, exc: Excitation, stamps: np.ndarray) -> Dict[str, np.ndarray]:
    """Noise-free channels of ``spec`` at ``stamps`` from popup's own replay (the truth
    model = the declared one with ``spec.effects``), plus the disturbance added to the
    measured channels (popup cannot put a torque on a bending joint in a replay)."""
    nominal = popup.Model("popup-lab", payload_kg=spec.payload_kg, pressure_pa=spec.pressure_pa, dt=POPUP_TRUTH_DT)
    truth = nominal.with_effects(popup_effects(spec.effects)) if spec.effects else nominal
    tf = np.arange(0.0, spec.duration + 1e-9, POPUP_TRUTH_DT)
    res = truth.replay(tf, exc(tf), sample_rate=1.0 / POPUP_TRUTH_DT)
    ts = np.asarray(res.channel("t"))
    out: Dict[str, np.ndarray] = {"t": stamps.copy()}
    k = np.round(stamps / POPUP_TRUTH_DT).astype(np.int64)
    on_grid = bool(np.all(np.abs(k * POPUP_TRUTH_DT - stamps) < 1e-9)) and k.max() < len(ts)
    from scipy.interpolate import CubicSpline

    for c in OUT_CHANNELS + ["p1", "p2"]:
        y = np.asarray(res.channel(c), dtype=float)
        out[c] = y[k] if on_grid else CubicSpline(ts, y)(stamps)
    if spec.disturbance:
        dist = spec.disturbance
        w = 2 * np.pi * dist["freq_hz"]
        out["imu2_az"] = out["imu2_az"] + dist["imu_amp"] * np.sin(w * stamps + dist["phase"])
        out["ee_z"] = out["ee_z"] + dist["ee_amp"] * np.sin(w * stamps + dist["phase"] + 0.5)
    return out


# ============================================================================ MuJoCo engine
def _rx(a: float) -> np.ndarray:
    return mjcf._rx(a)


def _rz(a: float) -> np.ndarray:
    return mjcf._rz(a)


def _tube_inertia(m: float, r: float, l: float) -> np.ndarray:
    return np.diag([m * r * r, m * (r * r / 2 + l * l / 12), m * (r * r / 2 + l * l / 12)])


def _body_parts(spec: Dict[str, Any], ib: int) -> List[Dict[str, Any]]:
    """Parts of arm-file body ``ib`` (0-based): dicts with mass, com (3,), extra inertia
    (3, 3) about the part's centre, and for tubes radius/length (kept for splitting)."""
    body = spec["bodies"][ib]
    out = []
    for p in body.get("parts", []):
        e = p.get("inertia_kgm2", [0.0] * 6)
        ic = np.array([[e[0], e[3], e[4]], [e[3], e[1], e[5]], [e[4], e[5], e[2]]], dtype=float)
        d = {"mass": float(p["mass_kg"]), "com": np.array(p["com_m"], dtype=float), "extra": ic, "shape": p["shape"]}
        if p["shape"] == "tube":
            r = p.get("radius_m")
            d["radius"] = float(spec["links"][body["link"] - 1]["radius_m"] if r is None else r)
            d["length"] = float(p["length_m"])
        out.append(d)
    return out


def _combine(parts: Sequence[Dict[str, Any]]) -> Tuple[float, np.ndarray, np.ndarray]:
    mass = sum(p["mass"] for p in parts)
    if mass <= 0:
        return 0.0, np.zeros(3), np.zeros((3, 3))
    com = sum(p["mass"] * p["com"] for p in parts) / mass
    inertia = np.zeros((3, 3))
    for p in parts:
        ic = p["extra"].copy()
        if p["shape"] == "tube":
            ic = ic + _tube_inertia(p["mass"], p["radius"], p["length"])
        r = p["com"] - com
        inertia += ic + p["mass"] * (np.dot(r, r) * np.eye(3) - np.outer(r, r))
    return mass, com, inertia


def _split_tubes(parts: Sequence[Dict[str, Any]], cut: float) -> Tuple[List[Dict[str, Any]], List[Dict[str, Any]]]:
    """Split the tube parts of an outer body (frame at its tip, tube along -x) at
    x = ``cut``: pieces with x < cut (inner) and x > cut (outer); point parts stay outer.
    Mass and extra inertia are split by length; positions stay in the outer frame."""
    inner, outer = [], []
    for p in parts:
        if p["shape"] != "tube" or p["length"] <= 0:
            outer.append(dict(p))
            continue
        a, b = p["com"][0] - p["length"] / 2, p["com"][0] + p["length"] / 2
        for lo, hi, dst in ((a, min(b, cut), inner), (max(a, cut), b, outer)):
            if hi - lo <= 1e-12:
                continue
            f = (hi - lo) / p["length"]
            q = dict(p)
            q["mass"], q["length"], q["extra"] = p["mass"] * f, hi - lo, p["extra"] * f
            q["com"] = np.array([(lo + hi) / 2, p["com"][1], p["com"][2]])
            dst.append(q)
    return inner, outer


@dataclass
class _Row:
    name: str
    kind: str  # motor | bending | torsion | rotor | play
    pos: np.ndarray
    quat: np.ndarray
    axis: np.ndarray
    jpos: np.ndarray
    parts: List[Dict[str, Any]]
    stiffness: float = 0.0
    damping: float = 0.0
    armature: float = 0.0
    link: int = 0
    motor: int = -1  # motor index for motor/rotor/play rows
    body: str = ""
    tubes: List[Dict[str, Any]] = field(default_factory=list)  # world-drag pieces: (x0, x1, radius)


def _dh_row(name: str, kind: str, d: float, a: float, alpha: float, off: float, parts: List[Dict[str, Any]], **kw: Any) -> _Row:
    rg = _rz(off) @ _rx(alpha)
    pg = _rz(off) @ np.array([a, 0.0, d])
    return _Row(name=name, kind=kind, pos=pg, quat=mjcf._mat2quat(rg), axis=rg.T @ np.array([0.0, 0.0, 1.0]), jpos=-rg.T @ pg, parts=parts, **kw)


def _plain_row(name: str, kind: str, axis: Sequence[float], **kw: Any) -> _Row:
    return _Row(name=name, kind=kind, pos=np.zeros(3), quat=np.array([1.0, 0, 0, 0]), axis=np.array(axis, dtype=float), jpos=np.zeros(3), parts=[], **kw)


def _k_of_p(spec: Dict[str, Any], link: int, p: float) -> Tuple[float, float]:
    st = spec["stiffness"]
    lk = spec["links"][link]
    scale = lk.get("stiffness_scale")
    if scale is None:
        scale = (lk["radius_m"] / st["reference_radius_m"]) ** 3
    return (scale * float(np.interp(p, st["pressure_pa"], st["k_nm_per_rad"])),
            scale * float(np.interp(p, st["pressure_pa"], st["c_nms_per_rad"])))


def _newton(res: Callable[[np.ndarray], np.ndarray], x: np.ndarray, *, tol: float = 1e-10, it: int = 60) -> np.ndarray:
    """Solve res(x) = 0: Newton with a forward-difference Jacobian, least-squares steps
    (flat directions, e.g. a joint inside its backlash gap, stay put) and backtracking."""
    x = np.array(x, dtype=float)
    r = res(x)
    for _ in range(it):
        nr = float(np.abs(r).max())
        if nr < tol:
            break
        J = np.empty((len(r), len(x)))
        for j in range(len(x)):
            h = 1e-7 * max(1.0, abs(x[j]))
            xp = x.copy()
            xp[j] += h
            J[:, j] = (res(xp) - r) / h
        dx = -np.linalg.lstsq(J, r, rcond=1e-12)[0]
        step = 1.0
        while step > 1e-6:
            xn = x + step * dx
            rn = res(xn)
            if float(np.abs(rn).max()) < nr:
                break
            step *= 0.5
        else:
            break
        x, r = xn, rn
    return x


def _knee(z: float) -> float:
    """Smooth min(z, 1): z - w·ln(1 + e^((z-1)/w)), w = WRINKLE_WIDTH."""
    u = (z - 1.0) / WRINKLE_WIDTH
    return z - WRINKLE_WIDTH * math.log1p(math.exp(u)) if u < 40 else 1.0


#: servo: natural frequency [rad/s] and damping ratio on the 0.8 kg·m² rotor
SERVO_W = 1500.0
SERVO_ZETA = 1.0
#: gear contact of the backlash joint: stiff enough that the gear's own compliance moves
#: the tip by ~0.02 noise sigma at 40 N·m (it is not the effect under test)
BACKLASH_K = 1e7
BACKLASH_D = 1000.0
#: the gear's output inertia J_out [kg·m²], armature of the link-side dof (its own angle,
#: beside the rotor's full armature): without it the contact sees only the 3 cm root piece
#: (~1e-5 kg·m²) at high frequency and would be far too stiff for any explicit step (here
#: ω ≈ 1e4 rad/s). It turns with the link, so in contact the gear drives it too; the torque
#: channel, read at the link, leaves its J_out·q̈ out. (Until session 67 it sat on the play
#: coordinate, where in contact it did nothing; with a gap of 1e-7 rad that arm differed from
#: the nominal one by 0.2 noise sigma, the gear compliance.)
BACKLASH_OUT = 0.1
#: how a MuJoCo run's gear with play is built (the truth's ``gear``; runs made before
#: session 67 have none: their output inertia sat on the play coordinate; at c9b456d the
#: torque was read at the gear, the output inertia's own torque in it, without "; torque
#: read at the link")
GEAR_MODEL = "two-mass: rotor and link side siblings, output inertia on the link angle; torque read at the link"
FRICTION_VEPS = 0.003
DRAG_RHO = 1.204
WRINKLE_WIDTH = 0.05
_KNEE0 = _knee(0.0)


class MujocoArm:
    """The popup-lab arm in MuJoCo with the effects of ``effects`` built in (module doc).

    ``MujocoArm(payload_kg, pressure_pa, effects, disturbance).run(exc, stamps)`` gives the
    noise-free channels at the stamps (the same names and conventions as popup)."""

    def __init__(self, payload_kg: float, pressure_pa: Sequence[float], effects: Optional[Mapping[str, Mapping[str, Any]]] = None,
                 disturbance: Optional[Mapping[str, Any]] = None, *, dt: float = MJ_DT):
        import mujoco

        self.mujoco = mujoco
        self.effects = {k: dict(v) for k, v in (effects or {}).items()}
        self.disturbance = dict(disturbance) if disturbance else None
        self.dt = float(dt)
        self.pressure = (float(pressure_pa[0]), float(pressure_pa[1]))
        nominal = popup.Model("popup-lab", payload_kg=payload_kg, pressure_pa=self.pressure)
        ad = mjcf.arm_data(nominal)
        self.spec = ad["spec"]
        pm = self.effects.get("payload_mass", {})
        self.payload = float(payload_kg) + float(pm.get("delta_kg", 0.0))
        self.payload_com = np.array(self.spec["payload"]["com_m"], dtype=float) + np.array(pm.get("com_offset_m", [0.0, 0.0, 0.0]), dtype=float)
        self.k_link = [_k_of_p(self.spec, l, self.pressure[l])[0] for l in range(2)]
        self.c_link = [_k_of_p(self.spec, l, self.pressure[l])[1] for l in range(2)]
        self.hbm_scale = 1.0
        bl = self.effects.get("backlash", {})
        gap = [float(x) for x in bl.get("gap", [0.0, 0.0, 0.0])]
        held = [bool(x) for x in bl.get("held", [0.0, 0.0, 0.0])]
        # the gear contact: stiff (BACKLASH_K) unless the truth gives a compliant gear
        self.gear_kd = (float(bl.get("gear_k", BACKLASH_K)), float(bl.get("gear_d", BACKLASH_D)))
        self.free_gap = [0.0 if h else g for g, h in zip(gap, held)]
        self.held_gap = [g if h else 0.0 for g, h in zip(gap, held)]
        self._build()
        if "higher_bending_modes" in self.effects:
            self._match_static_sag(nominal)

    def _build(self) -> None:
        self.rows = self._rows()
        self.xml = self._xml()
        self.m = self.mujoco.MjModel.from_xml_string(self.xml)
        self.d = self.mujoco.MjData(self.m)
        self._index()

    def _match_static_sag(self, nominal: Any) -> None:
        """Scale both links' segment springs together (``hbm_scale``) so that the arm's
        static tip sag in the horizontal pose (motors at 0, truth payload) equals the
        one-joint model's: the 2k/k/2 split matches a link's tip deflection under a tip
        force but turns its tip 1.5× as much, which alone would sag the arm ~30 % more."""
        ref = nominal.with_params(payload_kg=self.payload) if self.payload != nominal.payload_kg else nominal
        z0 = float(ref.end_effector(ref.rest_state((0.0, 0.0, 0.0)))[2])

        def sag(scale: float) -> float:
            self.hbm_scale = scale
            self._build()
            q = self.rest((0.0, 0.0, 0.0))
            self.d.qpos[:] = q
            self.mujoco.mj_kinematics(self.m, self.d)
            return float(self.d.site_xpos[self.ee_site][2]) - z0

        a, fa = 1.0, sag(1.0)
        b, fb = 1.5, sag(1.5)
        for _ in range(12):
            if abs(fb) < 1e-9 or fb == fa:
                break
            a, fa, b = b, fb, b - fb * (b - a) / (fb - fa)
            fb = sag(b)
        if abs(fb) > 1e-7:
            sag(b)  # leave the model built with the last scale
        self.hbm_scale = b

    # ------------------------------------------------------------------ model
    def _rows(self) -> List[_Row]:
        spec = self.spec
        joints = spec["joints"]
        arm_r = spec["motors"]["armature_kgm2"]
        tors = self.effects.get("torsion")
        segs = self.effects.get("higher_bending_modes")
        gaps = self.free_gap
        rows: List[_Row] = []
        nmotor = 0
        first_bend: Dict[int, float] = {}
        for i, j in enumerate(joints):
            parts = _body_parts(spec, i)
            if spec["payload"]["body"] == i + 1 and self.payload > 0:
                parts.append({"mass": self.payload, "com": self.payload_com, "extra": np.zeros((3, 3)), "shape": "point"})
            off = j.get("theta_offset", 0.0)
            if j["kind"] == "motor":
                mi = nmotor
                nmotor += 1
                if float(gaps[mi]) > 0:
                    # the two sides of the gear as siblings on the same axis (the flexible joint
                    # of Spong): a massless rotor body with the whole armature, and the link side
                    # with a small inertia of its own on its own angle (the gear's output inertia,
                    # which turns with the link); the contact acts on their difference
                    rows.append(_plain_row(f"rotor{mi + 1}", "rotor", [0, 0, 1], armature=arm_r[mi], motor=mi))
                    rows.append(_dh_row(j["name"], "play", j["d"], j["a"], j["alpha"], off, parts, armature=BACKLASH_OUT, motor=mi, body=f"body{i + 1}"))
                else:
                    rows.append(_dh_row(j["name"], "motor", j["d"], j["a"], j["alpha"], off, parts, armature=arm_r[mi], motor=mi, body=f"body{i + 1}"))
                continue
            li = j["link"] - 1
            k, c = self.k_link[li], self.c_link[li]
            if li not in first_bend:  # first row of the universal joint
                first_bend[li] = j["alpha"]
                if tors is not None and math.isfinite(float(tors["k_t"][li])):
                    rows.append(_plain_row(f"t{li + 1}", "torsion", [1, 0, 0], stiffness=float(tors["k_t"][li]), damping=float(tors.get("c_t", [0, 0])[li]), link=li))
                s = 2.0 * float(segs.get("k_scale", [1.0, 1.0])[li]) * self.hbm_scale if segs else 1.0
                rows.append(_dh_row(j["name"], "bending", j["d"], j["a"], j["alpha"], off, parts, stiffness=s * k, damping=s * c, link=li, body=f"body{i + 1}"))
                continue
            L = float(j["a"])
            if segs:
                ks = float(segs.get("k_scale", [1.0, 1.0])[li]) * self.hbm_scale
                a1 = first_bend[li]
                inner, outer = _split_tubes(parts, -L / 2)
                for p in inner:
                    p["com"] = p["com"] + np.array([L / 2, 0, 0])
                rows.append(_dh_row(j["name"], "bending", 0.0, L / 2, -a1, 0.0, inner, stiffness=2 * k * ks, damping=2 * c * ks, link=li, body=f"body{i + 1}_s1"))
                rows.append(_dh_row(joints[i - 1]["name"] + "_2", "bending", 0.0, 0.0, a1, 0.0, [],
                                    stiffness=0.5 * k * ks, damping=0.5 * c * ks, link=li, body=f"body{i + 1}_g2"))
                rows.append(_dh_row(j["name"] + "_2", "bending", j["d"], L / 2, j["alpha"], off, outer, stiffness=0.5 * k * ks, damping=0.5 * c * ks, link=li, body=f"body{i + 1}"))
            else:
                rows.append(_dh_row(j["name"], "bending", j["d"], j["a"], j["alpha"], off, parts, stiffness=k, damping=c, link=li, body=f"body{i + 1}"))
        for n, r in enumerate(rows):
            if not r.body:
                r.body = f"x_{r.name}"
            # drag pieces: tube parts along the body's x axis
            r.tubes = [{"x0": p["com"][0] - p["length"] / 2, "x1": p["com"][0] + p["length"] / 2, "r": p["radius"]} for p in r.parts if p["shape"] == "tube"]
        return rows

    def _xml(self) -> str:
        f, fs = mjcf._f, mjcf._fs
        g = self.spec["gravity_mps2"]
        lines = [
            '<mujoco model="popup-truth">',
            '  <compiler angle="radian" inertiafromgeom="false" autolimits="true"/>',
            f'  <option timestep="{f(self.dt)}" gravity="{fs(g)}" integrator="RK4">',
            '    <flag contact="disable"/>',
            "  </option>",
            "  <worldbody>",
        ]
        ind = "    "
        nested = 0
        for r in self.rows:
            if r.kind == "rotor":
                # a leaf beside the link side it drives (its sibling), not its parent
                lines.append(f'{ind}<body name="{r.body}" pos="{fs(r.pos)}" quat="{fs(r.quat)}">')
                lines.append(f'{ind}  <joint name="{r.name}" type="hinge" axis="{fs(r.axis)}" pos="{fs(r.jpos)}" armature="{f(r.armature)}"/>')
                lines.append(f'{ind}  <inertial pos="0 0 0" mass="{f(mjcf.MASSLESS_KG)}" diaginertia="{fs([mjcf.MASSLESS_INERTIA] * 3)}"/>')
                lines.append(f"{ind}</body>")
                continue
            nested += 1
            lines.append(f'{ind}<body name="{r.body}" pos="{fs(r.pos)}" quat="{fs(r.quat)}">')
            attrs = f'name="{r.name}" type="hinge" axis="{fs(r.axis)}" pos="{fs(r.jpos)}"'
            if r.armature:
                attrs += f' armature="{f(r.armature)}"'
            if r.kind in ("bending", "torsion"):
                attrs += f' stiffness="{f(r.stiffness)}" damping="{f(r.damping)}" springref="0"'
            lines.append(f"{ind}  <joint {attrs}/>")
            mass, com, inertia = _combine(r.parts)
            if mass > 0:
                full = [inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2]]
                lines.append(f'{ind}  <inertial pos="{fs(com)}" mass="{f(mass)}" fullinertia="{fs(full)}"/>')
            else:
                lines.append(f'{ind}  <inertial pos="0 0 0" mass="{f(mjcf.MASSLESS_KG)}" diaginertia="{fs([mjcf.MASSLESS_INERTIA] * 3)}"/>')
            for si, s in enumerate(self.spec["sensors"]["imu"]):
                if r.body == f"body{s['body']}":
                    lines.append(f'{ind}  <site name="imu{si + 1}" pos="{fs(s["position_m"])}"/>')
            ee = self.spec["sensors"]["end_effector"]
            if r.body == f"body{ee['body']}":
                lines.append(f'{ind}  <site name="ee" pos="{fs(ee["position_m"])}"/>')
            ind += "  "
        for _ in range(nested):
            ind = ind[:-2]
            lines.append(f"{ind}</body>")
        lines.append("  </worldbody>")
        lines.append("  <actuator>")
        for r in self.rows:
            if r.kind in ("motor", "rotor"):
                kp = self.spec["motors"]["armature_kgm2"][r.motor] * SERVO_W**2
                kv = 2 * SERVO_ZETA * self.spec["motors"]["armature_kgm2"][r.motor] * SERVO_W
                lines.append(f'    <general name="servo{r.motor + 1}" joint="{r.name}" gaintype="fixed" gainprm="{f(kp)}" biastype="affine" biasprm="0 {f(-kp)} {f(-kv)}"/>')
        lines.append("  </actuator>")
        lines.append("  <sensor>")
        for si in range(len(self.spec["sensors"]["imu"])):
            lines.append(f'    <accelerometer name="acc{si + 1}" site="imu{si + 1}"/>')
        lines.append("  </sensor>")
        lines.append("</mujoco>")
        return "\n".join(lines) + "\n"

    def _index(self) -> None:
        mj, m = self.mujoco, self.m
        jid = {r.name: mj.mj_name2id(m, mj.mjtObj.mjOBJ_JOINT, r.name) for r in self.rows}
        self.dof = {n: int(m.jnt_dofadr[i]) for n, i in jid.items()}
        self.qadr = {n: int(m.jnt_qposadr[i]) for n, i in jid.items()}
        drive = {r.motor: r.name for r in self.rows if r.kind in ("motor", "rotor")}
        self.motor_dof = [self.dof[drive[i]] for i in range(3)]
        self.motor_q = [self.qadr[drive[i]] for i in range(3)]
        #: (motor index, link-side dof, link-side qpos address, rotor dof, rotor qpos address)
        self.play = [(r.motor, self.dof[r.name], self.qadr[r.name], self.motor_dof[r.motor], self.motor_q[r.motor]) for r in self.rows if r.kind == "play"]
        self.armature = np.array(self.spec["motors"]["armature_kgm2"], dtype=float)
        self.kp = self.armature * SERVO_W**2
        self.kv = 2 * SERVO_ZETA * self.armature * SERVO_W
        # root universal joints (wrinkling) and bending joints per link (leak)
        self.bend = {l: [self.dof[r.name] for r in self.rows if r.kind == "bending" and r.link == l] for l in range(2)}
        self.bend_jnt = {l: [mj.mj_name2id(m, mj.mjtObj.mjOBJ_JOINT, r.name) for r in self.rows if r.kind == "bending" and r.link == l] for l in range(2)}
        self.k0 = {l: np.array([m.jnt_stiffness[i] for i in self.bend_jnt[l]]) for l in range(2)}
        self.c0 = {l: np.array([m.dof_damping[self.dof[r.name]] for r in self.rows if r.kind == "bending" and r.link == l]) for l in range(2)}
        roots = {}
        for r in self.rows:
            if r.kind == "bending" and r.link not in roots:
                roots[r.link] = []
            if r.kind == "bending" and len(roots[r.link]) < 2:
                roots[r.link].append((self.dof[r.name], self.qadr[r.name], r.stiffness))
        self.root_uj = roots
        self.sens_adr = [int(m.sensor_adr[mj.mj_name2id(m, mj.mjtObj.mjOBJ_SENSOR, f"acc{i + 1}")]) for i in range(2)]
        self.ee_site = mj.mj_name2id(m, mj.mjtObj.mjOBJ_SITE, "ee")
        self.drag_bodies = []
        pts, w, rad, bod = [], [], [], []
        for r in self.rows if "air_drag" in self.effects else []:
            if r.tubes:
                bid = mj.mj_name2id(m, mj.mjtObj.mjOBJ_BODY, r.body)
                self.drag_bodies.append(bid)
                for tb in r.tubes:
                    n = max(1, int(round((tb["x1"] - tb["x0"]) / 0.07)))
                    e = np.linspace(tb["x0"], tb["x1"], n + 1)
                    pts += [[x, 0.0, 0.0] for x in 0.5 * (e[1:] + e[:-1])]
                    w += [float(e[1] - e[0])] * n
                    rad += [tb["r"]] * n
                    bod += [len(self.drag_bodies) - 1] * n
        if self.drag_bodies:
            self.drag_pts = np.array(pts)
            self.drag_coef = 0.5 * DRAG_RHO * float(self.effects["air_drag"]["cd"]) * 2.0 * np.array(rad) * np.array(w)
            self.drag_of = np.array(bod)
            self.drag_sum = (np.arange(len(self.drag_bodies))[:, None] == self.drag_of[None, :]).astype(float)
            self.drag_bid = np.array(self.drag_bodies)
            self.drag_root = int(m.body_rootid[self.drag_bodies[0]])
        self.dist_dof = None
        if self.disturbance:
            self.dist_dof = self.dof[self.disturbance["joint"]]

    # ------------------------------------------------------------------ forces of the effects
    def _applied(self, t: float, update_drag: bool) -> None:
        d = self.d
        qf = d.qfrc_applied
        qf[:] = 0.0
        v = d.qvel
        jf = self.effects.get("joint_friction")
        if jf:
            for i in range(3):
                w = v[self.motor_dof[i]]
                tc = jf["tau_c"][i] + jf.get("tau_s", [0, 0, 0])[i] * math.exp(-(w / jf.get("v_s", [0.05] * 3)[i]) ** 2)
                qf[self.motor_dof[i]] -= tc * math.tanh(w / FRICTION_VEPS) + jf["b"][i] * w
        if self.play:
            q = d.qpos
            half = self.effects["backlash"]["gap"]
            gk, gd = self.gear_kd
            for mi, dof, qa, rdof, rqa in self.play:
                x, xd = q[qa] - q[rqa], v[dof] - v[rdof]
                h = 0.5 * half[mi]
                f = 0.0
                if x > h:
                    f = min(-gk * (x - h) - gd * xd, 0.0)
                elif x < -h:
                    f = max(-gk * (x + h) - gd * xd, 0.0)
                qf[dof] += f
                qf[rdof] -= f
        wr = self.effects.get("wrinkling")
        if wr:
            q = d.qpos
            for l, uj in self.root_uj.items():
                (da, qa, k), (db, qb, _) = uj
                a, b = q[qa], q[qb]
                nrm = math.hypot(a, b)
                if nrm <= 0:
                    continue
                s = k * nrm
                mw = wr["mw_scale"] * self.mw0[l] * (self._p(t, l) / self.pressure[l])
                g = wr["ratio"] * s + (1.0 - wr["ratio"]) * mw * (_knee(s / mw) - _KNEE0)
                corr = (g - s) / nrm  # extra moment per unit angle (negative: softer)
                qf[da] -= corr * a
                qf[db] -= corr * b
        if self.dist_dof is not None:
            ds = self.disturbance
            qf[self.dist_dof] += ds["amp_nm"] * math.sin(2 * math.pi * ds["freq_hz"] * t + ds["phase"])
        if self.drag_bodies and update_drag:
            self._drag()

    def _drag(self) -> None:
        """Quadratic drag on every tube piece (midpoint rule along the tube axis), from
        MuJoCo's com-based body velocities ``cvel``; applied as ``xfrc_applied`` (force at
        the body's centre of mass and the torque about it)."""
        d = self.d
        b = self.drag_bid[self.drag_of]
        R = d.xmat[b].reshape(-1, 3, 3)
        rw = np.einsum("nij,nj->ni", R, self.drag_pts)
        p = d.xpos[b] + rw
        cv = d.cvel[b]
        vp = cv[:, 3:] + np.cross(cv[:, :3], p - d.subtree_com[self.drag_root])
        ax = R[:, :, 0]
        vperp = vp - np.sum(vp * ax, axis=1)[:, None] * ax
        dF = -(self.drag_coef * np.linalg.norm(vperp, axis=1))[:, None] * vperp
        tq = np.cross(p - d.xipos[b], dF)
        d.xfrc_applied[self.drag_bid, :3] = self.drag_sum @ dF
        d.xfrc_applied[self.drag_bid, 3:] = self.drag_sum @ tq

    def _p(self, t: float, l: int) -> float:
        pl = self.effects.get("pressure_leak")
        return self.pressure[l] * (math.exp(-pl["rate"][l] * t) if pl else 1.0)

    def _set_pressure(self, t: float) -> None:
        m = self.m
        for l in range(2):
            k, c = _k_of_p(self.spec, l, self._p(t, l))
            fk, fc = k / self.k_link[l], c / self.c_link[l]
            for n, ji in enumerate(self.bend_jnt[l]):
                m.jnt_stiffness[ji] = self.k0[l][n] * fk
                m.dof_damping[self.bend[l][n]] = self.c0[l][n] * fc

    @property
    def mw0(self) -> List[float]:
        coef = math.pi / 2 if self.spec["wrinkling"]["coefficient"] == "classical" else math.pi**2 / 4
        return [coef * self.pressure[l] * self.spec["links"][l]["radius_m"] ** 3 for l in range(2)]

    # ------------------------------------------------------------------ rest
    def rest(self, q_motor: Sequence[float]) -> np.ndarray:
        """qpos at static equilibrium with the servos holding ``q_motor`` (the motors sit
        G/kp off; the link side of a backlash joint rests against the gap)."""
        mj, m, d = self.mujoco, self.m, self.d
        if "pressure_leak" in self.effects:
            self._set_pressure(0.0)
        d.ctrl[:] = np.asarray(q_motor, dtype=float)
        q0 = np.zeros(m.nq)
        for i in range(3):
            q0[self.motor_q[i]] = q_motor[i]
        for mi, dof, qa, rdof, rqa in self.play:
            q0[qa] = q_motor[mi]

        def res(x: np.ndarray) -> np.ndarray:
            d.qpos[:] = x
            d.qvel[:] = 0.0
            d.xfrc_applied[:] = 0.0
            mj.mj_kinematics(m, d)
            self._applied(0.0, False)
            mj.mj_forward(m, d)
            return np.array(d.qfrc_smooth)

        x = q0
        for _ in range(3):
            if self.play:
                # the gear contact is flat inside the gap: put each link side against the
                # side its load pushes it to (x = ±gap/2 + load/K past the rotor) before the
                # smooth solve
                r = res(x)
                gaps = self.effects["backlash"]["gap"]
                for mi, dof, qa, rdof, rqa in self.play:
                    load = r[dof] - (d.qfrc_applied[dof])
                    x[qa] = x[rqa] + ((math.copysign(0.5 * gaps[mi], load) + load / self.gear_kd[0]) if abs(load) > 1e-9 else 0.0)
            x = _newton(res, x)
            if np.abs(res(x)).max() < 1e-8:
                break
        return x

    # ------------------------------------------------------------------ run
    def run(self, exc: Excitation, stamps: np.ndarray, delays: Optional[Mapping[str, float]] = None) -> Dict[str, np.ndarray]:
        """Simulate the excitation and record the channels at ``stamps`` (on the dt grid);
        ``delays`` {imu, mocap, torque} [s] record those groups at t - delay (held at the
        first value before t = 0: the arm was at rest).

        MuJoCo's RK4 with a control callback (``mjcb_control``, called at every stage):
        the servo reference and every effect force are evaluated at the stage's own time
        and state (drag: every 4th step, 0.4 ms). At a stamp, ``mj_forward`` gives the sensors,
        the actuator force and q̈ of that state."""
        mj, m, d = self.mujoco, self.m, self.d
        dt = self.dt
        T = float(stamps[-1])
        nstep = int(round(T / dt)) + 1
        th = np.arange(2 * nstep + 4) * (dt / 2)
        qref = exc(th)
        play = np.zeros_like(qref)
        if any(self.held_gap):
            # a held link side: the servo (motor and link as one) tracks the play operator
            # of the reference, and the encoder records the motor side (servo angle − play)
            ql = qref[0].copy()
            h = 0.5 * np.asarray(self.held_gap)
            for i in range(len(qref)):
                ql = np.clip(ql, qref[i] - h, qref[i] + h)
                play[i] = ql - qref[i]
            qref = qref + play
        dref = np.gradient(qref, dt / 2, axis=0)
        self._ctrl = qref + (self.kv / self.kp)[None, :] * dref
        mj.mj_resetData(m, d)
        d.qpos[:] = self.rest(qref[0])
        d.qvel[:] = 0.0
        d.time = 0.0
        d.xfrc_applied[:] = 0.0
        idx = np.round(stamps / dt).astype(np.int64)
        groups = {"encoder": idx}
        delays = dict(delays or {})
        for g in ("imu", "mocap", "torque"):
            groups[g] = np.clip(idx - int(round(float(delays.get(g, 0.0)) / dt)), 0, None)
        need = np.unique(np.concatenate(list(groups.values())))
        pos = {int(k): n for n, k in enumerate(need)}
        rec = np.zeros((len(need), 3 + 3 + 3 + 6))
        qrec = np.zeros((len(need), m.nq))
        md, mq = self.motor_dof, self.motor_q
        arm = self.armature
        # a gear with play: the torque is read between the gear's output and the link (a joint
        # torque sensor), so the output inertia's own torque is not in it
        out_dof = [(mi, dof) for mi, dof, _, _, _ in self.play]
        a1, a2 = self.sens_adr
        ee = self.ee_site
        two_over_h = 2.0 / dt
        ctab = self._ctrl
        leak = "pressure_leak" in self.effects
        drag = bool(self.drag_bodies)
        state = {"drag": -1}

        def control(m_: Any, d_: Any) -> None:
            t = d_.time
            kk = int(t * two_over_h + 0.5)
            r = ctab[kk]
            c = d_.ctrl
            c[0] = r[0]
            c[1] = r[1]
            c[2] = r[2]
            if leak and kk % 20 == 0:
                self._set_pressure(t)
            upd = drag and kk % 8 == 0 and kk != state["drag"]
            if upd:
                state["drag"] = kk
            self._applied(t, upd)

        need_l = [int(k) for k in need]
        p = 0
        mj.set_mjcb_control(control)
        try:
            for k in range(nstep):
                if p < len(need_l) and k == need_l[p]:
                    mj.mj_forward(m, d)
                    r = rec[p]
                    qrec[p] = d.qpos
                    pl = play[2 * k]
                    r[0], r[1], r[2] = d.qpos[mq[0]] - pl[0], d.qpos[mq[1]] - pl[1], d.qpos[mq[2]] - pl[2]
                    af = d.actuator_force
                    r[3] = af[0] - arm[0] * d.qacc[md[0]]
                    r[4] = af[1] - arm[1] * d.qacc[md[1]]
                    r[5] = af[2] - arm[2] * d.qacc[md[2]]
                    for mi, dof in out_dof:
                        r[3 + mi] -= BACKLASH_OUT * d.qacc[dof]
                    r[6:9] = d.site_xpos[ee]
                    r[9:12] = d.sensordata[a1:a1 + 3]
                    r[12:15] = d.sensordata[a2:a2 + 3]
                    p += 1
                    if not np.all(np.isfinite(d.qacc)):
                        raise RuntimeError(f"MuJoCo run diverged at t = {k * dt:.4f} s")
                mj.mj_step(m, d)
        finally:
            mj.set_mjcb_control(None)
            if leak:
                self._set_pressure(0.0)
        bad = [w for w in ("mjWARN_BADQACC", "mjWARN_BADQVEL", "mjWARN_BADQPOS") if d.warning[int(getattr(mj.mjtWarning, w))].number > 0]
        if bad:
            raise RuntimeError(f"MuJoCo run unstable ({', '.join(bad)}); effects {sorted(self.effects)}")
        sel = {g: np.array([pos[int(k)] for k in v]) for g, v in groups.items()}
        self.last_qpos = qrec[sel["encoder"]]  # the whole joint vector at the stamps (tests)
        out: Dict[str, np.ndarray] = {"t": stamps.copy()}
        for j in range(3):
            out[f"q{j + 1}"] = rec[sel["encoder"], j]
            out[f"tau{j + 1}"] = rec[sel["torque"], 3 + j]
        for j, c in enumerate("xyz"):
            out[f"ee_{c}"] = rec[sel["mocap"], 6 + j]
            out[f"imu1_a{c}"] = rec[sel["imu"], 9 + j]
            out[f"imu2_a{c}"] = rec[sel["imu"], 12 + j]
        for l in range(2):
            out[f"p{l + 1}"] = np.array([self._p(float(t), l) for t in stamps])
        return out


def simulate_mujoco(spec: RunSpec, exc: Excitation, stamps: np.ndarray) -> Dict[str, np.ndarray]:
    """Noise-free channels of ``spec`` at ``stamps`` from the MuJoCo arm."""
    fx = {k: v for k, v in spec.effects.items() if k != "sensor_delay"}
    arm = MujocoArm(spec.payload_kg, spec.pressure_pa, fx, spec.disturbance)
    return arm.run(exc, stamps, delays=spec.effects.get("sensor_delay"))


# ============================================================================ measurement
def encoder_resolution(bits: int) -> float:
    """Joint-output resolution [rad] of a ``bits``-bit motor encoder behind the 100:1 gear."""
    return 2 * math.pi / (2**int(bits) * 100)


def _lowpassed(e: np.ndarray, fc: float, rate: float, sd: float) -> np.ndarray:
    """White noise ``e`` through a 1-pole low-pass at ``fc`` [Hz] (sampled at ``rate``), scaled
    back to standard deviation ``sd`` (coloured noise of the same size)."""
    from scipy.signal import butter, lfilter

    b, a = butter(1, min(fc / (rate / 2), 0.95))
    f = lfilter(b, a, np.concatenate([e[::-1][:2000], e]))[min(2000, e.size):]
    return f * (sd / max(float(np.std(f)), 1e-300))


def measure(clean: Mapping[str, np.ndarray], spec: RunSpec, rng: np.random.Generator) -> Dict[str, np.ndarray]:
    """The lab's view of the noise-free channels: white Gaussian noise per group
    (``popup.synth.NOISE`` × ``noise_scale``; IMU and torque noise coloured by a 1-pole
    low-pass at ``noise_lowpass_hz`` when set), quantised encoders, the channel set
    (``full``, ``no_mocap``, ``no_torque``, ``pressure_noisy`` = full + p1 p2 with 50 Pa
    noise), NaN dropouts (mocap occlusion bursts of 20-200 ms, single IMU and torque
    packets lost), and each channel's constant ``biases``."""
    t = np.asarray(clean["t"], dtype=float)
    n = len(t)
    out: Dict[str, np.ndarray] = {"t": t}
    res = encoder_resolution(spec.encoder_bits)
    for j in range(1, 4):
        out[f"q{j}"] = np.round(np.asarray(clean[f"q{j}"]) / res) * res
    for g, cols in GROUPS.items():
        sd = NOISE[g] * spec.noise_scale
        for c in cols:
            e = rng.normal(0.0, sd, n)
            if spec.noise_lowpass_hz > 0 and g in ("imu", "tau"):
                e = _lowpassed(e, spec.noise_lowpass_hz, spec.rate, sd)
            out[c] = np.asarray(clean[c], dtype=float) + e + spec.biases.get(c, 0.0)
    if spec.channels == "pressure_noisy":
        for c in ("p1", "p2"):
            out[c] = np.asarray(clean[c], dtype=float) + rng.normal(0.0, PRESSURE_NOISE_PA, n)
    if spec.channels == "no_mocap":
        for c in GROUPS["ee"]:
            del out[c]
    if spec.channels == "no_torque":
        for c in GROUPS["tau"]:
            del out[c]
    if spec.dropouts:
        dur = float(t[-1] - t[0])
        if "ee_x" in out:
            for _ in range(int(rng.poisson(max(1.0, dur / 3.0)))):
                t0 = rng.uniform(t[0], t[-1])
                m = (t >= t0) & (t < t0 + rng.uniform(0.02, 0.2))
                for c in GROUPS["ee"]:
                    out[c][m] = np.nan
        for imu in ("imu1", "imu2"):
            m = rng.random(n) < 0.003
            for c in ("ax", "ay", "az"):
                out[f"{imu}_{c}"][m] = np.nan
        if "tau1" in out:
            m = rng.random(n) < 0.001
            for c in GROUPS["tau"]:
                out[c][m] = np.nan
    return {c: out[c] for c in MEAS_ORDER if c in out}


def description(spec: RunSpec) -> str:
    return (f"synthetic lab run {spec.name} ({spec.engine} engine, family {spec.family}); "
            f"truth = {json.dumps(inf_to_str(spec.truth()), sort_keys=True)}")


def read_truth(run_or_path: Any) -> Dict[str, Any]:
    """The truth recorded in a run's description (a run folder or a MeasuredRun)."""
    import warnings

    if isinstance(run_or_path, (str, os.PathLike)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            run_or_path = popup.read_run(run_or_path)
    desc = run_or_path.description
    return json.loads(desc.split("truth = ", 1)[1])


def write(spec: RunSpec, data: Mapping[str, np.ndarray], out_dir: Any) -> Path:
    """Write the run with :func:`popup.io.write_run`: the experiment declares what a lab
    knows (arm, declared payload and pressures, encoder replay), the truth only the
    description."""
    exp = {
        "format": "popup-run/1",
        "arm": "popup-lab",
        "payload_kg": float(spec.payload_kg),
        "pressure_pa": [float(spec.pressure_pa[0]), float(spec.pressure_pa[1])],
        "gravity": True,
        "replay": "encoder",
        "description": description(spec),
    }
    path = Path(out_dir) / spec.name
    popup.io.write_run(path, exp, dict(data), overwrite=True)
    return path


def clean_channels(spec: RunSpec) -> Tuple[Dict[str, np.ndarray], Excitation]:
    """The noise-free channels of ``spec`` at its stamps, from its engine."""
    exc = excitation_of(spec.style, spec.duration, seed=int(_seq(spec.seed, spec.engine, spec.family, spec.index, "exc").generate_state(1)[0]),
                        amplitude=spec.amplitude, wrinkle=spec.wrinkle_poses)
    st = make_stamps(spec.duration, spec.rate, spec.jitter, _rng(spec.seed, spec.engine, spec.family, spec.index, "stamps"))
    if "actuator_saturation" in spec.effects and "frac" in spec.effects["actuator_saturation"]:
        # the limit as a fraction of the peak torque the nominal replay needs
        nom = popup.Model("popup-lab", payload_kg=spec.payload_kg, pressure_pa=spec.pressure_pa)
        tf = np.arange(0.0, spec.duration + 1e-9, 2e-3)
        r = nom.replay(tf, exc(tf), sample_rate=500)
        peak = [float(np.abs(np.asarray(r.channel(f"tau{j + 1}"))).max()) for j in range(3)]
        frac = spec.effects["actuator_saturation"].pop("frac")
        spec.effects["actuator_saturation"]["tau_max"] = [round(f * pk, 3) if math.isfinite(f) else math.inf for f, pk in zip(frac, peak)]
    if spec.level == "near" and len(spec.effects) == 1 and next(iter(spec.effects)) in SCALABLE:
        calibrate_near(spec, exc)
    if spec.engine == "popup":
        return simulate_popup(spec, exc, st), exc
    if spec.engine == "mujoco":
        return simulate_mujoco(spec, exc, st), exc
    raise ValueError(f"engine {spec.engine!r}: expected one of {ENGINES}")


def _groups_present(spec: RunSpec) -> List[str]:
    return [g for g in GROUPS if (g != "tau" or spec.channels != "no_torque") and (g != "ee" or spec.channels != "no_mocap")]


def member_size(spec: RunSpec, clean: Optional[Mapping[str, np.ndarray]] = None) -> Dict[str, float]:
    """How far each effect of a run with several moves the channels beside the others, in
    noise sigmas of this run: per effect, the largest over the channel groups present of the
    RMS of (noise-free truth − the same run made without that effect) / (NOISE ×
    noise_scale), both from the run's own engine on the same motor trajectory (``clean``: the
    run's noise-free channels, made here when not given). ``effect_size`` measures the
    effects together against popup's nominal model; this measures what each adds, which
    is what a diagnosis that has found the other can still see: a torsion beside a payload
    that all but removes the tip mass (popup pair 710-001: payload −0.465 of 0.5 kg, the
    torsion 0.20 σ) is below the 1 σ the benchmark counts as detectable."""
    if len(spec.effects) < 2:
        return {}
    if clean is None:
        clean, _ = clean_channels(copy.deepcopy(spec))
    out: Dict[str, float] = {}
    for e in sorted(spec.effects):
        s = copy.deepcopy(spec)
        s.effects.pop(e)
        c2, _ = clean_channels(s)
        out[e] = _r(max(float(np.sqrt(np.mean(np.concatenate([np.asarray(clean[c]) - np.asarray(c2[c]) for c in GROUPS[g]]) ** 2)))
                        / (NOISE[g] * spec.noise_scale) for g in _groups_present(spec)), 3)
    return out


def effect_size(clean: Mapping[str, np.ndarray], spec: RunSpec) -> Dict[str, float]:
    """How far the truth is from the declared nominal model, in noise sigmas of this run:
    per channel group present in the run, the RMS of (noise-free truth − popup's nominal
    replay of the true motor angles) / (NOISE × noise_scale). A nominal MuJoCo run gives
    ~1e-3 (the engine agreement)."""
    from scipy.interpolate import CubicSpline

    t = np.asarray(clean["t"])
    q = np.stack([clean[f"q{j}"] for j in (1, 2, 3)], axis=1)
    nom = popup.Model("popup-lab", payload_kg=spec.payload_kg, pressure_pa=spec.pressure_pa)
    # the replay's output rate must divide popup's 1 kHz: the run's own rate where it does,
    # else 1 kHz (e.g. 333 Hz), splined onto the run's stamps
    rate = min(1000.0, float(spec.rate))
    if abs(1000.0 / rate - round(1000.0 / rate)) > 1e-9:
        rate = 1000.0
    tt = np.arange(0.0, float(t[-1]) + 1e-9, 1.0 / rate)
    uniform = len(tt) == len(t) and float(np.abs(tt - t).max()) < 1e-9
    r = nom.replay(tt, q if uniform else CubicSpline(t, q)(tt), sample_rate=rate)
    out: Dict[str, float] = {}
    for g in _groups_present(spec):
        cols = GROUPS[g]
        e = np.concatenate([clean[c] - (np.asarray(r.channel(c)) if uniform else CubicSpline(tt, np.asarray(r.channel(c)))(t)) for c in cols])
        out[g] = _r(float(np.sqrt(np.mean(e**2)) / (NOISE[g] * spec.noise_scale)), 3)
    return out


#: strength parameters scaled by :func:`calibrate_near` (torsion: the compliance 1/k_t)
SCALABLE = {"joint_friction": ("tau_c", "b", "tau_s"), "payload_mass": ("delta_kg",), "sensor_delay": ("imu", "mocap", "torque"),
            "air_drag": ("cd",), "backlash": ("gap",), "pressure_leak": ("rate",), "torsion": ("k_t",), "wrinkling": ("ratio",)}


def _scaled(name: str, p: Mapping[str, Any], f: float) -> Dict[str, Any]:
    out = dict(p)
    for k in SCALABLE[name]:
        if k not in out:
            continue
        v = out[k]
        if name == "torsion":
            out[k] = [(_r(x / f) if math.isfinite(x) else x) for x in v]
        elif name == "wrinkling":  # the strength is the stiffness lost past the threshold, 1 - ratio
            out[k] = _r(1.0 - min(1.0, (1.0 - v) * f))
        elif isinstance(v, list):
            out[k] = [_r(x * f) for x in v]
        else:
            out[k] = _r(v * f)
    return out


def _within_bounds(name: str, p: Mapping[str, Any]) -> Dict[str, Any]:
    """``p`` with each parameter that has fit bounds in popup (``popup.estimate.BOUNDS``)
    clamped into them: a "near" torsion scaled past the bound (k_t 87 240 and 191 700
    N·m/rad on a 200 Hz trapezoid whose excitation barely reaches it, seed 113; the library
    fits k_t ≤ 1.5e4) is a truth no library effect can represent."""
    from popup.estimate import BOUNDS

    out = dict(p)
    for k, v in p.items():
        lo, hi = BOUNDS.get((name, k), (-math.inf, math.inf))
        if isinstance(v, list):
            out[k] = [min(max(x, lo), hi) if math.isfinite(x) else x for x in v]
        elif isinstance(v, (int, float)) and math.isfinite(v):
            out[k] = min(max(v, lo), hi)
    return out


def calibrate_near(spec: RunSpec, exc: Excitation) -> None:
    """Scale the strength of the run's single effect so that popup's own version of it
    moves the channels of this run by a target drawn in 1.5-4 noise sigmas (RMS, the
    most affected channel group present, this run's noise): "near detectability". Two
    secant steps on popup replays at 500 Hz (the effect's response is close to linear in
    its strength); the MuJoCo engine uses the same scale (its effect differs in detail)."""
    name = next(iter(spec.effects))
    rng = _rng(spec.seed, spec.engine, spec.family, spec.index, "near")
    target = float(rng.uniform(1.5, 4.0))
    nom = popup.Model("popup-lab", payload_kg=spec.payload_kg, pressure_pa=spec.pressure_pa)
    tf = np.arange(0.0, spec.duration + 1e-9, 2e-3)
    qf = exc(tf)
    r0 = nom.replay(tf, qf, sample_rate=500)
    present = _groups_present(spec)

    def sigma(p: Mapping[str, Any]) -> float:
        pp = {k: v for k, v in p.items() if k in popup.effects.EFFECTS[name].params}
        m1 = nom.with_effects({name: popup_effects({"x": pp})["x"]})
        # a stiff structural mode (torsion) needs a smaller step than the nominal's 1 ms
        sdt = m1.with_dt(1.0).stable_dt([float(x) for x in m1.rest_state()], replay=True)
        if 0.8 * sdt < m1.dt:
            m1 = m1.with_dt(2e-3 / math.ceil(2e-3 / (0.8 * sdt)))  # a divisor of the 2 ms sample period
        r1 = m1.replay(tf, qf, sample_rate=500)
        best = 0.0
        for g in present:
            e = np.concatenate([np.asarray(r1.channel(c)) - np.asarray(r0.channel(c)) for c in GROUPS[g]])
            best = max(best, float(np.sqrt(np.mean(e**2))) / (NOISE[g] * spec.noise_scale))
        return best

    p = dict(spec.effects[name])
    for _ in range(2):
        s0 = sigma(p)
        if s0 <= 0 or not math.isfinite(s0):
            break
        # at most 30× per step: an excitation that barely reaches the effect (a short run
        # that never turns q1, for torsion) would otherwise scale it out of its range
        p = _within_bounds(name, _scaled(name, p, min(max(target / s0, 1.0 / 30.0), 30.0)))
    spec.effects[name] = p
    spec.near_target_sigma = _r(target, 3)


def make_run(spec: RunSpec, out_dir: Any) -> Tuple[Path, Dict[str, Any]]:
    """Simulate, measure and write one run; returns (run folder, truth). The truth (also
    in the run's description) includes ``effect_sigma`` (:func:`effect_size`) and, for a
    run with several effects, ``member_sigma`` (:func:`member_size`)."""
    clean, _ = clean_channels(spec)
    spec.effect_sigma = effect_size(clean, spec)
    spec.member_sigma = member_size(spec, clean)
    data = measure(clean, spec, _rng(spec.seed, spec.engine, spec.family, spec.index, "noise"))
    path = write(spec, data, out_dir)
    return path, inf_to_str(spec.truth())


# ============================================================================ families
#: the library's own test magnitudes (tests/test_diagnosis.py), the base of the levels
BASE = {
    "joint_friction": {"tau_c": [1.5, 2.0, 0.8], "b": [0.3, 0.2, 0.1]},
    "backlash": {"gap": [0.01, 0.02, 0.015]},
    "pressure_leak": {"rate": [0.02, 0.03]},
}
PAIRS = [("joint_friction", "payload_mass"), ("sensor_delay", "torsion"), ("pressure_leak", "joint_friction"),
         ("air_drag", "payload_mass"), ("backlash", "joint_friction"), ("higher_bending_modes", "sensor_delay"),
         ("wrinkling", "joint_friction"), ("torsion", "payload_mass")]
NEEDS_TORQUE = {"joint_friction", "actuator_saturation"}


def _r(x: float, nd: int = 4) -> float:
    return float(f"{x:.{nd}g}")


def effect_params(name: str, engine: str, level: str, rng: np.random.Generator, channels: str) -> Dict[str, Any]:
    """Truth parameters of one effect: ``above`` = well above the noise (the order of the
    library's own tests and up to a few times more); ``near`` = of the order of the noise:
    drawn as ``above`` and scaled by :func:`calibrate_near` to 1.5-4 noise sigmas
    (saturation: a limit at 95-98 % of the peak torque; higher modes: always above)."""
    near = level == "near" and name not in SCALABLE  # scalable effects: calibrate_near sets the strength
    u = rng.uniform
    if name == "joint_friction":
        f = u(0.06, 0.12) if near else u(0.5, 1.5)
        tc = [_r(x * f * u(0.7, 1.3)) for x in BASE[name]["tau_c"]]
        p: Dict[str, Any] = {"tau_c": tc, "b": [_r(x * f * u(0.7, 1.3)) for x in BASE[name]["b"]],
                             "tau_s": [_r(x * u(0.0, 0.5)) for x in tc], "v_s": [_r(u(0.02, 0.1)) for _ in range(3)]}
        return p
    if name == "payload_mass":
        mag = u(0.004, 0.012) if near else u(0.1, 0.5)
        return {"delta_kg": _r(mag * rng.choice([-1.0, 1.0]))}
    if name == "sensor_delay":
        present = ["imu"] + (["mocap"] if channels != "no_mocap" else []) + (["torque"] if channels != "no_torque" else [])
        k = int(rng.integers(1, len(present) + 1))
        groups = list(rng.choice(present, size=k, replace=False))
        return {g: _r(u(0.0005, 0.0015) if near else u(0.005, 0.03)) for g in sorted(groups)}
    if name == "torsion":
        k1 = u(2500.0, 6000.0) if near else u(80.0, 400.0)
        k2 = k1 * u(1.0, 3.0) if rng.random() < 0.3 else math.inf
        return {"k_t": [_r(k1), _r(k2) if math.isfinite(k2) else math.inf], "c_t": [_r(u(0.05, 0.4)), _r(u(0.05, 0.2)) if math.isfinite(k2) else 0.0]}
    if name == "higher_bending_modes":
        ks = [_r(u(0.8, 1.25)), _r(u(0.8, 1.25))]
        if engine == "popup":
            s = 3.0 if rng.random() < 0.3 else 2.0
            out: Dict[str, Any] = {"segments": [s, s], "k_scale": ks}
            if rng.random() < 0.4:  # a stiffer root, as a continuous cantilever has (4:1 for 2 segments)
                out["root_ratio"] = [_r(u(2.0, 6.0))] * 2
            return out
        return {"segments": [2.0, 2.0], "k_scale": [1.0, 1.0], "split": "root 2k, mid k/2, both scaled to the one-joint arm's static sag"}
    if name == "air_drag":
        return {"cd": _r(u(1.0, 2.0) if near else u(4.0, 10.0))}
    if name == "backlash":
        f = u(0.05, 0.1) if near else u(0.5, 1.5)
        bl: Dict[str, Any] = {"gap": [_r(x * f * u(0.7, 1.3)) for x in BASE[name]["gap"]]}
        if engine == "mujoco" and level == "above" and rng.random() < 0.5:
            # a compliant gear (a harmonic drive's flanks, 1e4-1e5 N·m/rad, damping ratio
            # 0.2-0.5 on the link side's inertia) instead of the stiff contact; not on "near"
            # runs, whose gaps are scaled to a few noise sigmas of popup's rigid law: there
            # the compliance alone moves the channels by tens of sigmas, a gear compliance
            # with play below the encoder's resolution, which the library does not find
            # (its rigid base is not significant, so the compliant variant is not tried)
            k = 10.0 ** u(4.0, 5.0)
            bl["gear_k"] = _r(k)
            bl["gear_d"] = _r(u(0.2, 0.5) * 2.0 * math.sqrt(k * BACKLASH_OUT))
        return bl
    if name == "pressure_leak":
        f = u(0.06, 0.12) if near else u(0.5, 2.0)
        return {"rate": [_r(x * f * u(0.7, 1.3)) for x in BASE[name]["rate"]]}
    if name == "wrinkling":
        return {"ratio": _r(u(0.3, 0.6)), "mw_scale": _r(u(0.7, 0.9))}
    if name == "actuator_saturation":
        j = int(rng.integers(1, 3))  # q2 or q3 (gravity-loaded)
        frac = [math.inf, math.inf, math.inf]
        frac[j] = _r(u(0.95, 0.98) if near else u(0.75, 0.88))
        return {"frac": frac}
    raise ValueError(f"unknown effect {name!r}")


def _channel_options(effects: Sequence[str], engine: str) -> List[str]:
    opts = list(CHANNEL_SETS)
    if any(e in NEEDS_TORQUE for e in effects):
        opts.remove("no_torque")
    return opts


def check_rates(rates: Sequence[float]) -> List[float]:
    """``rates`` [Hz] as floats, each one whose period divides 1 ms (popup's replay step and
    the generators' output grid); ``ValueError`` naming the first that does not."""
    out = [float(r) for r in rates]
    for r in out:
        if not (r > 0 and abs(1000.0 / r - round(1000.0 / r)) < 1e-9):
            raise ValueError(f"rate {r:g} Hz: expected a rate whose period divides 1 ms (1000/rate an integer)")
    return out


def draw_biases(rng: np.random.Generator) -> Dict[str, float]:
    """A lab's sensor biases, as uncalibrated sensors have them: each torque, end-effector
    and IMU channel a constant of either sign and a magnitude uniform in :data:`BIASES`
    (its group's range: IMU 0.03-0.2 m/s², torque 0.01-0.08 N·m, mocap 0.2-1 mm)."""
    out: Dict[str, float] = {}
    for c in MEAS_ORDER:
        g = "tau" if c.startswith("tau") else "ee" if c.startswith("ee_") else "imu" if c.startswith("imu") else ""
        if g:
            lo, hi = BIASES[g]
            out[c] = _r(float(rng.choice([-1.0, 1.0]) * rng.uniform(lo, hi)), 6)
    return out


#: Sensor-bias ranges per channel group [channel unit] (:func:`draw_biases`, ``--biases``).
BIASES: Dict[str, Tuple[float, float]] = {"imu": (0.03, 0.2), "tau": (0.01, 0.08), "ee": (2e-4, 1e-3)}


def family_specs(kind: str, engine: str, n: int, seed: int, *, styles: Optional[Sequence[str]] = None, rates: Optional[Sequence[float]] = None,
                 biases: bool = False, **overrides: Any) -> List[RunSpec]:
    """The ``n`` run specs of a family: ``kind`` is an effect name (that effect alone,
    levels alternating near/above), ``"pairs"`` (two effects, cycling :data:`PAIRS`),
    ``"nominal"`` (nothing hidden) or ``"disturbance"`` (a periodic disturbance outside
    the library). The lab conditions vary run by run: rate 200/500/1000 Hz (cycled),
    jittered stamps (half the runs), channel set (cycled over the sets the truth can be
    seen in), dropouts, noise × 0.3-3 (log-uniform; drag ≤ 1), encoder 12/14/16 bits,
    payload, pressures, excitation (its style cycled over :data:`STYLES`, or over ``styles``;
    the trajectory drawn per run), duration 10-14 s. ``rates`` [Hz]: cycle over these
    instead (e.g. :data:`OTHER_RATES`, rates a lab also records at; each must divide
    1 kHz, popup's replay rate), the other draws unchanged. The cycles start at a phase of
    their own per family, so that even ``n = 1`` spreads rates, channel sets and levels
    over the families. ``overrides`` set any :class:`RunSpec` field of every run after the
    draw (e.g. ``duration=3.0`` for quick tests). ``biases``: every run also gets sensor
    biases (:func:`draw_biases`, from a stream of their own: the other draws unchanged)."""
    if engine not in ENGINES:
        raise ValueError(f"engine {engine!r}: expected one of {ENGINES}")
    if kind not in FAMILY_KINDS:
        raise ValueError(f"family {kind!r}: expected one of {FAMILY_KINDS}")
    for st in styles or ():
        if st not in STYLES:
            raise ValueError(f"excitation style {st!r}: expected one of {STYLES}")
    check_rates(rates or ())
    if kind in LIBRARY and kind not in EFFECT_FAMILIES[engine]:
        raise ValueError(f"the {engine} engine has no {kind} family (see the families module docs)")
    specs = []
    for i in range(n):
        rng = _rng(seed, engine, kind, i, "spec")
        if kind == "pairs":
            pairs = [p for p in PAIRS if all(e in EFFECT_FAMILIES[engine] for e in p)]
            names: List[str] = list(pairs[(i + seed) % len(pairs)])
        elif kind in LIBRARY:
            names = [kind]
        elif kind == "backlash_held":
            names = ["backlash"]
        else:
            names = []
        off = zlib.crc32(f"{engine}/{kind}".encode()) + int(seed)  # a family's own phase in the cycles below
        level = "above" if ((kind not in LIBRARY and kind != "backlash_held") or kind == "higher_bending_modes") else ("near", "above")[(i + off) % 2]
        cycle = [float(r) for r in rates] if rates else [500.0, 1000.0] if "higher_bending_modes" in names else [500.0, 200.0, 1000.0]
        chans = _channel_options(names, engine)
        sp = RunSpec(engine=engine, family=kind, index=i, seed=int(seed), level=level)
        sp.rate = cycle[(i + off) % len(cycle)]
        sp.jitter = _r(rng.uniform(0.05, 0.2)) if rng.random() < 0.5 else 0.0
        sp.channels = chans[(i // 2 + off) % len(chans)] if kind in LIBRARY else chans[(i + off) % len(chans)]
        sp.dropouts = bool(rng.random() < 0.4)
        sp.duration = float(np.round(rng.uniform(10.0, 14.0) * 2) / 2)
        sp.style = STYLES[(i + off) % len(STYLES)] if styles is None else styles[(i + off) % len(styles)]
        sp.payload_kg = float(rng.choice([0.5, 1.0, 1.5, 2.0]))
        sp.pressure_pa = (float(np.round(rng.uniform(22e3, 45e3), -2)), float(np.round(rng.uniform(22e3, 45e3), -2)))
        sp.amplitude = _r(rng.uniform(0.7, 1.2))
        sp.noise_scale = _r(math.exp(rng.uniform(math.log(0.3), math.log(3.0))))
        sp.encoder_bits = int(rng.choice([12, 14, 16]))
        # a third of the runs: coloured IMU/torque noise (a sensor front-end's low-pass)
        rn = _rng(seed, engine, kind, i, "noise_colour")
        sp.noise_lowpass_hz = _r(rn.uniform(20.0, 0.3 * sp.rate if sp.rate < 300 else 100.0)) if rn.random() < 1 / 3 else 0.0
        if "wrinkling" in names:
            sp.payload_kg = float(rng.choice([1.5, 2.0]))
            sp.pressure_pa = (float(np.round(rng.uniform(20e3, 28e3), -2)), float(np.round(rng.uniform(20e3, 28e3), -2)))
            sp.wrinkle_poses = True
        if "air_drag" in names:
            sp.noise_scale = _r(rng.uniform(0.3, 1.0))
            if level == "above":
                sp.amplitude = _r(rng.uniform(1.3, 1.7))
        sp.effects = {e: effect_params(e, engine, level, rng, sp.channels) for e in names}
        if kind == "backlash_held":
            sp.effects["backlash"]["held"] = [1.0, 1.0, 1.0]
        if biases:
            sp.biases = draw_biases(_rng(seed, engine, kind, i, "biases"))
        if kind == "disturbance":
            f = _r(rng.uniform(1.2, 2.4))
            ph = _r(rng.uniform(0, 2 * math.pi))
            if engine == "mujoco":
                joint = str(rng.choice(["d22", "d21", "d12"]))
                li = int(joint[1]) - 1
                k, _ = _k_of_p(mjcf.arm_data(popup.Model("popup-lab"))["spec"], li, sp.pressure_pa[li])
                sp.disturbance = {"joint": joint, "freq_hz": f, "phase": ph, "amp_nm": _r(k * rng.uniform(0.004, 0.01))}
            else:
                sp.disturbance = {"freq_hz": f, "phase": ph, "imu_amp": _r(rng.uniform(0.5, 1.2)), "ee_amp": _r(rng.uniform(0.002, 0.006))}
        for k, v in overrides.items():
            if not hasattr(sp, k):
                raise TypeError(f"family_specs: RunSpec has no field {k!r}")
            setattr(sp, k, v)
        specs.append(sp)
    return specs


def _make_one(args: Tuple[RunSpec, str]) -> Tuple[str, Dict[str, Any]]:
    spec, out = args
    path, truth = make_run(spec, out)
    return str(path), truth


def make_family(kind: str, engine: str, n: int, seed: int, out_dir: Any, *, jobs: int = 1, **overrides: Any) -> List[Tuple[Path, Dict[str, Any]]]:
    """Generate a family (see :func:`family_specs`; ``overrides`` go there) into
    ``out_dir``; returns ``[(run folder, truth dict), ...]`` in run order. ``jobs`` > 1
    generates in parallel processes (the result does not depend on it)."""
    specs = family_specs(kind, engine, n, seed, **overrides)
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    work = [(sp, str(out_dir)) for sp in specs]
    if jobs > 1 and len(work) > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(max_workers=jobs) as ex:
            res = list(ex.map(_make_one, work))
    else:
        res = [_make_one(w) for w in work]
    return [(Path(p), t) for p, t in res]


# ============================================================================ agreement
def engine_agreement(duration: float = 10.0, seed: int = 1, *, payload_kg: float = 1.0, pressure_pa: Sequence[float] = (30e3, 30e3),
                     rate: float = 500.0, amplitude: float = 1.0) -> Dict[str, Dict[str, float]]:
    """MuJoCo (nominal arm) against popup's own replay of the motor angles MuJoCo
    recorded (no effect, no noise, no quantisation): per channel the RMS and the largest
    difference, in units of the channel's noise sigma (``popup.synth.NOISE``), and the
    channel's own standard deviation."""
    exc = excitation(duration, seed=seed, amplitude=amplitude)
    st = make_stamps(duration, rate, 0.0, np.random.default_rng(0))
    arm = MujocoArm(payload_kg, pressure_pa)
    out = arm.run(exc, st)
    q = np.stack([out[f"q{j}"] for j in (1, 2, 3)], axis=1)
    res = popup.Model("popup-lab", payload_kg=payload_kg, pressure_pa=tuple(pressure_pa)).replay(st, q, sample_rate=rate)
    agg: Dict[str, Dict[str, float]] = {}
    for c in OUT_CHANNELS[3:]:
        g = "tau" if c.startswith("tau") else "ee" if c.startswith("ee") else "imu"
        e = out[c] - np.asarray(res.channel(c))
        agg[c] = {"rms_sigma": float(np.sqrt(np.mean(e**2)) / NOISE[g]), "max_sigma": float(np.abs(e).max() / NOISE[g]),
                  "rms": float(np.sqrt(np.mean(e**2))), "std": float(np.std(out[c]))}
    for n in ("d11", "d12", "d21", "d22"):
        e = arm.last_qpos[:, arm.qadr[n]] - np.asarray(res.channel(n))
        agg[n] = {"rms_rad": float(np.sqrt(np.mean(e**2))), "max_rad": float(np.abs(e).max()), "std": float(np.std(np.asarray(res.channel(n))))}
    return agg


if __name__ == "__main__":  # pragma: no cover
    import argparse

    ap = argparse.ArgumentParser(description="generate one family of runs, or print the engine agreement")
    ap.add_argument("kind", nargs="?", default="agreement", help=f"'agreement' or one of {', '.join(FAMILY_KINDS)}")
    ap.add_argument("--engine", default="mujoco", choices=ENGINES)
    ap.add_argument("--n", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="out/families")
    a = ap.parse_args()
    if a.kind == "agreement":
        for c, v in engine_agreement(seed=a.seed or 1).items():
            print(f"{c:8s} " + "  ".join(f"{k} {x:.3g}" for k, x in v.items()))
    else:
        for pth, tr in make_family(a.kind, a.engine, a.n, a.seed, a.out):
            print(pth, json.dumps(tr))
