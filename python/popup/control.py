"""Closed-loop control: controllers, reference signals, task sequences, obstacles and runs.

A :class:`Task` is what the arm does: a list of :class:`Phase` objects (``Deflated →
Inflating → Ready → Moving → Grasping → Damping → Holding → Releasing → Withdrawing`` or any
sequence of your own), the :class:`Controller` (motoreducers, cascade gains, damping PIDs),
the fault policy and the obstacles. It serialises to the TOML control format of the Rust core
(:meth:`Task.to_toml`, :meth:`Task.from_toml`), so a task written here runs the same from the
CLI. :meth:`popup.Model.run_task` runs one; :meth:`popup.Model.rollout_task` runs a batch
(payloads, pressures, gains, effects, initial poses) in parallel with the GIL released.

Units are SI: angles rad, rates rad/s, positions m, torques N·m, time s. The discrete-time
laws are in ``docs/control.md``.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Mapping, NamedTuple, Optional, Sequence, Union

import numpy as np
import tomli_w

from . import _core
from .exceptions import InputError
from .results import CHANNELS, UNITS, WrinkleAlarm, ChannelTable

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = [
    "CONTROL_CHANNELS",
    "GAIN_NAMES",
    "PHASE_KINDS",
    "Controller",
    "Phase",
    "Obstacle",
    "Task",
    "Event",
    "ControlResult",
    "ControlBatch",
    "const",
    "step",
    "square",
    "ramp",
    "min_jerk",
    "sine",
    "chirp",
    "samples",
    "gains_to_flat",
    "gains_from_flat",
]

CONTROL_CHANNELS: List[str] = list(_core.control_channels())
"""Controller channels appended to every closed-loop result (see :class:`ControlResult`)."""
GAIN_NAMES: List[str] = list(_core.gain_names())
"""Flat gain layout: ``pos_kp[0..2], pos_ki, vel_kp, vel_ki, damp_kp, damp_ki, damp_kd, cart_k``."""
PHASE_KINDS = ("deflated", "inflating", "ready", "moving", "grasping", "damping", "holding", "releasing", "withdrawing", "phase")
_CIDX = {c: i for i, c in enumerate(CONTROL_CHANNELS)}
_FAULT_CODES = {-1: "WrinkleAlarm", -2: "Saturated", -3: "Contact", -4: "Unstable"}
_GAIN_KEYS = ("pos_kp", "pos_ki", "vel_kp", "vel_ki", "damp_kp", "damp_ki", "damp_kd")

Signal = Dict[str, Any]


# ---------------------------------------------------------------- reference signals
def const(value: float) -> Signal:
    """Constant reference [rad]."""
    return {"kind": "const", "value": float(value)}


def step(from_: float, to: float, delay: float = 0.0) -> Signal:
    """``from_`` until ``delay`` [s], then ``to`` [rad]."""
    return {"kind": "step", "from": float(from_), "to": float(to), "delay": float(delay)}


def square(low: float, high: float, period: float, delay: float = 0.0) -> Signal:
    """``low`` until ``delay``, then ``high``/``low`` alternating every half ``period`` [s]."""
    return {"kind": "square", "low": float(low), "high": float(high), "period": float(period), "delay": float(delay)}


def ramp(from_: float, to: float, rate: float, delay: float = 0.0) -> Signal:
    """From ``from_`` towards ``to`` at ``rate`` [rad/s] starting at ``delay``."""
    return {"kind": "ramp", "from": float(from_), "to": float(to), "rate": float(rate), "delay": float(delay)}


def min_jerk(from_: float, to: float, duration: float, delay: float = 0.0) -> Signal:
    """Minimum-jerk move (zero velocity and acceleration at both ends)."""
    return {"kind": "min_jerk", "from": float(from_), "to": float(to), "delay": float(delay), "duration": float(duration)}


def sine(amplitude: float, freq_hz: float, offset: float = 0.0, phase: float = 0.0, delay: float = 0.0) -> Signal:
    """``offset + amplitude sin(2π f (t − delay) + phase)``."""
    return {"kind": "sine", "offset": float(offset), "amplitude": float(amplitude), "freq_hz": float(freq_hz), "phase": float(phase), "delay": float(delay)}


def chirp(amplitude: float, f0_hz: float, f1_hz: float, duration: float, offset: float = 0.0, delay: float = 0.0) -> Signal:
    """Linear chirp from ``f0_hz`` to ``f1_hz`` over ``duration`` [s]."""
    return {
        "kind": "chirp",
        "offset": float(offset),
        "amplitude": float(amplitude),
        "f0_hz": float(f0_hz),
        "f1_hz": float(f1_hz),
        "duration": float(duration),
        "delay": float(delay),
    }


def samples(t: Any, y: Any) -> Signal:
    """User samples (linear interpolation, held at the ends)."""
    return {"kind": "samples", "t": [float(v) for v in np.asarray(t, dtype=float).ravel()], "y": [float(v) for v in np.asarray(y, dtype=float).ravel()]}


def _signals(name: str, x: Any) -> List[Signal]:
    if isinstance(x, Mapping) or np.ndim(x) == 0 and not isinstance(x, (list, tuple)):
        raise InputError(f"input {name}: expected 3 signals (one per motor joint), got {x!r}")
    if len(x) != 3:
        raise InputError(f"input {name}: expected 3 signals (one per motor joint), got {len(x)}")
    return [dict(s) if isinstance(s, Mapping) else const(float(s)) for s in x]


# ---------------------------------------------------------------- gains
def gains_to_flat(gains: Optional[Mapping[str, Any]] = None, base: Optional[np.ndarray] = None) -> np.ndarray:
    """Flat gain vector (:data:`GAIN_NAMES` order) from a mapping such as
    ``{"vel_kp": 1000, "damp_kp": [0.04, 0.04, 0.0]}`` applied on top of ``base``."""
    f = np.array(Controller().flat_gains() if base is None else base, dtype=np.float64)
    for k, v in (gains or {}).items():
        if k == "cart_k":
            f[21] = float(v)
        elif k in _GAIN_KEYS:
            g = _GAIN_KEYS.index(k)
            f[3 * g : 3 * g + 3] = np.broadcast_to(np.asarray(v, dtype=np.float64), (3,))
        else:
            raise InputError(f"input gains: unknown gain {k!r}; known: {list(_GAIN_KEYS) + ['cart_k']}")
    return f


def gains_from_flat(flat: Any) -> Dict[str, Any]:
    """Inverse of :func:`gains_to_flat`."""
    f = np.asarray(flat, dtype=np.float64)
    out: Dict[str, Any] = {k: f[3 * g : 3 * g + 3].tolist() for g, k in enumerate(_GAIN_KEYS)}
    out["cart_k"] = float(f[21])
    return out


# ---------------------------------------------------------------- configuration objects
@dataclass
class Controller:
    """Controller settings (see ``docs/control.md``).

    ``gains``: any of ``pos_kp pos_ki vel_kp vel_ki damp_kp damp_ki damp_kd`` (a number or
    three) and ``cart_k``; unset gains take the thesis defaults. ``motor``: motoreducer fields
    for all three joints (``gear_ratio``, ``torque_per_unit`` [N·m per drive unit],
    ``tau_max`` [N·m], ``current_bandwidth`` [rad/s], ``encoder_counts``); ``motors``: three
    such mappings. ``damping``: damping PIDs on (bool or three). ``cartesian_arm``: the
    kinematics of the Cartesian law and its workspace check: ``"prbm"`` (the chain's own,
    default), ``"as_built"`` (the arm file's rigid thesis Table 1, as the thesis's chapter 8
    did with its PRBM plant) or ``"ik"`` (Table 2).
    """

    rate_hz: float = 10_000.0
    gains: Dict[str, Any] = field(default_factory=dict)
    motor: Optional[Dict[str, Any]] = None
    motors: Optional[List[Dict[str, Any]]] = None
    damping: Union[bool, Sequence[bool]] = False
    damping_lpf_rad_s: float = 13.5
    v_max: float = math.inf
    anti_windup: bool = True
    cartesian_arm: str = "prbm"

    def to_dict(self) -> Dict[str, Any]:
        d: Dict[str, Any] = {
            "rate_hz": float(self.rate_hz),
            "damping": bool(self.damping) if isinstance(self.damping, (bool, np.bool_)) else [bool(b) for b in self.damping],
            "damping_lpf_rad_s": float(self.damping_lpf_rad_s),
            "v_max": float(self.v_max),
            "anti_windup": bool(self.anti_windup),
            "cartesian_arm": str(self.cartesian_arm),
            "gains": {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.gains.items()},
        }
        if self.motor is not None:
            d["motor"] = dict(self.motor)
        if self.motors is not None:
            d["motors"] = [dict(m) for m in self.motors]
        return d

    def flat_gains(self) -> np.ndarray:
        """This controller's gains in the flat layout (defaults filled in)."""
        text = tomli_w.dumps({"controller": self.to_dict()})
        g, _ = _core.check_control(_default_core_model(), text, "<controller>")
        return np.asarray(g)


