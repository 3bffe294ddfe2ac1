"""The Python front of the engine: :class:`Model` (arm + options + parameters), single
runs (torque-driven or encoder replay) and batched rollouts.

Units are SI (m, kg, s, rad, N·m, Pa). Joint order of the chain is
``q1, q2, d11, d12, q3, d21, d22`` for ``popup-lab`` (see :attr:`Model.joint_names`).
"""

from __future__ import annotations

import math
import os
import warnings as _warnings
from typing import TYPE_CHECKING, Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _core
from .exceptions import InputError, PopupWarning, StepTooLargeError
from .results import BatchResult, SimResult, WrinkleAlarm

if TYPE_CHECKING:
    from .control import ControlBatch, ControlResult, Task

__all__ = ["Arm", "RigidArm", "Model", "load_arm", "arm_names", "arm_motor"]

Arm = _core.Arm
RigidArm = _core.RigidArm

ArmLike = Union["_core.Arm", str, "os.PathLike[str]"]


def _toml_loads(text: str) -> Dict[str, Any]:
    try:
        import tomllib
    except ImportError:  # Python < 3.11
        import tomli as tomllib  # type: ignore[no-redef]
    return tomllib.loads(text)


def _report(errors: Sequence[Optional[Tuple[str, str]]], warns: Sequence[Sequence[str]], raise_on_error: bool) -> None:
    """Raise the first failed job's error (``raise_on_error``) and issue every distinct
    warning of a batch once, attributed to the caller of the public method."""
    if raise_on_error:
        for e in errors:
            if e is not None:
                _core._raise(e[0], e[1])
    seen = set()
    for ws in warns:
        for w in ws:
            if w not in seen:
                seen.add(w)
                _warnings.warn(w, PopupWarning, stacklevel=4)


def arm_names() -> List[str]:
    """Names :func:`load_arm` (and ``popup.Model(name)``, the CLI's ``--arm``, scenario and
    measured-run ``arm`` keys) know: ``popup-lab`` and the arm files packaged with the core
    (``crates/popup-core/arms/<name>.toml``, e.g. ``popup-lab-thesis``, docs/thesis.md).
    The list is the core's (``popup_core::spec::ArmSpec::BUILTIN``): one resolution for
    every front end."""
    return list(_core.Arm.builtin_names())


def arm_motor(name: str) -> Dict[str, float]:
    """The controller's motoreducer constants a packaged arm file states for its drives
    (comment lines ``# motor.<key> = <value>``: ``torque_per_unit`` [N·m per drive unit],
    ``tau_max`` [N·m], ``current_bandwidth`` [rad/s]), ready for
    ``Controller(motor=popup.arm_motor("popup-lab-thesis"))``; empty when the file states
    none. The controller's motoreducer is not part of the arm description, so an arm file
    fitted together with its drives carries them as these comments.

    Raises :class:`InputError` for a name that is not a packaged arm file."""
    text = _core.Arm.packaged_source(name)
    if text is None:
        packaged = [n for n in arm_names() if _core.Arm.packaged_source(n) is not None]
        raise InputError(f"input name: {name!r} is not a packaged arm file; packaged: {', '.join(packaged)} (all arms: {', '.join(arm_names())})")
    out: Dict[str, float] = {}
    for line in text.splitlines():
        t = line.strip()
        if t.startswith("# motor.") and "=" in t:
            k, v = t[len("# motor.") :].split("=", 1)
            out[k.strip()] = float(v.split()[0])
    return out


def load_arm(arm: ArmLike) -> "_core.Arm":
    """An :class:`Arm` from an Arm, a built-in name (:func:`arm_names`: ``"popup-lab"``,
    ``"popup-lab-thesis"``, ...) or a path to a TOML arm file. An unknown name raises
    :class:`UnknownArmError` listing the known ones."""
    if isinstance(arm, _core.Arm):
        return arm
    if not isinstance(arm, (str, os.PathLike)):
        raise InputError(f"input arm: expected an Arm, a built-in name ({', '.join(arm_names())}) or a path to an arm file, got {arm!r}")
    s = os.fspath(arm)
    if not isinstance(s, str) or "\x00" in s:
        raise InputError(f"input arm: {s!r} is not an arm name or a path to an arm file")
    if s in _core.Arm.builtin_names():
        return _core.Arm.builtin(s)
    if s.endswith(".toml") or os.path.exists(s):
        return _core.Arm.load(s)
    return _core.Arm.builtin(s)  # raises UnknownArmError naming the built-ins


