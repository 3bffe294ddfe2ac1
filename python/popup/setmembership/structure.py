"""Model structures (:func:`fir`, :func:`arx`, :func:`oe`): which outputs, inputs and orders."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, List, Sequence, Tuple, Union

import numpy as np

from ..exceptions import InputError, ParameterError


ArrayLike = Any


EpsLike = Union[float, Sequence[float], np.ndarray]


# ============================================================== structures
def as_names(x: Union[str, Sequence[str]], what: str) -> Tuple[str, ...]:
    if isinstance(x, str):
        return (x,)
    out = tuple(str(v) for v in x)
    if not out:
        raise ParameterError(f"{what}: at least one name is needed")
    if len(set(out)) != len(out):
        raise ParameterError(f"{what}: names must be distinct, got {list(out)}")
    return out


def _orders(name: str, v: Union[int, Sequence[int]], m: int, minimum: int) -> Tuple[int, ...]:
    vals: List[Any] = [v] * m if np.ndim(v) == 0 else list(v)  # type: ignore[arg-type]
    if len(vals) != m:
        raise ParameterError(f"{name}: one value per input ({m}) expected, got {len(vals)}: {list(vals)}")
    out = []
    for x in vals:
        try:
            whole = float(x).is_integer()
        except (TypeError, ValueError):
            whole = False
        if isinstance(x, (bool, np.bool_)) or not whole:
            raise ParameterError(f"{name} must be whole numbers, got {x!r}")
        if int(x) < minimum:
            raise ParameterError(f"{name} must be >= {minimum}, got {int(x)}")
        out.append(int(x))
    return tuple(out)


@dataclass(frozen=True)
class Structure:
    """A model structure for one output, MISO.

    ``kind``:

    * ``"fir"``: ``y(t) = Σ_j B_j(q) u_j(t) + c + e(t)``;
    * ``"arx"``: ``A(q) y(t) = Σ_j B_j(q) u_j(t) + c + e(t)`` (equation error);
    * ``"oe"``: ``y(t) = Σ_j B_j(q)/F_j(q) u_j(t) + c + e(t)`` (output error),

    with ``A(q) = 1 + a_1 q⁻¹ + … + a_na q⁻ⁿᵃ``, ``F_j(q) = 1 + f_j1 q⁻¹ + … + f_j,nf q⁻ⁿᶠ``,
    ``B_j(q) = b_j,nk q⁻ⁿᵏ + … + b_j,nk+nb−1 q⁻⁽ⁿᵏ⁺ⁿᵇ⁻¹⁾`` (``nb_j`` coefficients after a
    delay of ``nk_j`` samples) and ``c`` a constant (only with ``offset``).

    Parameter names (:attr:`names`, in this order): ``a1..a{na}`` (ARX), ``f_{input}_{i}``
    (OE, per input), ``b_{input}_{lag}`` (per input, lag = nk..nk+nb−1), ``c``.
    """

    kind: str
    inputs: Tuple[str, ...]
    output: str
    nb: Tuple[int, ...]
    nk: Tuple[int, ...]
    na: int = 0
    nf: Tuple[int, ...] = ()
    offset: bool = False

    @property
    def n_inputs(self) -> int:
        return len(self.inputs)

    @property
    def names(self) -> List[str]:
        """Parameter names, in the order of every parameter vector."""
        out = [f"a{i}" for i in range(1, self.na + 1)]
        for j, u in enumerate(self.inputs):
            for i in range(1, (self.nf[j] if self.nf else 0) + 1):
                out.append(f"f_{u}_{i}")
        for j, u in enumerate(self.inputs):
            out += [f"b_{u}_{self.nk[j] + k}" for k in range(self.nb[j])]
        if self.offset:
            out.append("c")
        return out

    @property
    def n_params(self) -> int:
        return len(self.names)

    @property
    def max_lag(self) -> int:
        """Samples lost at the start by a FIR/ARX regression (the largest lag)."""
        lags = [self.na] + [nk + nb - 1 for nb, nk in zip(self.nb, self.nk) if nb > 0]
        return max(0, *lags)

    def describe(self) -> str:
        """One line, e.g. ``OE(nb=[2,2], nf=[2,2], nk=[0,0]) q2,q3 -> ee_x, offset``."""
        parts = []
        if self.kind == "arx":
            parts.append(f"na={self.na}")
        parts.append(f"nb={list(self.nb)}")
        if self.kind == "oe":
            parts.append(f"nf={list(self.nf)}")
        parts.append(f"nk={list(self.nk)}")
        off = ", offset" if self.offset else ""
        return f"{self.kind.upper()}({', '.join(parts)}) {','.join(self.inputs)} -> {self.output}{off}"

    def split(self, theta: ArrayLike) -> Dict[str, Any]:
        """Named pieces of a parameter vector: ``{"a": (na,), "f": {input: (nf_j,)},
        "b": {input: (nb_j,)}, "c": float}``."""
        th = np.asarray(theta, dtype=float)
        if th.shape != (self.n_params,):
            raise InputError(f"parameter vector of {self.describe()} must have shape ({self.n_params},), got {th.shape}")
        i = 0
        a = th[: self.na]
        i = self.na
        f: Dict[str, np.ndarray] = {}
        if self.kind == "oe":
            for j, u in enumerate(self.inputs):
                f[u] = th[i : i + self.nf[j]]
                i += self.nf[j]
        b: Dict[str, np.ndarray] = {}
        for j, u in enumerate(self.inputs):
            b[u] = th[i : i + self.nb[j]]
            i += self.nb[j]
        c = float(th[i]) if self.offset else 0.0
        return {"a": a, "f": f, "b": b, "c": c}


def fir(nb: Union[int, Sequence[int]], nk: Union[int, Sequence[int]] = 0, *, inputs: Union[str, Sequence[str]] = "u",
        output: str = "y", offset: bool = False) -> Structure:
    """FIR structure ``y(t) = Σ_j B_j(q) u_j(t) + c + e(t)``: ``nb`` coefficients per input
    (int or one per input, >= 0, at least one > 0), delays ``nk`` [samples] (>= 0)."""
    ins = as_names(inputs, "inputs")
    s = Structure("fir", ins, str(output), _orders("nb", nb, len(ins), 0), _orders("nk", nk, len(ins), 0), offset=bool(offset))
    if sum(s.nb) == 0 and not offset:
        raise ParameterError("fir: every nb is 0: the model has no parameter")
    return s


def arx(na: int, nb: Union[int, Sequence[int]], nk: Union[int, Sequence[int]] = 1, *,
        inputs: Union[str, Sequence[str]] = "u", output: str = "y", offset: bool = False) -> Structure:
    """ARX (equation-error) structure ``A(q) y(t) = Σ_j B_j(q) u_j(t) + c + e(t)``: ``na``
    (>= 0) denominator coefficients, ``nb`` (>= 0) numerator coefficients and ``nk`` (>= 0)
    delays [samples] per input. The bound applies to the equation error e."""
    ins = as_names(inputs, "inputs")
    (na_,) = _orders("na", na, 1, 0)
    return Structure("arx", ins, str(output), _orders("nb", nb, len(ins), 0), _orders("nk", nk, len(ins), 0), na=na_, offset=bool(offset))


def oe(nb: Union[int, Sequence[int]], nf: Union[int, Sequence[int]], nk: Union[int, Sequence[int]] = 1, *,
       inputs: Union[str, Sequence[str]] = "u", output: str = "y", offset: bool = True) -> Structure:
    """Output-error structure ``y(t) = Σ_j B_j(q)/F_j(q) u_j(t) + c + e(t)``: per input
    ``nb`` (>= 1) numerator coefficients, ``nf`` (>= 0) denominator coefficients, delay
    ``nk`` (>= 0) [samples]; ``offset`` (default on) adds c. The thesis's G1..G4:
    ``oe(nb=2, nf=2, nk=0, inputs=THESIS_INPUTS, output="ee_x")``."""
    ins = as_names(inputs, "inputs")
    return Structure("oe", ins, str(output), _orders("nb", nb, len(ins), 1), _orders("nk", nk, len(ins), 0),
                     nf=_orders("nf", nf, len(ins), 0), offset=bool(offset))