_DEFAULT_MODEL: List[Any] = []


def _default_core_model() -> Any:
    if not _DEFAULT_MODEL:
        _DEFAULT_MODEL.append(_core.Model(_core.Arm.builtin("popup-lab"), 1e-4))
    return _DEFAULT_MODEL[0]


@dataclass
class Phase:
    """One phase of a task.

    ``kind`` is one of :data:`PHASE_KINDS`; it sets defaults (``grasping`` needs
    ``payload_kg``, ``releasing`` sets the payload to 0, ``damping`` turns the damping PIDs on
    and waits until still, ``deflated``/``inflating`` set the pressures, ``moving`` and
    ``withdrawing`` need a motion). Give at most one motion: ``hold=True``, ``track`` (three
    signals or numbers [rad]), ``velocity`` (three signals [rad/s], position loops bypassed),
    ``move_to`` (three angles [rad], with ``duration`` [s]) or ``cartesian`` (target p_WE [m]).
    ``until``: exit guard, keys ``min_time``, ``max_time`` [s], ``settled`` [rad], ``still``
    [m/s²], ``at_target`` [m].
    """

    kind: str
    name: Optional[str] = None
    hold: Optional[bool] = None
    track: Optional[Sequence[Any]] = None
    velocity: Optional[Sequence[Any]] = None
    move_to: Optional[Sequence[float]] = None
    duration: Optional[float] = None
    cartesian: Optional[Sequence[float]] = None
    payload_kg: Optional[float] = None
    pressure_pa: Optional[Sequence[float]] = None
    damping: Optional[Union[bool, Sequence[bool]]] = None
    until: Optional[Dict[str, float]] = None

    def to_dict(self) -> Dict[str, Any]:
        if self.kind not in PHASE_KINDS:
            raise InputError(f"input phase kind: {self.kind!r} unknown; known: {list(PHASE_KINDS)}")
        d: Dict[str, Any] = {"kind": self.kind}
        if self.name is not None:
            d["name"] = self.name
        if self.hold is not None:
            d["hold"] = bool(self.hold)
        if self.track is not None:
            d["track"] = _signals("track", self.track)
        if self.velocity is not None:
            d["velocity"] = _signals("velocity", self.velocity)
        if self.move_to is not None:
            if self.duration is None:
                raise InputError(f"input phase {self.name or self.kind}: move_to needs a duration [s]")
            d["move_to"] = {"q": [float(v) for v in self.move_to], "duration": float(self.duration)}
        if self.cartesian is not None:
            d["cartesian"] = {"target": [float(v) for v in self.cartesian]}
        if self.payload_kg is not None:
            d["payload_kg"] = float(self.payload_kg)
        if self.pressure_pa is not None:
            d["pressure_pa"] = [float(v) for v in self.pressure_pa]
        if self.damping is not None:
            d["damping"] = bool(self.damping) if isinstance(self.damping, (bool, np.bool_)) else [bool(b) for b in self.damping]
        if self.until is not None:
            d["until"] = {k: float(v) for k, v in self.until.items()}
        return d