def _as_float_array(name: str, x: Any, ndim: Optional[int]) -> np.ndarray:
    if np.iscomplexobj(x):
        raise InputError(f"input {name}: complex values; expected real numbers")
    try:
        a = np.array(x, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InputError(f"input {name}: cannot convert to a float array ({e})") from None
    if ndim is not None and a.ndim != ndim:
        raise InputError(f"input {name}: expected {ndim} dimensions, got shape {a.shape}")
    return a


def check_names(name: str, x: Any) -> List[str]:
    """A list of names (one string counts as one name), or an InputError naming ``name``."""
    if isinstance(x, str):
        return [x]
    try:
        out = list(x)
    except TypeError:
        raise InputError(f"input {name}: expected a list of names, got {x!r}") from None
    bad = [v for v in out if not isinstance(v, str)]
    if bad:
        raise InputError(f"input {name}: expected names (strings), got {bad[0]!r}")
    return out


def _flag(name: str, x: Any) -> bool:
    """A bool (or 0/1), or an InputError naming ``name``."""
    if isinstance(x, (bool, np.bool_)) or (isinstance(x, (int, np.integer)) and x in (0, 1)):
        return bool(x)
    raise InputError(f"input {name}: expected True or False, got {x!r}")


def check_scalar(name: str, x: Any, unit: str) -> float:
    """One number of argument ``name``, or an InputError naming it."""
    try:
        if np.ndim(x) != 0:
            raise TypeError(f"shape {np.shape(x)}")
        if np.iscomplexobj(x):
            raise TypeError("complex")
        return float(x)
    except (TypeError, ValueError) as e:
        raise InputError(f"input {name}: expected one number [{unit}], got {x!r} ({e})") from None


def _pair(name: str, x: Any) -> Tuple[float, float]:
    """Link 1 and link 2 values of ``name`` (one number is used for both), or an
    InputError naming the argument."""
    try:
        if np.iscomplexobj(x):
            raise TypeError("complex")
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InputError(f"input {name}: expected (link 1, link 2) [Pa] or one number for both, got {x!r} ({e})") from None
    if a.ndim == 0:
        return (float(a), float(a))
    if a.shape != (2,):
        raise InputError(f"input {name}: expected (link 1, link 2) [Pa] or one number for both, got shape {a.shape}")
    return (float(a[0]), float(a[1]))


def _duration(x: Any) -> float:
    d = check_scalar("duration", x, "s")
    if not (math.isfinite(d) and d >= 0):
        raise InputError(f"input duration: {d!r} s must be finite and >= 0")
    return d


def check_threads(x: Any) -> int:
    """A thread count (0 = all cores), or an InputError naming ``threads``."""
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, np.integer)):
        raise InputError(f"input threads: expected an integer (0 = all cores), got {x!r}")
    if not -(2**63) <= int(x) < 2**63:  # the core takes a 64-bit count and refuses absurd ones itself
        raise InputError(f"input threads: {int(x)} is not a thread count (0 = all cores, or 1 up to a few times the machine's cores)")
    return int(x)


def check_count(what: str, x: Any, lo: int, hi: int, meaning: str = "") -> int:
    """``x`` as an int, refused with an :class:`InputError` naming input ``what`` unless it is
    an integer (not a bool) from ``lo`` to ``hi``; ``meaning`` says what it counts."""
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, np.integer)) or not lo <= x <= hi:
        raise InputError(f"input {what}: expected an integer from {lo} to {hi}{f' ({meaning})' if meaning else ''}, got {x!r}")
    return int(x)


def _rate(x: Any) -> float:
    r = check_scalar("sample_rate", x, "Hz")
    if not (math.isfinite(r) and r > 0):
        raise InputError(f"input sample_rate: {r!r} Hz must be finite and > 0")
    return r


def _tile(name: str, a: np.ndarray, nb: int, inner_ndim: int) -> np.ndarray:
    """Tile an array without batch axis (ndim == inner_ndim) to (nb, ...)."""
    if a.ndim == inner_ndim:
        return np.broadcast_to(a, (nb,) + a.shape).copy()
    if a.ndim == inner_ndim + 1 and a.shape[0] in (1, nb):
        return np.broadcast_to(a, (nb,) + a.shape[1:]).copy()
    raise InputError(f"input {name}: shape {a.shape} does not match the batch size {nb}")


def _effects_dict(row: np.ndarray) -> Dict[str, Dict[str, List[float]]]:
    from . import effects as fx

    return fx.from_flat(row)


#: The thesis's fitted FEM-link materials (section 2.3) by name: ``e_pa`` [Pa], ``wall_m``
#: [m], ``nu``, ``lambda_s`` [s] (stiffness-proportional damping; the thesis prints
#: × 10⁴ s, read as × 10⁻⁴ s, docs/beams.md), ``mu_per_s`` [1/s].
BEAM_PRESETS: Dict[str, Dict[str, float]] = {k: dict(v) for k, v in _core.BEAM_PRESETS.items()}


