"""The effect library (``effects.md``): named physical terms the nominal model leaves out.

Every effect is implemented in the Rust core; this module is its registry at the Python
surface: names, parameters with units, bounds and neutral values, and the conversion
between ``{effect: {param: values}}`` dictionaries and the flat vectors that batched
rollouts take.

>>> import popup
>>> popup.effects.EFFECTS["joint_friction"].params["tau_c"].unit
'N·m'
>>> m = popup.Model("popup-lab").with_effect("joint_friction", tau_c=[1.0, 2.0, 0.5])
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from . import _core
from .exceptions import ParameterError

__all__ = [
    "EffectParam",
    "Effect",
    "EFFECTS",
    "EFFECT_NAMES",
    "NE",
    "neutral_flat",
    "to_flat",
    "from_flat",
    "normalize",
    "OUTPUT_ONLY_IN_REPLAY",
    "acts_only_on",
]

#: What each effect looks like in the residual (``effects.md``), shown with suspects.
SIGNATURES: Dict[str, str] = {
    "joint_friction": "motor torque residual that follows sign(q̇) and q̇",
    "backlash": "end-effector and tip-IMU residual after each velocity reversal of a joint",
    "higher_bending_modes": "residual spectrum peaks above the first bending mode",
    "pressure_leak": "residual that grows with time; bending frequency drifting down",
    "wrinkling": "residual concentrated where |M| approaches M_w; amplitude-dependent frequency",
    "payload_mass": "gravity-loaded torque and sag residual; bending frequency shift",
    "sensor_delay": "residual–input cross-correlation peak at a positive lag",
    "actuator_saturation": "residual only while the command is at its limit",
    "air_drag": "damping residual growing with tip speed squared",
    "torsion": "lateral residual when the arm moves out of plane",
}

DESCRIPTIONS: Dict[str, str] = {
    "joint_friction": "Coulomb + viscous (optionally Stribeck) friction in each motoreducer",
    "backlash": "dead zone between the motor-side encoder and the link side of each motor joint",
    "higher_bending_modes": "more flexibility inside a link than one universal joint gives (multi-segment PRBM)",
    "pressure_leak": "inflation pressure decaying during the run, so k(p), c(p) and M_w drift",
    "wrinkling": "bending stiffness dropping once the bending moment passes the wrinkling moment",
    "payload_mass": "the true payload differs from the declared one",
    "sensor_delay": "a measured channel lags the physics",
    "actuator_saturation": "the motoreducer cannot deliver more than a torque limit",
    "air_drag": "quadratic aerodynamic drag on the inflated links",
    "torsion": "torsional compliance of each link about its own axis",
}


@dataclass(frozen=True)
class EffectParam:
    """One parameter of an effect: ``length`` values (3 per motor joint, 2 per link, 1)."""

    effect: str
    name: str
    unit: str
    length: int
    neutral: float
    lower: float
    upper: float
    fit: bool
    integer: bool
    doc: str
    offset: int

    @property
    def slice(self) -> slice:
        """Where this parameter sits in the flat effect vector."""
        return slice(self.offset, self.offset + self.length)


@dataclass(frozen=True)
class Effect:
    """An effect of the library: name, description, residual signature and parameters."""

    name: str
    description: str
    signature: str
    params: Dict[str, EffectParam] = field(default_factory=dict)

    @property
    def fit_params(self) -> List[EffectParam]:
        """Parameters fitted when the effect is diagnosed."""
        return [p for p in self.params.values() if p.fit]


def _build() -> Tuple[Dict[str, Effect], int]:
    effects: Dict[str, Effect] = {n: Effect(n, DESCRIPTIONS.get(n, ""), SIGNATURES.get(n, ""), {}) for n in _core.EFFECT_NAMES}
    off = 0
    for eff, name, unit, n, neutral, lo, hi, fit, integer, doc in _core.effect_registry():
        effects[eff].params[name] = EffectParam(eff, name, unit, n, neutral, lo, hi, fit, integer, doc, off)
        off += n
    return effects, off


EFFECTS, NE = _build()
#: Effect names in library order.
EFFECT_NAMES: List[str] = list(EFFECTS)


def neutral_flat() -> np.ndarray:
    """The flat vector of the nominal model (every effect neutral)."""
    v = np.zeros(NE)
    for e in EFFECTS.values():
        for p in e.params.values():
            v[p.slice] = p.neutral
    return v


def _values(p: EffectParam, value: Any) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if a.ndim == 0:
        a = np.full(p.length, float(a))
    if a.shape != (p.length,):
        raise ParameterError(f"invalid parameter {p.effect}.{p.name}: expected a number or {p.length} values, got shape {a.shape}")
    for i, x in enumerate(a):
        key = f"{p.effect}.{p.name}" + (f"[{i}]" if p.length > 1 else "")
        if np.isnan(x) or x < p.lower or x > p.upper:
            raise ParameterError(f"invalid parameter {key} = {x}: must be within [{p.lower}, {p.upper}] {p.unit}")
        if p.integer and float(x) != int(x):
            raise ParameterError(f"invalid parameter {key} = {x}: must be a whole number")
    return a


def normalize(effect: str, params: Mapping[str, Any]) -> Dict[str, np.ndarray]:
    """Check an effect name and its parameters; broadcast scalars to per-joint/per-link
    arrays. Raises :class:`ParameterError` naming the effect, parameter and bound."""
    if effect not in EFFECTS:
        raise ParameterError(f"invalid parameter effect = {effect!r}: must be one of {', '.join(EFFECT_NAMES)}")
    e = EFFECTS[effect]
    out = {}
    for k, v in params.items():
        if k not in e.params:
            raise ParameterError(f"invalid parameter {effect}.{k}: {effect} has parameters {', '.join(e.params)}")
        out[k] = _values(e.params[k], v)
    return out


def to_flat(effects: Mapping[str, Mapping[str, Any]], base: Optional[np.ndarray] = None) -> np.ndarray:
    """Flat vector from ``{effect: {param: values}}`` on top of ``base`` (default neutral)."""
    v = neutral_flat() if base is None else np.array(base, dtype=np.float64)
    for eff, params in effects.items():
        for k, a in normalize(eff, params).items():
            v[EFFECTS[eff].params[k].slice] = a
    return v


def from_flat(v: Any, *, only_active: bool = True) -> Dict[str, Dict[str, List[float]]]:
    """``{effect: {param: values}}`` from a flat vector (only non-neutral effects by default)."""
    v = np.asarray(v, dtype=np.float64)
    if v.shape != (NE,):
        raise ParameterError(f"invalid parameter effects: expected a flat vector of {NE} values, got shape {v.shape}")
    out: Dict[str, Dict[str, List[float]]] = {}
    for e in EFFECTS.values():
        d = {k: [float(x) for x in v[p.slice]] for k, p in e.params.items()}
        if not only_active or not is_neutral(e.name, v):
            out[e.name] = d
    return out


#: parameters that only shape an effect (neutral while its strength is), from the core
_SHAPING = frozenset(_core.effect_shaping())


def is_neutral(effect: str, v: Any) -> bool:
    """True when ``effect`` changes nothing in flat vector ``v`` (as the core decides)."""
    v = np.asarray(v, dtype=np.float64)
    for p in EFFECTS[effect].params.values():
        if (p.effect, p.name) in _SHAPING:
            continue
        if not np.all(v[p.slice] == p.neutral):
            return False
    return True


def active(v: Any) -> List[str]:
    """Names of the effects that are switched on in flat vector ``v``."""
    return [n for n in EFFECT_NAMES if not is_neutral(n, v)]


#: ``(effect, parameter or "*", channel prefix)``: parameters that act on the sensor rows
#: only in encoder replay, never on the motion (the friction and clamp of the motor torque
#: read, the delays of the groups read from the physics), from the core.
OUTPUT_ONLY_IN_REPLAY: Tuple[Tuple[str, str, str], ...] = tuple(_core.effect_output_only())


def acts_only_on(effect: str, names: Sequence[str], channels: Sequence[str]) -> Optional[List[str]]:
    """The ``channels`` that ``effect``'s parameters ``names`` act on in encoder replay when
    each of them acts on the sensor rows only (:data:`OUTPUT_ONLY_IN_REPLAY`), else ``None``
    (one of them moves the arm, so it may act on every channel)."""
    prefixes = set()
    for n in names:
        hit = [pre for e, k, pre in OUTPUT_ONLY_IN_REPLAY if e == effect and k in ("*", n)]
        if not hit:
            return None
        prefixes.update(hit)
    if not prefixes:
        return None
    return [c for c in channels if any(c.startswith(pre) for pre in prefixes)]