@dataclass
class Obstacle:
    """An obstacle in the base frame W: use :meth:`sphere`, :meth:`box` or :meth:`plane`."""

    name: str
    shape: str
    params: Dict[str, Any]

    @staticmethod
    def sphere(name: str, center: Sequence[float], radius: float) -> "Obstacle":
        """Sphere of centre p_WC [m] and radius [m]."""
        return Obstacle(name, "sphere", {"center": [float(v) for v in center], "radius": float(radius)})

    @staticmethod
    def box(name: str, center: Sequence[float], half_extents: Sequence[float], yaw: float = 0.0) -> "Obstacle":
        """Box of centre [m] and half extents [m], turned by ``yaw`` about W's z axis [rad]."""
        return Obstacle(name, "box", {"center": [float(v) for v in center], "half_extents": [float(v) for v in half_extents], "yaw": float(yaw)})

    @staticmethod
    def plane(name: str, point: Sequence[float], normal: Sequence[float]) -> "Obstacle":
        """Half-space below the plane through ``point`` with outward ``normal`` (a table top)."""
        return Obstacle(name, "plane", {"point": [float(v) for v in point], "normal": [float(v) for v in normal]})

    def to_dict(self) -> Dict[str, Any]:
        return {"name": self.name, self.shape: dict(self.params)}