class Model:
    """An arm, simulation options and parameters.

    Parameters
    ----------
    arm : Arm, str or path
        A built-in arm name (``"popup-lab"``), an :class:`Arm`, or a TOML arm file.
    payload_kg : float, optional
        Payload at the tip [kg]; default the arm's ``payload.default_kg`` (2 kg).
    pressure_pa : (float, float), optional
        Relative inflation pressure of link 1 and 2 [Pa]; default the arm's (30 kPa).
    gravity : bool
        Gravity on (the arm's vector, z down) or off.
    dt : float
        Physics time step [s]. Default 1e-3 s.
    integrator : {"rk4", "semi_implicit"}
        ``"rk4"`` (order 4, default: integration error far below any model error you
        diagnose) or ``"semi_implicit"`` (order 1, one evaluation per step, MuJoCo
        ``implicitfast``-like).
    disable : iterable of {"gravity", "spring", "damper"}
        Force terms switched off.
    """

    def __init__(
        self,
        arm: ArmLike = "popup-lab",
        *,
        payload_kg: Optional[float] = None,
        pressure_pa: Optional[Sequence[float]] = None,
        gravity: bool = True,
        dt: float = 1e-3,
        integrator: str = "rk4",
        disable: Iterable[str] = (),
        _core_model: Optional["_core.Model"] = None,
    ) -> None:
        dis = check_names("disable", disable)
        if not _flag("gravity", gravity) and "gravity" not in dis:
            dis.append("gravity")
        if _core_model is None:
            if not isinstance(integrator, str):
                raise InputError(f"input integrator: expected a name (\"rk4\" or \"semi_implicit\"), got {integrator!r}")
            _core_model = _core.Model(load_arm(arm), dt=check_scalar("dt", dt, "s"), integrator=integrator, disable=dis)
        self._m = _core_model
        spec_defaults = self._defaults()
        self.payload_kg = check_scalar("payload_kg", spec_defaults[0] if payload_kg is None else payload_kg, "kg")
        self.pressure_pa: Tuple[float, float] = _pair("pressure_pa", spec_defaults[1] if pressure_pa is None else pressure_pa)
        # validate now, so a bad payload/pressure fails at construction
        info = self._m.param_data(self.payload_kg, self.pressure_pa)
        for w in info["warnings"]:
            _warnings.warn(w, PopupWarning, stacklevel=2)

    def _defaults(self) -> Tuple[float, Tuple[float, float]]:
        d = _toml_loads(self._m.arm.to_toml())
        return float(d["payload"]["default_kg"]), (float(d["links"][0]["pressure_pa"]), float(d["links"][1]["pressure_pa"]))

    # ------------------------------------------------------------------ properties
    @property
    def core(self) -> "_core.Model":
        """The compiled engine model (``popup._core.Model``)."""
        return self._m

    @property
    def arm(self) -> "_core.Arm":
        """The arm description."""
        return self._m.arm

    @property
    def dt(self) -> float:
        """Physics time step [s]."""
        return float(self._m.dt)

    @property
    def integrator(self) -> str:
        """Integrator name."""
        return str(self._m.integrator)

    @property
    def joint_names(self) -> List[str]:
        """Joint names in chain order."""
        return list(self._m.joint_names)

    @property
    def wrinkling_moment(self) -> np.ndarray:
        """Wrinkling-onset moment M_w of link 1 and 2 at the current pressures [N·m]."""
        return np.array(self._m.param_data(self.payload_kg, self.pressure_pa)["mw"])

    @property
    def stiffness(self) -> np.ndarray:
        """Bending stiffness k per chain joint at the current pressures [N·m/rad] (0 on motors)."""
        return np.array(self._m.param_data(self.payload_kg, self.pressure_pa)["k"])

    @property
    def damping(self) -> np.ndarray:
        """Bending damping c per chain joint [N·m·s/rad] (0 on motors)."""
        return np.array(self._m.param_data(self.payload_kg, self.pressure_pa)["c"])

    # ------------------------------------------------------------------ effects
    @property
    def effects_flat(self) -> np.ndarray:
        """The arm's effect parameters as a flat vector (registry order, see
        :mod:`popup.effects`)."""
        from . import effects as fx

        d = _toml_loads(self._m.arm.to_toml()).get("effects", {})
        return fx.to_flat(d)

    @property
    def effects(self) -> Dict[str, Dict[str, List[float]]]:
        """Effects switched on in this model: ``{effect: {param: values}}``."""
        from . import effects as fx

        return fx.from_flat(self.effects_flat)

    def with_effects(self, effects: Mapping[str, Mapping[str, Any]]) -> "Model":
        """A copy with several effects set (``{effect: {param: values}}``; parameters not
        named keep their values). Structural parameters recompile the engine model."""
        from . import effects as fx

        over: Dict[str, Dict[str, List[float]]] = {}
        for name, params in effects.items():
            over[name] = {k: [float(x) for x in v] for k, v in fx.normalize(name, params).items()}
            for k, v in over[name].items():
                if len(v) == 1:
                    over[name][k] = v[0]  # type: ignore[assignment]
        arm = self._m.arm.with_overrides({"effects": over})
        return self._recompiled(arm)

    def with_effect(self, name: str, **params: Any) -> "Model":
        """A copy with effect ``name`` switched on with ``params`` (see
        ``popup.effects.EFFECTS[name].params`` for names, units and bounds), e.g.
        ``model.with_effect("joint_friction", tau_c=[1.4, 2.1, 0.9])``."""
        return self.with_effects({name: params})

    def without_effect(self, name: str) -> "Model":
        """A copy with effect ``name`` back at its neutral values."""
        from . import effects as fx

        if name not in fx.EFFECTS:
            fx.normalize(name, {})
        return self.with_effects({name: {k: p.neutral for k, p in fx.EFFECTS[name].params.items()}})

    @property
    def link_models(self) -> List[str]:
        """Link models of link 1 and 2: ``"rigid"``, ``"prbm"``, ``"prbm(S)"`` (S PRBM
        segments) or ``"beam(n)"`` (an Euler–Bernoulli beam of n elements, docs/beams.md)."""
        return list(self._m.link_models)

    def with_links(
        self,
        link1: Optional[str] = None,
        link2: Optional[str] = None,
        *,
        preset: Optional[str] = None,
        **material: Any,
    ) -> "Model":
        """A copy with other link models: ``"rigid"`` (the link's universal joint locked at
        zero; its ``m*`` channels are the constraint moments at its root), ``"prbm"`` (one
        universal joint, the 7-DOF PRBM), ``"prbm(S)"`` (S = 1..3 segments) or
        ``"beam(n)"`` (n = 1..6 Euler–Bernoulli elements clamped at the link's motor, in the
        chain's floating frame); ``None`` keeps a link as it is. ``preset`` (a name of :data:`BEAM_PRESETS`, e.g. ``"thesis-1.2mm"``)
        and ``material`` (``e_pa``, ``wall_m``, ``nu``, ``lambda_s``, ``mu_per_s``,
        ``shear``; a number for both links or a pair) set the beam material, written to the
        ``higher_bending_modes`` effect. Beam links need a small ``dt`` with RK4 (the
        step check names the largest stable one) or ``integrator="semi_implicit"``.

        Example: ``model.with_links("prbm", "beam(4)", preset="thesis-0.8mm")``.
        """
        import re

        cur = self.effects_flat
        from . import effects as fx

        hbm = fx.from_flat(cur).get("higher_bending_modes", {})
        seg = list(hbm.get("segments", [1.0, 1.0]))
        el = list(hbm.get("elements", [0.0, 0.0]))
        for i, spec in enumerate((link1, link2)):
            if spec is None:
                continue
            m = re.fullmatch(r"\s*(rigid|prbm|beam)\s*(?:\(\s*(\d+)\s*\))?\s*", str(spec))
            if m is None:
                raise InputError(f"input link{i + 1}: {spec!r} is not a link model; use 'rigid', 'prbm', 'prbm(S)' (S = 1..3) or 'beam(n)' (n = 1..6)")
            kind, num = m.group(1), m.group(2)
            if kind == "rigid":
                if num is not None:
                    raise InputError(f"input link{i + 1}: {spec!r}: a rigid link takes no count; use 'rigid'")
                seg[i], el[i] = 0.0, 0.0
            elif kind == "prbm":
                seg[i], el[i] = float(num or 1), 0.0
            else:
                if num is None:
                    raise InputError(f"input link{i + 1}: {spec!r}: a beam link needs its element count, e.g. 'beam(4)'")
                seg[i], el[i] = 1.0, float(num)
        params: Dict[str, Any] = {"segments": seg, "elements": el}
        if preset is not None:
            if preset not in BEAM_PRESETS:
                raise InputError(f"input preset: {preset!r} is not a beam preset; known: {', '.join(BEAM_PRESETS)}")
            for k, v in BEAM_PRESETS[preset].items():
                params[k] = [v, v]
        for k, v in material.items():
            params[k] = [float(v), float(v)] if np.ndim(v) == 0 else [float(x) for x in v]
        return self.with_effects({"higher_bending_modes": params})

    def _recompiled(self, arm: "_core.Arm") -> "Model":
        dis = list(self._m.disabled)
        core = _core.Model(arm, dt=self.dt, integrator=self.integrator, gravity=None if "gravity" in dis else list(self._m.gravity), disable=dis)
        return Model(payload_kg=self.payload_kg, pressure_pa=self.pressure_pa, _core_model=core)

    def with_dt(self, dt: float, integrator: Optional[str] = None) -> "Model":
        """A copy with another physics step ``dt`` [s] (and integrator, default this one's);
        arm, effects and parameters unchanged."""
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0):
            raise InputError(f"input dt: {dt} must be finite and > 0 [s]")
        dis = list(self._m.disabled)
        core = _core.Model(self._m.arm, dt=dt, integrator=integrator or self.integrator, gravity=None if "gravity" in dis else list(self._m.gravity), disable=dis)
        return Model(payload_kg=self.payload_kg, pressure_pa=self.pressure_pa, _core_model=core)

    def with_params(self, *, payload_kg: Optional[float] = None, pressure_pa: Optional[Sequence[float]] = None) -> "Model":
        """A copy with other parameters, sharing the compiled engine model."""
        return Model(
            payload_kg=self.payload_kg if payload_kg is None else payload_kg,
            pressure_pa=self.pressure_pa if pressure_pa is None else pressure_pa,
            _core_model=self._m,
        )

    def describe(self) -> Dict[str, Any]:
        """Everything needed to reproduce a run of this model."""
        return {
            "arm": self.arm.name,
            "payload_kg": self.payload_kg,
            "pressure_pa": self.pressure_pa,
            "dt": self.dt,
            "integrator": self.integrator,
            "disabled": list(self._m.disabled),
            "gravity_mps2": list(self._m.gravity),
            "wrinkle_coefficient": float(self._m.wrinkle_coefficient),
            "popup_version": _core.__version__,
            "build_profile": _core.BUILD_PROFILE,
        }

    def __repr__(self) -> str:
        return (
            f"Model(arm={self.arm.name!r}, payload_kg={self.payload_kg}, pressure_pa={self.pressure_pa}, "
            f"dt={self.dt}, integrator={self.integrator!r})"
        )

    # ------------------------------------------------------------------ statics & kinematics
    def rest_state(self, q_motor: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
        """Joint coordinates (nv,) at rest (nv = len(joint_names): 7, more with segments/torsion): motors at ``q_motor`` [rad], bending joints in
        static equilibrium under gravity and payload."""
        return np.asarray(self._m.rest_state(self.payload_kg, self.pressure_pa, list(map(float, q_motor))))

    def locked_modes(self, q_motor: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
        """Undamped natural frequencies of the bending joints with the motors locked at
        ``q_motor``, about the static equilibrium [rad/s], ascending."""
        q = self.rest_state(q_motor)
        return np.asarray(self._m.locked_modes(self.payload_kg, self.pressure_pa, q.tolist()))

    def stable_dt(self, q: Optional[Sequence[float]] = None, *, replay: bool = False) -> float:
        """This model's ``dt`` [s] if its integrator is stable with it about ``q`` (full
        joint vector, default :meth:`rest_state`), else the largest stable step the engine's
        step check finds [s] (the value a run would name in its
        :class:`~popup.StepTooLargeError`). ``replay``: motors prescribed (encoder replay)
        instead of torque-driven. Beam links need small steps with RK4 (docs/beams.md)."""
        qq = self.rest_state() if q is None else np.asarray(q, dtype=np.float64)
        try:
            self._m.check_step(self.payload_kg, self.pressure_pa, [float(x) for x in qq], replay)
        except StepTooLargeError as e:
            if e.dt_max is None:
                raise
            return float(e.dt_max)
        return self.dt

    def holding_torque(self, q_motor: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
        """Motor torques (3,) that hold the arm at rest at ``q_motor`` [N·m]."""
        q = self.rest_state(q_motor)
        g = np.asarray(self._m.gravity_torque(self.payload_kg, q.tolist()))
        return g[list(self._m.motor_index)]

    def end_effector(self, q: Sequence[float]) -> np.ndarray:
        """End-effector position p_WE (3,) [m] for chain coordinates q (nv,)."""
        return np.asarray(self._m.end_effector(list(map(float, q))))

    def frames(self, q: Sequence[float]) -> np.ndarray:
        """Homogeneous transforms T_W_i of frames 0..7, shape (8, 4, 4)."""
        return np.asarray(self._m.frames(list(map(float, q))))

    def mass_matrix(self, q: Sequence[float]) -> np.ndarray:
        """Joint-space mass matrix (7, 7) with armature [kg·m²]."""
        return np.asarray(self._m.mass_matrix(self.payload_kg, list(map(float, q))))

    def rigid(self, table: str = "as_built") -> "_core.RigidArm":
        """Rigid 3-DOF kinematics: ``"as_built"`` (thesis Table 1), ``"ik"`` (Table 2) or
        ``"prbm"`` (the 7-DOF chain with its bending joints at zero, reach 1.2 m)."""
        return _core.RigidArm(self.arm, table)

    # ------------------------------------------------------------------ runs
    def simulate(
        self,
        torque: Any = None,
        *,
        duration: float,
        torque_times: Any = None,
        initial_q: Any = None,
        initial_v: Any = None,
        sample_rate: float = 500.0,
        check_step: bool = True,
        log: Optional[Union[str, "os.PathLike[str]"]] = None,
    ) -> SimResult:
        """Torque-driven run: motor torques in, full motion out.

        Parameters
        ----------
        torque : None, (3,) or (N, 3) array
            Motor torques [N·m] (at the reducer, armature included in the model). None =
            zero; (3,) = constant; (N, 3) = time samples at ``torque_times`` (default: every
            ``dt`` from 0), interpolated linearly and held after the last sample.
        duration : float
            Simulated time [s].
        initial_q, initial_v : (nv,) arrays, optional
            Initial chain coordinates [rad] and rates [rad/s]; default: at rest with the
            motors at 0 and the bending joints in static equilibrium.
        sample_rate : float
            Output rate [Hz]; 1/sample_rate must be a multiple of ``dt``.
        log : path, optional
            MCAP file the run is streamed into as it runs (``docs/logging.md``);
            :func:`popup.read_log` gives back the same arrays.
        """
        return self.rollout(
            torque=torque,
            torque_times=torque_times,
            duration=duration,
            initial_q=initial_q,
            initial_v=initial_v,
            sample_rate=sample_rate,
            threads=1,
            check_step=check_step,
            log=log,
        )[0]

    def replay(
        self,
        t: Any,
        q: Any,
        *,
        initial_q: Any = None,
        initial_v: Any = None,
        sample_rate: float = 500.0,
        check_step: bool = True,
        log: Optional[Union[str, "os.PathLike[str]"]] = None,
    ) -> SimResult:
        """Encoder-driven replay: the motor joints follow ``q`` (N, 3) [rad] at times ``t``
        (N,) [s] exactly (natural cubic spline: consistent q, q̇, q̈); the bending joints
        are integrated; the motor torques needed are an output.

        By default the run starts at rest: bending joints in static equilibrium at the
        first encoder sample. ``log``: an MCAP file the run is streamed into
        (``docs/logging.md``).
        """
        return self.rollout(
            encoder_t=t,
            encoder_q=q,
            initial_q=initial_q,
            initial_v=initial_v,
            sample_rate=sample_rate,
            threads=1,
            check_step=check_step,
            log=log,
        )[0]

    def rollout(
        self,
        *,
        payload_kg: Any = None,
        pressure_pa: Any = None,
        torque: Any = None,
        torque_times: Any = None,
        duration: Optional[float] = None,
        encoder_t: Any = None,
        encoder_q: Any = None,
        initial_q: Any = None,
        initial_v: Any = None,
        sample_rate: float = 500.0,
        threads: int = 0,
        check_step: bool = True,
        raise_on_error: bool = True,
        effects: Any = None,
        log: Optional[Union[str, "os.PathLike[str]"]] = None,
    ) -> BatchResult:
        """Batched rollouts in parallel (Rust, GIL released), bit-identical to running the
        runs one by one and for any ``threads``.

        Every argument may carry a leading batch axis; singletons are tiled. Shapes:
        payload_kg ``([B])``, pressure_pa ``([B] x 2)``, torque ``(3,)`` (constant),
        ``(N x 3)`` (time samples) or ``(B x N x 3)`` (N = 1: constant per run), encoder_q ``([B] x N x 3)`` with encoder_t ``(N,)`` shared,
        initial_q/initial_v ``([B] x nv)``. Give either torques (with ``duration``) or
        encoder samples. ``threads=0`` uses all cores.

        ``effects``: flat effect vectors ``([B] x NE)`` (see :mod:`popup.effects`) to vary
        effect parameters across the batch; default the model's own effects.

        A failed run raises its error (``raise_on_error``) or leaves NaN rows with the
        message in ``errors``. ``log``: an MCAP file to stream a single run (B = 1) into.
        """
        replay = encoder_q is not None or encoder_t is not None
        if replay and torque is not None:
            raise InputError("input: give either torque (torque-driven) or encoder_t/encoder_q (replay), not both")
        pay = _as_float_array("payload_kg", self.payload_kg if payload_kg is None else payload_kg, None)
        if pay.ndim > 1 or pay.size == 0:
            raise InputError(f"input payload_kg: expected a scalar or shape (B,) with B >= 1, got shape {pay.shape}")
        pay = pay.reshape(-1)
        sample_rate = _rate(sample_rate)
        pres = _as_float_array("pressure_pa", self.pressure_pa if pressure_pa is None else pressure_pa, None)
        if pres.ndim not in (1, 2) or pres.shape[-1] != 2:
            raise InputError(f"input pressure_pa: expected shape ([B] x 2) (link 1, link 2), got {pres.shape}")
        if replay:
            if encoder_t is None or encoder_q is None:
                raise InputError("input: replay needs both encoder_t (N,) and encoder_q ([B] x N x 3)")
            times = _as_float_array("encoder_t", encoder_t, 1)
            vals = _as_float_array("encoder_q", encoder_q, None)
            if vals.ndim not in (2, 3) or vals.shape[-1] != 3 or vals.shape[-2] != times.shape[0]:
                raise InputError(f"input encoder_q: expected shape ([B] x {times.shape[0]} x 3), got {vals.shape}")
            drive = "replay"
        else:
            if duration is None:
                raise InputError("input duration: a torque-driven run needs a duration [s]")
            duration = _duration(duration)
            tq = np.zeros(3) if torque is None else _as_float_array("torque", torque, None)
            if tq.shape[-1:] != (3,):
                raise InputError(f"input torque: last axis must have 3 motor torques, got shape {tq.shape}")
            if tq.ndim == 1:
                tq = tq[None, :]  # constant torque: (1, 3)
            if tq.ndim == 2:
                tq = tq[None]
            n = tq.shape[1]
            if torque_times is None:
                times = np.arange(n, dtype=np.float64) * self.dt if n > 1 else np.zeros(1)
            else:
                times = _as_float_array("torque_times", torque_times, 1)
            if n == 1:
                times = np.array([0.0, max(float(duration), self.dt)])
                tq = np.repeat(tq, 2, axis=1)
            vals = tq
            drive = "torque"
        nb = max(pay.shape[0], pres.shape[0] if pres.ndim == 2 else 1, vals.shape[0] if vals.ndim == 3 else 1)
        for name, x in (("initial_q", initial_q), ("initial_v", initial_v), ("effects", effects)):
            if x is not None and np.ndim(x) == 2:
                nb = max(nb, np.shape(x)[0])
        pay_b = _tile("payload_kg", pay, nb, 0) if pay.shape[0] > 1 else np.full(nb, pay[0])
        pres_b = _tile("pressure_pa", pres, nb, 1)
        vals_b = _tile("values", vals, nb, 2)
        iq = None if initial_q is None else _tile("initial_q", _as_float_array("initial_q", initial_q, np.ndim(initial_q)), nb, 1)
        iv = None if initial_v is None else _tile("initial_v", _as_float_array("initial_v", initial_v, np.ndim(initial_v)), nb, 1)
        if iv is not None and iq is None:
            raise InputError("input initial_v: given without initial_q")
        fx_b = None if effects is None else np.ascontiguousarray(_tile("effects", np.asarray(effects, dtype=np.float64), nb, 1))
        if not (np.isfinite(sample_rate) and sample_rate > 0):
            raise InputError(f"input sample_rate: {sample_rate} Hz must be finite and > 0")
        log_exp = ""
        if log is not None:
            import tomli_w
            from types import SimpleNamespace

            from .io import sim_experiment

            desc = self.describe()
            desc.update({"payload_kg": float(pay_b[0]), "pressure_pa": pres_b[0], "drive": drive, "sample_rate_hz": float(sample_rate)})
            exp = sim_experiment(SimpleNamespace(params=desc))  # type: ignore[arg-type]
            if not replay:
                exp["description"] += "; torque-driven: replay it with the logged torques, not the encoder"
            log_exp = tomli_w.dumps(exp)
        data, errors, alarms, warns = self._m.rollout(
            np.ascontiguousarray(pay_b),
            np.ascontiguousarray(pres_b),
            drive,
            np.ascontiguousarray(times),
            np.ascontiguousarray(vals_b),
            iq,
            iv,
            None if replay else float(duration),  # type: ignore[arg-type]
            1.0 / float(sample_rate),
            check_threads(threads),
            _flag("check_step", check_step),
            fx_b,
            None if log is None else os.fspath(log),
            log_exp,
        )
        err_msgs: List[Optional[str]] = [None if e is None else e[1] for e in errors]
        _report(errors, warns, _flag("raise_on_error", raise_on_error))
        params = self.describe()
        params.update(
            {
                "payload_kg": pay_b,
                "pressure_pa": pres_b,
                "drive": drive,
                "sample_rate_hz": float(sample_rate),
                "effects": self.effects if fx_b is None else [_effects_dict(row) for row in fx_b],
                "seed": None,
            }
        )
        return BatchResult(
            data=np.asarray(data),
            params=params,
            errors=err_msgs,
            alarms=[[WrinkleAlarm(*a) for a in al] for al in alarms],
            warnings=[list(w) for w in warns],
        )

    # ------------------------------------------------------------ closed loop
    def run_task(
        self,
        task: "Task",
        *,
        duration: float,
        q0: Sequence[float] = (0.0, 0.0, 0.0),
        sample_rate: float = 500.0,
        payload_kg: Optional[float] = None,
        pressure_pa: Optional[Sequence[float]] = None,
        gains: Optional[Mapping[str, Any]] = None,
        effects: Any = None,
        check_step: bool = True,
    ) -> "ControlResult":
        """Run a closed-loop :class:`popup.control.Task` for ``duration`` [s] from rest at
        motor angles ``q0`` [rad] (bending in static equilibrium, drives holding the arm).

        The controller period 1/rate_hz must be a whole multiple of this model's ``dt``
        (build the model with e.g. ``dt=1e-4`` for the default 10 kHz controller). A run that
        goes unstable ends in the ``Unstable`` fault (``status == "unstable"``), not an
        exception; bad tasks, unreachable Cartesian targets and unstable time steps raise.
        """
        b = self.rollout_task(
            task,
            duration=duration,
            q0=np.asarray(q0, dtype=np.float64)[None, :] if np.ndim(q0) == 1 else q0,
            sample_rate=sample_rate,
            payload_kg=payload_kg,
            pressure_pa=pressure_pa,
            gains=None if gains is None else [gains],
            effects=effects,
            threads=1,
            check_step=check_step,
        )
        return b[0]

    def rollout_task(
        self,
        task: "Task",
        *,
        duration: float,
        q0: Any = (0.0, 0.0, 0.0),
        sample_rate: float = 500.0,
        payload_kg: Any = None,
        pressure_pa: Any = None,
        gains: Any = None,
        effects: Any = None,
        threads: int = 0,
        check_step: bool = True,
        raise_on_error: bool = True,
    ) -> "ControlBatch":
        """Batched closed-loop runs of one task in parallel (GIL released), bit-identical to
        one-by-one runs for any ``threads``.

        Swept inputs take a leading batch axis (singletons are tiled): ``payload_kg ([B])``,
        ``pressure_pa ([B] x 2)``, ``q0 ([B] x 3)``, ``effects ([B] x NE)``, and ``gains``:
        a ``(B x NG)`` array in :data:`popup.control.GAIN_NAMES` order or a list of B
        mappings such as ``{"vel_kp": 1000, "damp_kp": 0.04}`` (applied on top of the task's
        controller gains). Gain studies are one call.
        """
        from .control import ControlBatch, Event, gains_to_flat

        text = task.to_toml()
        base, nph = _core.check_control(self._m, text, "<task>")
        pay = _as_float_array("payload_kg", self.payload_kg if payload_kg is None else payload_kg, None).reshape(-1)
        if pay.size == 0:
            raise InputError("input payload_kg: expected a scalar or shape (B,) with B >= 1, got an empty array")
        duration = _duration(duration)
        sample_rate = _rate(sample_rate)
        pres = _as_float_array("pressure_pa", self.pressure_pa if pressure_pa is None else pressure_pa, None)
        if pres.ndim not in (1, 2) or pres.shape[-1] != 2:
            raise InputError(f"input pressure_pa: expected shape ([B] x 2) (link 1, link 2), got {pres.shape}")
        q0a = _as_float_array("q0", q0, None)
        if q0a.ndim not in (1, 2) or q0a.shape[-1] != 3:
            raise InputError(f"input q0: expected shape ([B] x 3) motor angles [rad], got {q0a.shape}")
        if gains is None:
            g = None
        elif isinstance(gains, np.ndarray) and gains.ndim == 2:
            g = np.asarray(gains, dtype=np.float64)
        else:
            g = np.stack([gains_to_flat(x, np.asarray(base)) for x in gains])
        nb = max(pay.shape[0], pres.shape[0] if pres.ndim == 2 else 1, q0a.shape[0] if q0a.ndim == 2 else 1, 1 if g is None else g.shape[0])
        if effects is not None and np.ndim(effects) == 2:
            nb = max(nb, np.shape(effects)[0])
        pay_b = np.full(nb, pay[0]) if pay.shape[0] == 1 else _tile("payload_kg", pay, nb, 0)
        pres_b = _tile("pressure_pa", pres, nb, 1)
        q0_b = _tile("q0", q0a, nb, 1)
        g_b = np.tile(np.asarray(base), (nb, 1)) if g is None else _tile("gains", g, nb, 1)
        fx_b = None if effects is None else np.ascontiguousarray(_tile("effects", np.asarray(effects, dtype=np.float64), nb, 1))
        if not (np.isfinite(sample_rate) and sample_rate > 0):
            raise InputError(f"input sample_rate: {sample_rate} Hz must be finite and > 0")
        data, ctrl, errors, events, status, alarms, warns = _core.closed_loop_rollout(
            self._m,
            text,
            np.ascontiguousarray(pay_b),
            np.ascontiguousarray(pres_b),
            np.ascontiguousarray(q0_b),
            float(duration),
            1.0 / float(sample_rate),
            np.ascontiguousarray(g_b),
            fx_b,
            check_threads(threads),
            _flag("check_step", check_step),
            "<task>",
        )
        _report(errors, warns, _flag("raise_on_error", raise_on_error))
        params = self.describe()
        params.update({"payload_kg": pay_b, "pressure_pa": pres_b, "q0": q0_b, "task": text, "sample_rate_hz": float(sample_rate), "seed": None})
        names = [p.name or p.kind.capitalize() for p in task.phases]
        assert len(names) == nph
        return ControlBatch(
            data=np.asarray(data),
            control=np.asarray(ctrl),
            events=[[Event(*e) for e in ev] for ev in events],
            status=list(status),
            alarms=[[WrinkleAlarm(*a) for a in al] for al in alarms],
            errors=[None if e is None else e[1] for e in errors],
            gains=g_b,
            phase_names=names,
            params=params,
            warnings=[list(w) for w in warns],
        )