@dataclass
class Task:
    """A closed-loop task: phases, controller, fault policy and obstacles.

    ``faults`` keys: ``wrinkle``, ``saturation``, ``contact`` (each ``"continue"``, ``"hold"``,
    ``"stop"`` or ``"retreat"``), ``wrinkle_clear_ratio``, ``saturation_time`` [s],
    ``contact_margin`` [m], ``clear_time`` [s].
    """

    phases: List[Phase]
    controller: Controller = field(default_factory=Controller)
    faults: Optional[Dict[str, Any]] = None
    obstacles: List[Obstacle] = field(default_factory=list)
    payload_radius_m: float = 0.05

    def to_dict(self) -> Dict[str, Any]:
        d: Dict[str, Any] = {"controller": self.controller.to_dict(), "payload_radius_m": float(self.payload_radius_m)}
        if self.faults:
            d["faults"] = dict(self.faults)
        if self.obstacles:
            d["obstacles"] = [o.to_dict() for o in self.obstacles]
        d["phases"] = [p.to_dict() for p in self.phases]
        return d

    def to_toml(self) -> str:
        """The TOML control format (readable by the Rust core and the CLI)."""
        return tomli_w.dumps(self.to_dict())

    @staticmethod
    def from_toml(source: Union[str, Path]) -> "Task":
        """Read a task from TOML text or a file path. The text is checked by the core's
        parser first: an unknown key or a bad value raises :class:`popup.InputError` (or
        :class:`popup.ParameterError`) naming the file, line and key."""
        p = Path(source) if not isinstance(source, str) or ("\n" not in source and source.endswith(".toml")) else None
        text = p.read_text() if p is not None else str(source)
        # the core's parser checks keys and values and names the line and key
        _core.check_control(_default_core_model(), text, str(p or "<task>"))
        d = tomllib.loads(text)
        c = dict(d.get("controller", {}))
        ctrl = Controller(**{k: v for k, v in c.items()})
        phases = []
        for ph in d.get("phases", []):
            ph = dict(ph)
            mt = ph.pop("move_to", None)
            cart = ph.pop("cartesian", None)
            phases.append(
                Phase(
                    **ph,
                    move_to=None if mt is None else mt["q"],
                    duration=None if mt is None else mt["duration"],
                    cartesian=None if cart is None else cart["target"],
                )
            )
        obs = []
        for o in d.get("obstacles", []):
            o = dict(o)
            name = o.pop("name")
            (shape, params), = o.items()
            obs.append(Obstacle(name, shape, params))
        return Task(phases, ctrl, d.get("faults"), obs, d.get("payload_radius_m", 0.05))

    @staticmethod
    def single(phase: Phase, controller: Optional[Controller] = None, **kw: Any) -> "Task":
        """A task of one phase."""
        return Task([phase], controller or Controller(), **kw)


# ---------------------------------------------------------------- results
class Event(NamedTuple):
    """One entry of a closed-loop run's log."""

    t: float
    """Time [s]."""
    kind: str
    """``transition``, ``timeout``, ``fault``, ``alarm``, ``contact``, ``payload`` or ``pressure``."""
    from_phase: str
    """Phase before."""
    to_phase: str
    """Phase after."""
    detail: str
    """Guard that fired, fault details, contact location..."""


class _Control(ChannelTable):
    control: np.ndarray

    def control_channel(self, name: str) -> np.ndarray:
        """One controller channel by name (:data:`CONTROL_CHANNELS`)."""
        if name not in _CIDX:
            raise KeyError(f"unknown controller channel {name!r}; channels are {CONTROL_CHANNELS}")
        return self.control[..., _CIDX[name]]

    @property
    def ref_q(self) -> np.ndarray:
        """Position references [rad], (..., 3)."""
        return self.control[..., 0:3]

    @property
    def vref(self) -> np.ndarray:
        """Velocity references entering the velocity loops (damping term included) [rad/s]."""
        return self.control[..., 3:6]

    @property
    def u_damp(self) -> np.ndarray:
        """Damping-PID outputs [rad/s]."""
        return self.control[..., 6:9]

    @property
    def a_rel(self) -> np.ndarray:
        """Filtered relative tip accelerations (damping inputs) [m/s²]."""
        return self.control[..., 9:12]

    @property
    def tau_cmd(self) -> np.ndarray:
        """Torque references after the limit, before the current loop [N·m]."""
        return self.control[..., 12:15]

    @property
    def phase_code(self) -> np.ndarray:
        """Active phase index (negative: fault, see :class:`ControlResult`)."""
        return self.control[..., 15]

    @property
    def d_min(self) -> np.ndarray:
        """Minimum clearance to any obstacle [m] (inf without obstacles)."""
        return self.control[..., 16]


@dataclass
class ControlResult(_Control):
    """One closed-loop run: the sensor channels (as :class:`popup.SimResult`), the controller
    channels, the event log and how the run ended (``status``: ``"completed"`` or
    ``"unstable"``: rows after the failure are NaN). ``phase_names[i]`` names phase code i;
    codes −1..−4 are WrinkleAlarm, Saturated, Contact, Unstable."""

    data: np.ndarray
    control: np.ndarray
    events: List[Event]
    status: str
    alarms: List[WrinkleAlarm]
    phase_names: List[str]
    params: Dict[str, Any] = field(default_factory=dict)
    warnings: List[str] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.data.shape[0])

    def phase_name(self, code: float) -> str:
        """Name of a phase code."""
        c = int(code)
        return _FAULT_CODES[c] if c < 0 else self.phase_names[c]

    def transitions(self) -> List[Event]:
        """Only the phase changes (transitions, timeouts, faults) of the log."""
        return [e for e in self.events if e.kind in ("transition", "timeout", "fault", "contact") and e.from_phase != e.to_phase]

    def events_frame(self) -> Any:
        """The log as a pandas DataFrame."""
        import pandas as pd

        return pd.DataFrame(self.events, columns=list(Event._fields))

    def to_pandas(self) -> Any:
        """Sensor and controller channels, one row per sample, indexed by time."""
        import pandas as pd

        df = pd.DataFrame(np.hstack([self.data, self.control]), columns=CHANNELS + CONTROL_CHANNELS)
        df["phase"] = [self.phase_name(c) if np.isfinite(c) else "" for c in self.control[:, _CIDX["phase"]]]
        return df.set_index("t")

    def plot(self, *, axes: Any = None) -> Any:
        """Joint angles with references, bending angles, motor torques and the phase
        timeline (four stacked axes); returns the figure."""
        import matplotlib.pyplot as plt

        if axes is None:
            fig, axes = plt.subplots(4, 1, sharex=True, figsize=(8, 9))
        else:
            fig = axes[0].figure
        t = self.time
        for j in range(3):
            (ln,) = axes[0].plot(t, self.q[:, j], label=f"q{j + 1}")
            axes[0].plot(t, self.ref_q[:, j], "--", color=ln.get_color(), lw=0.8)
        axes[0].set_ylabel("q [rad]")
        axes[0].legend(loc="best", fontsize="small")
        for i, n in enumerate(["d11", "d12", "d21", "d22"]):
            axes[1].plot(t, self.bending[:, i], label=n)
        axes[1].set_ylabel("bending [rad]")
        axes[1].legend(loc="best", fontsize="small")
        for j in range(3):
            axes[2].plot(t, self.tau[:, j], label=f"tau{j + 1}")
        axes[2].set_ylabel("torque [N·m]")
        axes[2].legend(loc="best", fontsize="small")
        axes[3].step(t, self.phase_code, where="post")
        codes = sorted({int(c) for c in self.phase_code[np.isfinite(self.phase_code)]})
        axes[3].set_yticks(codes, [self.phase_name(c) for c in codes])
        axes[3].set_xlabel("t [s]")
        return fig


@dataclass
class ControlBatch(_Control):
    """A batch of closed-loop runs: ``data`` (B, S, NCH), ``control`` (B, S, NCTRL), and per
    run ``events``, ``status``, ``alarms``, ``errors``; ``gains`` (B, NG) as run."""

    data: np.ndarray
    control: np.ndarray
    events: List[List[Event]]
    status: List[str]
    alarms: List[List[WrinkleAlarm]]
    errors: List[Optional[str]]
    gains: np.ndarray
    phase_names: List[str]
    params: Dict[str, Any] = field(default_factory=dict)
    warnings: List[List[str]] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.data.shape[0])

    def __getitem__(self, b: int) -> ControlResult:
        return ControlResult(
            data=self.data[b],
            control=self.control[b],
            events=self.events[b],
            status=self.status[b],
            alarms=self.alarms[b],
            phase_names=self.phase_names,
            params={k: (v[b] if isinstance(v, np.ndarray) and v.ndim >= 1 and v.shape[0] == len(self) else v) for k, v in self.params.items()},
            warnings=self.warnings[b] if self.warnings else [],
        )

    def to_pandas(self) -> Any:
        """One row per run: the swept inputs (payload, pressures, gains) and scalar metrics
        (peak |bending|, RMS bending, peak |torque|, peak tip acceleration, wrinkle alarms)."""
        import pandas as pd

        rows = []
        for b in range(len(self)):
            r: Dict[str, Any] = {"payload_kg": float(self.params["payload_kg"][b]), "p1": float(self.params["pressure_pa"][b][0]), "p2": float(self.params["pressure_pa"][b][1])}
            r.update({n: float(v) for n, v in zip(GAIN_NAMES, self.gains[b])})
            r.update(_metrics(self.data[b]))
            r.update({"status": self.status[b], "n_alarms": len(self.alarms[b]), "error": self.errors[b]})
            rows.append(r)
        return pd.DataFrame(rows)


def _metrics(data: np.ndarray) -> Dict[str, float]:
    idx = {c: i for i, c in enumerate(CHANNELS)}
    bend = data[:, [idx[c] for c in ("d11", "d12", "d21", "d22")]]
    tau = data[:, [idx[c] for c in ("tau1", "tau2", "tau3")]]
    imu = data[:, [idx[c] for c in ("imu2_ax", "imu2_ay", "imu2_az")]]
    return {
        "peak_bending_rad": float(np.nanmax(np.abs(bend))) if np.isfinite(bend).any() else math.nan,
        "rms_bending_rad": float(np.sqrt(np.nanmean(bend**2))) if np.isfinite(bend).any() else math.nan,
        "peak_torque_nm": float(np.nanmax(np.abs(tau))) if np.isfinite(tau).any() else math.nan,
        "peak_tip_accel_ms2": float(np.nanmax(np.linalg.norm(imu - imu[:1], axis=1))) if np.isfinite(imu).any() else math.nan,
        "peak_moment_ratio": float(np.nanmax(data[:, [idx["m1_ratio"], idx["m2_ratio"]]])) if np.isfinite(data).any() else math.nan,
    }


_ = UNITS  # re-exported units apply to the sensor channels
