"""Set-membership identification: parameter uncertainty intervals (PUI) under bounded
noise, solved as linear programs with HiGHS.

::

    import popup
    from popup import setmembership as sm

    run = popup.read_run("examples/data/lab_run")            # or a SimResult
    s = sm.arx(na=2, nb=2, nk=0, inputs=["q2", "dq2", "q3", "dq3"], output="ee_x", offset=True)
    r = sm.pui(run, s, eps=0.005)                            # |e(t)| <= 5 mm
    r.to_pandas()            # lower, upper, width, center (Chebyshev), minimax, per parameter
    r.plot()                 # intervals as error bars

    s = sm.oe(nb=2, nf=2, nk=0, inputs=["q2", "dq2", "q3", "dq3"], output="ee_x")
    r = sm.oe_pui(run, s, eps=0.005)                         # the thesis's output-error problem

Linear in the parameters (FIR, ARX) — exact
-------------------------------------------
For a model ``y(t) = φ(t)ᵀθ + e(t)`` with ``|e(t)| <= ε`` the feasible parameter set is
the polytope ``FPS = {θ : |y(t) − φ(t)ᵀθ| <= ε, t = 1..N}`` (2N linear inequalities).
Its tightest axis-aligned box, the *parameter uncertainty intervals*, is
``[min θ_i, max θ_i]`` over the FPS: 2p linear programs, solved by HiGHS
(:func:`scipy.optimize.linprog`, ``method="highs"``, the constraint matrix as a
``scipy.sparse`` CSR matrix), in a thread pool (HiGHS releases the GIL). The intervals
are exact to HiGHS's feasibility tolerance (1e-7 of ε on every constraint): every θ that
explains the data within ε lies in them, and every end point is attained by such a θ
(:attr:`PUIResult.witnesses`). Numerics: rows are divided by ε, columns by their largest
magnitude, the variables are re-parameterised so that the constraint matrix has
orthonormal columns (Cholesky QR twice; an ARX on a slowly varying output has cond(Φ) ~
1e7) and shifted to the least-squares fit; all exact changes of variables. Two more LPs:

* the *minimal bound* ``ε_min = min_θ max_t |y(t) − φ(t)ᵀθ|`` (the L∞ / minimax fit;
  its minimiser is :attr:`PUIResult.minimax`). The FPS is empty iff ``ε < ε_min``: then
  :class:`InfeasibleError` says so and gives ``ε_min``;
* the *Chebyshev centre* (centre of the largest ball inside the FPS) as the central
  estimate. The ball is taken in the metric of the regressors, ``‖Φ(θ − θ')/ε‖₂``: free
  of the parameters' units and of any re-parameterisation, and round even when the
  regressors are nearly collinear (where a Euclidean ball in θ would be squeezed to
  nothing by the thinnest direction and its centre would not be central). Every θ with
  ``‖Φ(θ − center)‖₂ <= radius·ε`` is feasible. (Numerically rank-deficient Φ: the
  parameters scaled by their interval half-widths instead; :attr:`PUIResult.center_metric`.)
  The per-coordinate midpoint of the intervals (:attr:`PUIResult.midpoint`) is the
  other classical central estimate (optimal in the worst case per parameter, but not
  always inside the FPS).

Output error (OE) — an approximation, stated
--------------------------------------------
``y(t) = Σ_j B_j(q)/F_j(q) u_j(t) + c + e(t)``, ``|e(t)| <= ε`` is bilinear in the
denominators ``F_j`` and the numerators ``B_j`` (the thesis's problem: second-order
G1..G4 from q2, q̇2, q3, q̇3 to the end-effector x, ε = 5 mm). :func:`oe_pui` does:

1. *Start*: the equation-error (ARX, common denominator A of order max nf) minimax fit;
   ``F_j = A`` for every input, roots reflected inside the unit circle.
2. *Denominator*: sequential linear programming on the true output error. With the
   output linearised in the denominator coefficients (it is exactly linear in the
   numerators and c), one LP gives the minimax step within a trust region; it is kept
   only if the true simulated output error ``max_t |y − ŷ|`` falls (and the ``F_j``
   stay stable). This converges to a *local* minimiser F̂ of
   ``ε_min(F) = min_{B,c} max_t |y − ŷ(F, B, c)|``.
3. *Numerator given F̂* (exact, conditional): with F̂ fixed the model is linear in
   (B, c); its PUI is exact LPs (:attr:`PUIResult.conditional`). It contains the true
   numerator whenever F̂ is the true denominator.
4. *Joint intervals* (first-order): the PUI of the FPS of the model linearised in F
   around F̂ (exact in B and c), with the prior that every F_j is stable (so
   ``|f_ji| <= C(nf_j, i)``, a binomial coefficient). Not guaranteed to contain the
   exact OE-PUI (the exact FPS is not convex); every interval reported is widened to
   contain the conditional intervals and, with ``sweep=M``, every point verified
   feasible in a sweep of denominators: those of the 2p first-order end points and M
   random convex combinations of them, each checked by an exact LP (``ε_min(F) <= ε``)
   and its numerator bounded by exact LPs. The sweep's hull is an *inner*
   approximation of the exact OE-PUI (:attr:`PUIResult.sweep`).

Conventions for OE: the run starts at rest, so the inputs enter as deviations from their
first sample, the filters start from zero, and ``c`` absorbs the output's rest value.
``ε_min`` reported for OE is ``ε_min(F̂)``: an upper bound on the exact OE minimal bound.

Data come from a :class:`~popup.MeasuredRun` (a missing rate channel ``dqN`` is derived
from ``qN`` by central differences, noted), a :class:`~popup.SimResult`, a DataFrame, or
arrays ``(y, u)``. Samples must be uniform in time. Units are those of the channels
(:data:`popup.UNITS`); ε is in the output's unit.
"""

from __future__ import annotations

import math
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog
from scipy.signal import lfilter

from .exceptions import ConvergenceError, InputError, ParameterError, PopupError

__all__ = [
    "Structure",
    "fir",
    "arx",
    "oe",
    "IdData",
    "iddata",
    "Regression",
    "regressors",
    "PUIResult",
    "InfeasibleError",
    "pui_linear",
    "pui",
    "oe_pui",
    "identify",
    "min_bound",
    "simulate",
    "multisine",
    "THESIS_INPUTS",
    "LAB_POSE",
]

#: The thesis's inputs (chapter 3): motor angles and rates of joints 2 and 3.
THESIS_INPUTS: Tuple[str, ...] = ("q2", "dq2", "q3", "dq3")
#: The pose about which :func:`multisine` moves the arm [rad] (that of
#: :func:`popup.synth.lab_trajectory`).
LAB_POSE: Tuple[float, float, float] = (0.0, -math.pi / 2 + 0.6, 0.5)

ArrayLike = Any
EpsLike = Union[float, Sequence[float], np.ndarray]


class InfeasibleError(PopupError, ValueError):
    """The feasible parameter set is empty: no parameter vector of the model structure
    explains the data within the noise bound. Either the bound is too small or the model
    class is wrong.

    Attributes
    ----------
    eps : float
        The bound given (largest value if per-sample) [output unit].
    eps_min : float
        The smallest bound for which the set is not empty (for OE: with the estimated
        denominator, an upper bound on the exact one) [output unit].
    structure : str
        The model structure.
    n : int
        Number of constraints' samples.
    minimax : ndarray
        The parameter vector achieving ``eps_min``.
    """

    def __init__(self, eps: float, eps_min: float, structure: str, n: int, minimax: np.ndarray,
                 unit: str = "", detail: str = "") -> None:
        self.eps = float(eps)
        self.eps_min = float(eps_min)
        self.structure = structure
        self.n = int(n)
        self.minimax = np.asarray(minimax, dtype=float)
        u = f" {unit}" if unit else ""
        ratio = self.eps_min / self.eps if self.eps > 0 else math.inf
        msg = (
            f"infeasible: no parameter vector of {structure} explains the {n} samples within "
            f"|e(t)| <= eps = {self.eps:.6g}{u}. The smallest bound this model class achieves is "
            f"eps_min = {self.eps_min:.6g}{u} ({ratio:.3g} x the bound given). Either the noise bound is too "
            f"small for the model structure or the model class is wrong (orders, delays, inputs, "
            f"nonlinearity): use eps >= {self.eps_min:.6g}{u} or change the structure."
        )
        if detail:
            msg += " " + detail
        self._args = (eps, eps_min, structure, n, self.minimax, unit, detail)
        super().__init__(msg)

    def __reduce__(self) -> Tuple[Any, ...]:  # picklable (process pools)
        return (type(self), self._args)


# ============================================================== structures
def _names(x: Union[str, Sequence[str]], what: str) -> Tuple[str, ...]:
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
    ins = _names(inputs, "inputs")
    s = Structure("fir", ins, str(output), _orders("nb", nb, len(ins), 0), _orders("nk", nk, len(ins), 0), offset=bool(offset))
    if sum(s.nb) == 0 and not offset:
        raise ParameterError("fir: every nb is 0: the model has no parameter")
    return s


def arx(na: int, nb: Union[int, Sequence[int]], nk: Union[int, Sequence[int]] = 1, *,
        inputs: Union[str, Sequence[str]] = "u", output: str = "y", offset: bool = False) -> Structure:
    """ARX (equation-error) structure ``A(q) y(t) = Σ_j B_j(q) u_j(t) + c + e(t)``: ``na``
    (>= 0) denominator coefficients, ``nb`` (>= 0) numerator coefficients and ``nk`` (>= 0)
    delays [samples] per input. The bound applies to the equation error e."""
    ins = _names(inputs, "inputs")
    (na_,) = _orders("na", na, 1, 0)
    return Structure("arx", ins, str(output), _orders("nb", nb, len(ins), 0), _orders("nk", nk, len(ins), 0), na=na_, offset=bool(offset))


def oe(nb: Union[int, Sequence[int]], nf: Union[int, Sequence[int]], nk: Union[int, Sequence[int]] = 1, *,
       inputs: Union[str, Sequence[str]] = "u", output: str = "y", offset: bool = True) -> Structure:
    """Output-error structure ``y(t) = Σ_j B_j(q)/F_j(q) u_j(t) + c + e(t)``: per input
    ``nb`` (>= 1) numerator coefficients, ``nf`` (>= 0) denominator coefficients, delay
    ``nk`` (>= 0) [samples]; ``offset`` (default on) adds c. The thesis's G1..G4:
    ``oe(nb=2, nf=2, nk=0, inputs=THESIS_INPUTS, output="ee_x")``."""
    ins = _names(inputs, "inputs")
    return Structure("oe", ins, str(output), _orders("nb", nb, len(ins), 1), _orders("nk", nk, len(ins), 0),
                     nf=_orders("nf", nf, len(ins), 0), offset=bool(offset))


# ============================================================== data
@dataclass
class IdData:
    """Identification data: one output and its inputs, uniformly sampled.

    Attributes
    ----------
    y : ndarray (N,)
        Output samples [output unit].
    u : ndarray (N, m)
        Input samples, one column per input [input units].
    output : str
    inputs : tuple of str
    dt : float
        Sample period [s] (NaN when unknown).
    t0 : float
        Time of the first sample [s].
    source : str
        Where the data came from.
    notes : list of str
        What was done to the data (derived rates, window, decimation).
    """

    y: np.ndarray
    u: np.ndarray
    output: str
    inputs: Tuple[str, ...]
    dt: float = math.nan
    t0: float = 0.0
    source: str = "arrays"
    notes: List[str] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.y.shape[0])


def _check_finite(name: str, x: np.ndarray, dt: float, t0: float) -> None:
    bad = ~np.isfinite(x)
    if bad.any():
        i = int(np.argmax(bad))
        when = f" (t = {t0 + i * dt:.6g} s)" if math.isfinite(dt) else ""
        raise InputError(
            f"channel {name!r} has {int(bad.sum())} non-finite value(s) (NaN/inf), the first at sample {i}{when}; "
            f"the regressors need every sample of a contiguous window: choose a window without gaps (t_start/t_stop)"
        )


def _as_data(y: ArrayLike, u: ArrayLike, output: str, inputs: Sequence[str], dt: float = math.nan, t0: float = 0.0,
             source: str = "arrays", notes: Optional[List[str]] = None) -> IdData:
    try:
        yy = np.asarray(y, dtype=np.float64)
        uu = np.asarray(u, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InputError(f"y and u must be numeric arrays: {e}") from None
    if yy.ndim != 1:
        raise InputError(f"y ({output}) must be 1-D (N,), got shape {yy.shape}")
    if uu.ndim == 1:
        uu = uu[:, None]
    if uu.ndim != 2:
        raise InputError(f"u must be (N,) or (N, m), got shape {uu.shape}")
    if uu.shape[0] != yy.shape[0]:
        raise InputError(f"mismatched lengths: y ({output}) has {yy.shape[0]} samples, u has {uu.shape[0]}")
    if uu.shape[1] != len(inputs):
        raise InputError(f"u has {uu.shape[1]} column(s) but the structure has {len(inputs)} input(s) {list(inputs)}")
    _check_finite(output, yy, dt, t0)
    for j, nm in enumerate(inputs):
        _check_finite(nm, uu[:, j], dt, t0)
    return IdData(yy.copy(), np.ascontiguousarray(uu), str(output), tuple(inputs), float(dt), float(t0), source, list(notes or []))


def iddata(source: Any, output: str = "ee_x", inputs: Union[str, Sequence[str]] = THESIS_INPUTS, *,
           t_start: Optional[float] = None, t_stop: Optional[float] = None, step: int = 1,
           derive_rates: bool = True) -> IdData:
    """Identification data from a run.

    Parameters
    ----------
    source : MeasuredRun, SimResult, pandas.DataFrame, mapping of arrays, or IdData
        A run (measured-run channel names, :data:`popup.CHANNELS`), a DataFrame with a
        ``t`` column or index, or a mapping ``{"t": ..., name: ...}``.
    output, inputs : str
        Channel names, e.g. ``"ee_x"`` from ``("q2", "dq2", "q3", "dq3")``.
    t_start, t_stop : float, optional
        Time window [s] (inclusive).
    step : int
        Keep every ``step``-th sample (plain decimation, no anti-alias filter).
    derive_rates : bool
        A rate channel ``dqN`` missing from the source (measured runs have none) is
        computed from ``qN`` by central differences (:func:`numpy.gradient`); noted.

    Raises :class:`~popup.InputError` for a missing channel, non-finite samples in the
    window, non-uniform sampling, or fewer than 2 samples.
    """
    ins = _names(inputs, "inputs")
    if isinstance(step, bool) or not float(step).is_integer() or int(step) < 1:
        raise ParameterError(f"step must be a whole number >= 1, got {step!r}")
    step = int(step)
    notes: List[str] = []
    if isinstance(source, IdData):
        if source.output != output or source.inputs != ins:
            raise InputError(f"IdData has {source.inputs} -> {source.output!r}, asked for {ins} -> {output!r}")
        t = source.t0 + np.arange(len(source)) * (source.dt if math.isfinite(source.dt) else 1.0)
        cols = {output: source.y, **{n: source.u[:, j] for j, n in enumerate(ins)}}
        name = source.source
        notes += source.notes
    else:
        getter, have, t, name = _channel_getter(source)
        cols = {}
        for ch in (output, *ins):
            if ch in have:
                cols[ch] = getter(ch)
            elif derive_rates and ch.startswith("dq") and ch[1:] in have:
                cols[ch] = np.gradient(getter(ch[1:]), t)
                notes.append(f"{ch} derived from {ch[1:]} by central differences")
            else:
                raise InputError(f"{name}: no channel {ch!r}; it has {sorted(have)}")
    t = np.asarray(t, dtype=np.float64)
    keep = np.ones(t.shape[0], dtype=bool)
    if t_start is not None:
        keep &= t >= t_start
    if t_stop is not None:
        keep &= t <= t_stop
    idx = np.flatnonzero(keep)[::step]
    if t_start is not None or t_stop is not None:
        notes.append(f"window t = [{t[idx[0]] if idx.size else math.nan:.6g}, {t[idx[-1]] if idx.size else math.nan:.6g}] s")
    if step > 1:
        notes.append(f"decimated by {step} (no anti-alias filter)")
    if idx.size < 2:
        raise InputError(f"{name}: {idx.size} sample(s) in the window; at least 2 are needed")
    tt = t[idx]
    d = np.diff(tt)
    dt = float(np.mean(d))
    if not np.all(np.isfinite(d)) or dt <= 0 or np.max(np.abs(d - dt)) > 1e-6 * max(dt, 1e-12) + 1e-9:
        raise InputError(f"{name}: samples are not uniform in time (dt from {np.min(d):.6g} to {np.max(d):.6g} s); "
                         f"set-membership regressors need a fixed sample period")
    y = np.asarray(cols[output], dtype=float)[idx]
    u = np.column_stack([np.asarray(cols[n], dtype=float)[idx] for n in ins])
    return _as_data(y, u, output, ins, dt, float(tt[0]), name, notes)


def _channel_getter(source: Any) -> Tuple[Callable[[str], np.ndarray], set, np.ndarray, str]:
    from .io import MeasuredRun
    from .results import SimResult

    if isinstance(source, MeasuredRun):
        return source.channel, set(source.columns), source.time, f"measured run {source.source}"
    if isinstance(source, SimResult):
        return source.channel, set(source.channels), source.time, "simulated run"
    try:
        import pandas as pd

        if isinstance(source, pd.DataFrame):
            df = source if "t" in source.columns else source.reset_index()
            if "t" not in df.columns:
                raise InputError("DataFrame needs a 't' column or index [s]")
            return (lambda c: df[c].to_numpy(dtype=float)), set(map(str, df.columns)), df["t"].to_numpy(dtype=float), "DataFrame"
    except ImportError:  # pragma: no cover
        pass
    if isinstance(source, Mapping):
        if "t" not in source:
            raise InputError("a mapping of arrays needs 't' [s]")
        return (lambda c: np.asarray(source[c], dtype=float)), set(map(str, source.keys())), np.asarray(source["t"], dtype=float), "arrays"
    raise InputError(f"cannot take identification data from {type(source).__name__}: give a MeasuredRun, SimResult, "
                     f"DataFrame, mapping, IdData or a tuple (y, u)")


def _resolve(data: Any, s: Structure, **kw: Any) -> IdData:
    if isinstance(data, tuple) and len(data) == 2:
        if kw:
            raise InputError(f"{sorted(kw)} apply to runs, not to (y, u) arrays")
        return _as_data(data[0], data[1], s.output, s.inputs)
    return iddata(data, s.output, s.inputs, **kw)


# ============================================================== regressors
@dataclass
class Regression:
    """A linear regression ``y = Φ θ + e`` (one row per sample kept).

    Attributes
    ----------
    phi : ndarray (n, p)
    y : ndarray (n,)
    names : list of str
        Parameter names (columns of ``phi``).
    rows : ndarray (n,) of int
        Sample index of every row in the data.
    """

    phi: np.ndarray
    y: np.ndarray
    names: List[str]
    rows: np.ndarray


def _shift(x: np.ndarray, lag: int) -> np.ndarray:
    """x(t − lag) with zeros before the start (rest), same length."""
    if lag == 0:
        return x
    out = np.zeros_like(x)
    if lag < x.shape[0]:
        out[lag:] = x[: x.shape[0] - lag]
    return out


def regressors(structure: Structure, y: ArrayLike, u: ArrayLike, *, skip: int = 0) -> Regression:
    """The regression of a FIR or ARX structure: row ``t`` is ``φ(t) = [−y(t−1) … −y(t−na),
    u_j(t−nk_j) … u_j(t−nk_j−nb_j+1) per input, 1]``, for ``t = max_lag + skip … N−1``
    (the first :attr:`Structure.max_lag` samples have no complete past). Built with one
    vectorised slice per column.

    Raises :class:`~popup.InputError` for mismatched lengths, non-finite samples, the wrong
    number of inputs, or fewer usable samples than parameters.
    """
    s = structure
    if s.kind not in ("fir", "arx"):
        raise ParameterError(f"regressors: {s.kind.upper()} is not linear in its parameters; use oe_pui()")
    d = y if isinstance(y, IdData) else _as_data(y, u, s.output, s.inputs)
    return _regression(s, d.y, d.u, skip)


def _regression(s: Structure, y: np.ndarray, u: np.ndarray, skip: int) -> Regression:
    if isinstance(skip, bool) or not float(skip).is_integer() or skip < 0:
        raise ParameterError(f"skip must be a whole number >= 0, got {skip!r}")
    n_all = y.shape[0]
    t0 = s.max_lag + int(skip)
    n = n_all - t0
    p = s.n_params
    if n < max(p, 1):
        raise InputError(f"too few samples for {s.describe()}: {n_all} given, {t0} lost to the lags/skip, "
                         f"{max(n, 0)} rows left for {p} parameters (need at least {p + t0} samples)")
    phi = np.empty((n, p))
    col = 0
    for i in range(1, s.na + 1):
        phi[:, col] = -y[t0 - i : n_all - i]
        col += 1
    for j in range(s.n_inputs):
        for k in range(s.nb[j]):
            lag = s.nk[j] + k
            phi[:, col] = u[t0 - lag : n_all - lag, j]
            col += 1
    if s.offset:
        phi[:, col] = 1.0
    return Regression(phi, y[t0:].copy(), s.names, np.arange(t0, n_all))


# ============================================================== results
@dataclass
class PUIResult:
    """Parameter uncertainty intervals of one identification.

    Attributes
    ----------
    names : list of str
        Parameter names (:attr:`Structure.names`).
    lower, upper : ndarray (p,)
        Interval bounds [parameter units] (±inf: unbounded by the data).
    center : ndarray (p,)
        Chebyshev centre of the feasible set: the centre of the largest ball inside it,
        in the metric :attr:`center_metric`.
    radius : float
        Radius of that ball: with ``"regressors"``, every θ with ``‖Φ(θ − center)‖₂ <=
        radius·ε`` is feasible; with ``"half-widths"``, every θ with ``‖(θ − center)/h‖₂
        <= radius`` (h: the interval half-widths). NaN if its LP failed (centre = minimax).
    minimax : ndarray (p,)
        The minimax (L∞) estimate, the parameter vector achieving :attr:`eps_min`.
    eps : float or ndarray
        The noise bound [output unit].
    eps_min : float
        Smallest bound with a non-empty feasible set (OE: with the estimated denominator).
    n : int
        Number of samples in the constraints (2n inequalities).
    n_data : int
        Samples given.
    structure : Structure or None
    method : str
        What was solved.
    approximation : str
        "" when the intervals are exact; otherwise what is approximate.
    solve_time : float
        Wall time of the identification [s].
    lp_times : ndarray
        Wall time of every LP [s].
    threads : int
        Worker threads for the LPs.
    dt : float
        Sample period [s] (NaN when unknown).
    unit : str
        Unit of the output (and of eps).
    notes : list of str
    conditional : PUIResult or None
        OE: the exact intervals of the numerators and c given the estimated denominators.
    denominators : dict or None
        OE: ``{input: [1, f_1, …]}`` of F̂.
    iterations : list of dict
        OE: the denominator iterations (output-error bound, trust region, accepted).
    sweep : dict or None
        OE with ``sweep=M``: ``{"drawn", "stable", "feasible", "lower", "upper"}`` (the
        hull of verified feasible points).
    center_metric : str
        ``"regressors"`` (the metric ``‖Φ(θ − θ')/ε‖₂``, used whenever Φ has full
        numerical rank) or ``"half-widths"`` (the parameters scaled by their interval
        half-widths).
    witnesses : ndarray (2p, p) or None
        A parameter vector attaining each bound: row ``2i`` attains ``lower[i]``, row
        ``2i+1`` ``upper[i]`` (NaN where unbounded). For OE, those of the first-order set.
    """

    names: List[str]
    lower: np.ndarray
    upper: np.ndarray
    center: np.ndarray
    radius: float
    minimax: np.ndarray
    eps: Union[float, np.ndarray]
    eps_min: float
    n: int
    n_data: int
    structure: Optional[Structure]
    method: str
    approximation: str = ""
    solve_time: float = 0.0
    lp_times: np.ndarray = field(default_factory=lambda: np.zeros(0))
    threads: int = 1
    dt: float = math.nan
    unit: str = ""
    notes: List[str] = field(default_factory=list)
    conditional: Optional["PUIResult"] = None
    denominators: Optional[Dict[str, np.ndarray]] = None
    iterations: List[Dict[str, Any]] = field(default_factory=list)
    sweep: Optional[Dict[str, Any]] = None
    witnesses: Optional[np.ndarray] = None
    center_metric: str = "regressors"

    @property
    def n_lp(self) -> int:
        """Number of LPs solved."""
        return int(self.lp_times.shape[0])

    @property
    def width(self) -> np.ndarray:
        """upper − lower, (p,)."""
        return self.upper - self.lower

    @property
    def midpoint(self) -> np.ndarray:
        """(lower + upper)/2, (p,)."""
        return 0.5 * (self.lower + self.upper)

    @property
    def intervals(self) -> Dict[str, Tuple[float, float]]:
        """``{name: (lower, upper)}``."""
        return {n: (float(a), float(b)) for n, a, b in zip(self.names, self.lower, self.upper)}

    @property
    def exact(self) -> bool:
        """True when the intervals are exact LP bounds of the stated model (FIR/ARX or OE
        with given denominators)."""
        return not self.approximation

    def __getitem__(self, name: str) -> Tuple[float, float]:
        return self.intervals[name]

    def contains(self, theta: ArrayLike, *, tol: float = 1e-9) -> np.ndarray:
        """Per parameter: ``lower − tol·scale <= θ_i <= upper + tol·scale`` (scale =
        max(1, |θ_i|)), (p,) bool."""
        th = np.asarray(theta, dtype=float)
        if th.shape != self.lower.shape:
            raise InputError(f"theta must have shape {self.lower.shape}, got {th.shape}")
        sc = tol * np.maximum(1.0, np.abs(th))
        return (th >= self.lower - sc) & (th <= self.upper + sc)

    def to_pandas(self, truth: Optional[ArrayLike] = None) -> Any:
        """A DataFrame indexed by parameter: ``lower upper width center minimax`` (and
        ``truth inside`` when ``truth`` is given; OE: ``cond_lower cond_upper``)."""
        import pandas as pd

        df = pd.DataFrame({"lower": self.lower, "upper": self.upper, "width": self.width,
                           "center": self.center, "minimax": self.minimax}, index=pd.Index(self.names, name="parameter"))
        if self.conditional is not None:
            cl = pd.Series(self.conditional.lower, index=self.conditional.names)
            cu = pd.Series(self.conditional.upper, index=self.conditional.names)
            df["cond_lower"] = cl.reindex(df.index)
            df["cond_upper"] = cu.reindex(df.index)
        if truth is not None:
            df["truth"] = np.asarray(truth, dtype=float)
            df["inside"] = self.contains(truth)
        df.attrs.update({"structure": self.structure.describe() if self.structure else "", "eps": self.eps,
                         "eps_min": self.eps_min, "n": self.n, "radius": self.radius, "solve_time_s": self.solve_time,
                         "method": self.method, "approximation": self.approximation, "unit": self.unit})
        return df

    def summary(self) -> str:
        """A few lines: structure, bound, N, time, and the intervals."""
        eps = float(np.max(self.eps))
        lines = [
            f"{self.structure.describe() if self.structure else 'linear regression'}: {self.n} samples, "
            f"eps = {eps:.6g} {self.unit} (eps_min = {self.eps_min:.6g}), {self.n_lp} LPs in {self.solve_time:.3g} s "
            f"({self.threads} thread(s)); Chebyshev radius {self.radius:.3g}",
            f"method: {self.method}",
        ]
        if self.approximation:
            lines.append(f"approximation: {self.approximation}")
        w = max(len(n) for n in self.names)
        for n, lo, hi, c in zip(self.names, self.lower, self.upper, self.center):
            lines.append(f"  {n:<{w}}  [{lo: .6g}, {hi: .6g}]  centre {c: .6g}")
        return "\n".join(lines)

    def __repr__(self) -> str:
        st = self.structure.describe() if self.structure else "linear regression"
        return (f"PUIResult({st}, n={self.n}, eps={float(np.max(self.eps)):.4g}, eps_min={self.eps_min:.4g}, "
                f"params={len(self.names)}, exact={self.exact}, solve_time={self.solve_time:.3g}s)")

    def plot(self, truth: Optional[ArrayLike] = None, *, ax: Any = None, ncols: int = 6) -> Any:
        """One small panel per parameter (their scales differ by orders of magnitude):
        the interval as an error bar around the Chebyshev centre, the minimax estimate
        (open circle), ``truth`` (red cross) when given, and for OE the exact numerator
        interval given F̂ (grey bar, right). ``ax``: p axes to draw into. Returns the
        figure."""
        from .plot import pyplot

        plt = pyplot()
        p = len(self.names)
        if ax is None:
            nc = max(1, min(int(ncols), p))
            nr = int(math.ceil(p / nc))
            fig, axes = plt.subplots(nr, nc, figsize=(2.1 * nc, 2.0 * nr + 0.6), squeeze=False)
            axes = list(axes.ravel())
            for a in axes[p:]:
                a.set_visible(False)
        else:
            axes = list(np.atleast_1d(ax).ravel())
            if len(axes) < p:
                raise InputError(f"plot needs {p} axes (one per parameter), got {len(axes)}")
            fig = axes[0].figure
        tr = None if truth is None else np.asarray(truth, dtype=float)
        cond: Dict[str, Tuple[float, float]] = {}
        if self.conditional is not None:
            cond = {n: (lo, hi) for n, lo, hi in zip(self.conditional.names, self.conditional.lower, self.conditional.upper)}
        for i, (a, name) in enumerate(zip(axes, self.names)):
            lo, hi, c = self.lower[i], self.upper[i], self.center[i]
            if np.isfinite(lo) and np.isfinite(hi):
                a.errorbar([0.0], [c], yerr=[[c - lo], [hi - c]], fmt="o", capsize=5, color="C0", label="interval, Chebyshev centre")
            else:
                a.plot([0.0], [c], "o", color="C0")
                a.annotate("unbounded", (0.0, c), textcoords="offset points", xytext=(4, 4), fontsize="x-small", color="C1")
            a.plot([0.0], [self.minimax[i]], "o", mfc="none", color="C2", label="minimax")
            if name in cond:
                a.vlines([0.35], cond[name][0], cond[name][1], color="0.5", lw=3, label="given F̂ (exact)")
            if tr is not None:
                a.plot([0.0], [tr[i]], "x", color="red", ms=9, mew=2, label="truth")
            a.set_xlim(-0.6, 0.8)
            a.set_xticks([])
            a.set_title(name, fontsize="small")
            a.tick_params(labelsize="x-small")
            try:
                a.ticklabel_format(axis="y", useOffset=False)
            except AttributeError:  # pragma: no cover - a non-scalar formatter
                pass
            a.grid(True, axis="y", alpha=0.3)
        axes[0].legend(fontsize="xx-small", loc="best")
        st = self.structure.describe() if self.structure else "linear regression"
        fig.suptitle(f"{st}: eps = {float(np.max(self.eps)):.4g} {self.unit}, N = {self.n}", fontsize="small")
        fig.tight_layout()
        return fig


# ============================================================== LP core
def _threads(threads: Optional[int], jobs: int) -> int:
    if threads is None or threads == 0:
        threads = os.cpu_count() or 1
    if isinstance(threads, bool) or int(threads) < 1:
        raise ParameterError(f"threads must be >= 1 (or 0/None: every core), got {threads!r}")
    return max(1, min(int(threads), jobs))


def _lp(c: np.ndarray, A: Any, b: np.ndarray, bounds: Any) -> Tuple[Any, float]:
    """One LP by HiGHS (simplex); when it stops on numerical trouble (status 4) retried
    with HiGHS's interior point method, then both without presolve."""
    t = time.perf_counter()
    r = linprog(c, A_ub=A, b_ub=b, bounds=bounds, method="highs")
    for method, opts in (("highs-ipm", {}), ("highs-ipm", {"presolve": False}), ("highs-ds", {"presolve": False})):
        if r.status != 4:
            break
        r = linprog(c, A_ub=A, b_ub=b, bounds=bounds, method=method, options=opts)
    return r, time.perf_counter() - t


def _run(jobs: List[Tuple[np.ndarray, Any, np.ndarray, Any]], threads: int) -> List[Tuple[Any, float]]:
    if threads <= 1 or len(jobs) <= 1:
        return [_lp(*j) for j in jobs]
    with ThreadPoolExecutor(max_workers=threads) as ex:
        return list(ex.map(lambda j: _lp(*j), jobs))


def _eps_array(eps: EpsLike, n: int) -> np.ndarray:
    e = np.asarray(eps, dtype=float)
    if e.ndim == 0:
        e = np.full(n, float(e))
    if e.shape != (n,):
        raise InputError(f"eps must be a scalar or one bound per sample ({n}), got shape {e.shape}")
    if not np.all(np.isfinite(e)) or np.any(e <= 0):
        raise ParameterError(f"the noise bound eps must be finite and > 0, got {eps if np.ndim(eps) == 0 else 'an array with ' + str(e.min())}")
    return e


def _orth(M: np.ndarray) -> Optional[Tuple[np.ndarray, np.ndarray]]:
    """``(Q, T⁻¹)`` with ``M = Q T``, Q with (nearly) orthonormal columns, by Cholesky QR
    done twice (CholeskyQR2: two Gram matrices, two small inverses; only matrix
    products, which stay fast when the BLAS is oversubscribed, unlike LAPACK's
    Householder QR). None when M is (numerically) rank deficient."""
    p = M.shape[1]
    Q = M
    Tinv = np.eye(p)
    for _ in range(2):
        try:
            L = np.linalg.cholesky(Q.T @ Q)
            d = np.abs(np.diag(L))
            if not np.all(np.isfinite(d)) or d.min() <= 1e-7 * d.max():
                raise np.linalg.LinAlgError("ill-conditioned Gram matrix")
        except np.linalg.LinAlgError:
            break
        Rinv = np.linalg.inv(L.T)
        Q = Q @ Rinv
        Tinv = Tinv @ Rinv
    else:
        return _checked(M, Tinv)
    # too ill-conditioned for Cholesky QR (cond > ~1e7): Householder QR
    R = np.linalg.qr(M, mode="r")
    d = np.abs(np.diag(R))
    if not d.size or d.min() <= 1e-13 * d.max():
        return None
    return _checked(M, np.linalg.inv(R))


def _checked(M: np.ndarray, Tinv: np.ndarray) -> Optional[Tuple[np.ndarray, np.ndarray]]:
    """``(M T⁻¹, T⁻¹)`` when ``M T⁻¹`` is close to orthonormal (the change of variables is
    then exact to rounding and worth it), else None (numerically rank deficient)."""
    Q = M @ Tinv
    if not np.all(np.isfinite(Q)) or np.max(np.abs(Q.T @ Q - np.eye(M.shape[1]))) > 1e-3:
        return None
    return Q, Tinv


class _Scaled:
    """The FPS ``|y − Φθ| <= ε`` (and an optional box on θ) as well-conditioned LPs.

    Rows are divided by ε (constraints ``|b − A₁θ₁| <= 1``, ``b = y/ε``), columns by their
    largest magnitude s (``θ₁ = s θ``), and θ₁ is re-parameterised by the QR factor of
    ``A₁ = Q R``: ``z = R θ₁``, so the constraint matrix of every LP is ``±Q`` (orthonormal
    columns) however collinear the regressors are (an ARX on a slowly varying output:
    cond(Φ) ~ 1e7). The objective ``θ₁ᵢ = (R⁻¹ z)ᵢ`` is a row of ``R⁻¹``. Exact for any
    invertible R (R only has to make the LP well conditioned): :func:`_orth`.
    Rank-deficient Φ: no re-parameterisation (the LPs report unbounded).
    """

    def __init__(self, phi: np.ndarray, y: np.ndarray, eps: np.ndarray, box: Optional[Tuple[np.ndarray, np.ndarray]]) -> None:
        A1 = phi / eps[:, None]
        s = np.max(np.abs(A1), axis=0)
        s[~(s > 0)] = 1.0
        A1 = A1 / s
        self.s = s
        self.p = p = phi.shape[1]
        self.A1 = A1
        self.b0 = y / eps
        qt = _orth(A1)
        self.whitened = qt is not None
        if qt is not None:
            Q, self.Tinv = qt
            z0 = Q.T @ self.b0  # least squares: the LP variables are the offsets from it
        else:
            Q, self.Tinv = A1, np.eye(p)
            z0 = np.zeros(p)
        self.Q = Q
        self.A = sp.csr_matrix(Q)
        self.off = self.Tinv @ z0  # θ₁ of the least-squares fit
        self.b = self.b0 - Q @ z0
        rows, rhs = [], []
        if box is not None:
            lo, hi = box
            for i in range(p):
                if np.isfinite(hi[i]):
                    rows.append(self.Tinv[i])
                    rhs.append(hi[i] * s[i] - self.off[i])
                if np.isfinite(lo[i]):
                    rows.append(-self.Tinv[i])
                    rhs.append(-lo[i] * s[i] + self.off[i])
        Bm = np.array(rows).reshape(len(rows), p)
        nb_ = np.linalg.norm(Bm, axis=1) if len(rows) else np.ones(0)
        nb_[nb_ == 0] = 1.0
        self.B = sp.csr_matrix(Bm / nb_[:, None])  # unit rows
        self.hb = np.asarray(rhs, dtype=float) / nb_
        self.box = box
        self.G = sp.vstack([self.A, -self.A, self.B], format="csr")
        self.h = np.concatenate([self.b + 1.0, 1.0 - self.b, self.hb])
        self.free: List[Tuple[Optional[float], Optional[float]]] = [(None, None)] * p

    def theta(self, z: np.ndarray) -> np.ndarray:
        """Parameters θ from LP variables z."""
        return (self.off + self.Tinv @ z) / self.s

    def minimax_job(self) -> Tuple[np.ndarray, Any, np.ndarray, Any]:
        n = self.A.shape[0]
        one = sp.csr_matrix(np.ones((n, 1)))
        zb = sp.csr_matrix((self.B.shape[0], 1))
        G = sp.vstack([sp.hstack([self.A, -one]), sp.hstack([-self.A, -one]), sp.hstack([self.B, zb])], format="csr")
        c = np.zeros(self.p + 1)
        c[-1] = 1.0
        return c, G, np.concatenate([self.b, -self.b, self.hb]), self.free + [(0.0, None)]

    def bound_jobs(self) -> List[Tuple[np.ndarray, Any, np.ndarray, Any]]:
        jobs = []
        for i in range(self.p):
            for sign in (1.0, -1.0):
                jobs.append((sign * self.Tinv[i], self.G, self.h, self.free))
        return jobs

    def chebyshev_job(self, lo1: np.ndarray, hi1: np.ndarray) -> Tuple[Tuple[np.ndarray, Any, np.ndarray, Any], Callable[[np.ndarray], np.ndarray], str]:
        """The largest ball inside the FPS (and the box), as an LP ``max r``.

        Whitened (the usual case): the ball in the LP variables z, i.e. in the metric
        ``‖Φ(θ − θ')/ε‖₂`` of the regressors (units- and parameterisation-free, and round
        however collinear the regressors): rows ``±q_tᵀ z + r ‖q_t‖ <= 1 ∓ b_t``.
        Otherwise (numerically rank-deficient Φ): the ball in coordinates v with ``θ₁ = m
        + W v`` (m, W: midpoints and half-widths of the intervals, 1 where unbounded).
        Returns the job, the map from its solution to θ₁, and the metric's name."""
        p = self.p
        if self.whitened:
            qn = np.sqrt(np.einsum("ij,ij->i", self.Q, self.Q))
            bn = np.ones(self.B.shape[0])  # unit rows
            G = sp.vstack([sp.hstack([self.G, sp.csr_matrix(np.r_[qn, qn, bn][:, None])])], format="csr")
            c = np.zeros(p + 1)
            c[-1] = -1.0
            return (c, G, self.h, self.free + [(0.0, None)]), (lambda x: self.off + self.Tinv @ x[:p]), "regressors"
        fin = np.isfinite(lo1) & np.isfinite(hi1)
        m = np.where(fin, 0.5 * (lo1 + hi1), 0.0)
        w = np.where(fin, 0.5 * (hi1 - lo1), 1.0)
        w = np.maximum(w, 1e-12 * max(float(np.max(w)), 1e-300))
        AW = self.A1 * w
        norms = np.sqrt(np.einsum("ij,ij->i", AW, AW))
        qt = _orth(AW)
        if qt is not None:
            M, Rinv = qt
        else:
            Rinv = np.eye(p)
            M = AW
        Am = self.A1 @ m
        blocks = [np.hstack([M, norms[:, None]]), np.hstack([-M, norms[:, None]])]
        rhs = [self.b0 + 1.0 - Am, 1.0 - self.b0 + Am]
        fi = np.flatnonzero(fin)
        if fi.size:  # the ball inside the interval box: |v_i| + r <= 1
            Rf = Rinv[fi]
            one = np.ones((fi.size, 1))
            blocks += [np.hstack([Rf, one]), np.hstack([-Rf, one])]
            rhs += [np.ones(fi.size), np.ones(fi.size)]
        G = sp.csr_matrix(np.vstack(blocks))
        c = np.zeros(p + 1)
        c[-1] = -1.0
        job = (c, G, np.concatenate(rhs), [(None, None)] * p + [(0.0, None)])
        return job, (lambda x: m + w * (Rinv @ x[:p])), "half-widths"


def _status_error(r: Any, what: str) -> ConvergenceError:
    return ConvergenceError(f"HiGHS failed on {what}: status {r.status}: {r.message}")


def _pui_core(phi: np.ndarray, y: np.ndarray, eps: EpsLike, names: List[str], *, box: Any = None,
              threads: Optional[int] = None, structure: Optional[Structure] = None, unit: str = "",
              method: str = "", strict: bool = True) -> PUIResult:
    t_all = time.perf_counter()
    n, p = phi.shape
    e = _eps_array(eps, n)
    if y.shape != (n,):
        raise InputError(f"y must have shape ({n},), got {y.shape}")
    if not np.all(np.isfinite(phi)) or not np.all(np.isfinite(y)):
        raise InputError("the regression matrix and y must be finite")
    bx = None
    if box is not None:
        lo, hi = (np.broadcast_to(np.asarray(v, dtype=float), (p,)).copy() for v in box)
        if np.any(lo > hi):
            raise ParameterError("box: lower > upper for some parameter")
        bx = (lo, hi)
    S = _Scaled(phi, y, e, bx)
    desc = structure.describe() if structure is not None else f"the linear regression ({p} parameters)"
    times: List[float] = []
    nthr = _threads(threads, 2 * p)
    # 1. minimal bound (minimax fit)
    r0, t0 = _lp(*S.minimax_job())
    times.append(t0)
    if r0.status == 2:
        raise InfeasibleError(float(e.max()), math.inf, desc, n, np.full(p, np.nan), unit, "(the prior box excludes every parameter vector)")
    if r0.status != 0:
        raise _status_error(r0, "the minimal-bound LP")
    tau = float(r0.x[-1])
    theta_mm = S.theta(r0.x[:p])
    eps_scalar = float(e[0]) if np.all(e == e[0]) else None
    eps_min = tau * (eps_scalar if eps_scalar is not None else float(e.max()))
    if tau > 1.0 + 1e-9:
        raise InfeasibleError(float(e.max()), eps_min, desc, n, theta_mm, unit,
                              "" if eps_scalar is not None else "(per-sample bounds: eps_min scales every bound by the same factor)")
    # 2. the 2p interval LPs, in parallel
    res = _run(S.bound_jobs(), nthr)
    zlo = np.empty(p)
    zhi = np.empty(p)
    wit = np.full((2 * p, p), np.nan)
    failed: List[str] = []
    for k, (r, dt_) in enumerate(res):
        times.append(dt_)
        i, sign = divmod(k, 2)
        if r.status == 0:
            val = S.off[i] + float(r.fun) * (1.0 if sign == 0 else -1.0)
            wit[k] = S.theta(r.x)
        elif r.status == 3:
            val = -math.inf if sign == 0 else math.inf
        elif r.status == 2:
            raise InfeasibleError(float(e.max()), eps_min, desc, n, theta_mm, unit,
                                  "(the bound is within the LP tolerance of eps_min: the feasible set is numerically empty)")
        elif not strict:  # numerical failure: fall back on the prior box (or unbounded)
            lim = (bx[0][i] if sign == 0 else bx[1][i]) if bx is not None else (-math.inf if sign == 0 else math.inf)
            val = float(lim) * S.s[i]
            failed.append(names[i])
        else:
            raise _status_error(r, f"the bound of {names[i]}")
        (zlo if sign == 0 else zhi)[i] = val
    zhi = np.maximum(zhi, zlo)
    # 3. Chebyshev centre in half-width-normalised coordinates
    job, to_theta1, metric = S.chebyshev_job(zlo, zhi)
    rc, tc = _lp(*job)
    times.append(tc)
    notes: List[str] = []
    if rc.status == 0:
        center = to_theta1(rc.x) / S.s
        radius = float(rc.x[-1])
    elif rc.status == 3:
        center = np.full(p, np.nan)
        radius = math.inf
    else:  # numerical failure: fall back on the minimax point
        center = theta_mm.copy()
        radius = math.nan
        notes.append(f"Chebyshev-centre LP failed (HiGHS status {rc.status}): the centre is the minimax point")
    lower, upper = zlo / S.s, zhi / S.s
    return PUIResult(
        names=list(names), lower=lower, upper=upper, center=center, radius=radius, minimax=theta_mm,
        eps=(eps_scalar if eps_scalar is not None else e.copy()), eps_min=eps_min, n=n, n_data=n, structure=structure,
        method=method or "exact: 2p LPs (HiGHS) on the polytope |y - Phi theta| <= eps",
        solve_time=time.perf_counter() - t_all, lp_times=np.asarray(times), threads=nthr, unit=unit, witnesses=wit,
        center_metric=metric,
        notes=notes + ([f"LP failed numerically (HiGHS status 4) for a bound of {', '.join(sorted(set(failed)))}: the prior box (or unbounded) reported"] if failed else []),
    )


def pui_linear(phi: ArrayLike, y: ArrayLike, eps: EpsLike, *, names: Optional[Sequence[str]] = None,
               box: Optional[Tuple[ArrayLike, ArrayLike]] = None, threads: Optional[int] = None) -> PUIResult:
    """PUI of any linear regression ``y = Φ θ + e``, ``|e(t)| <= eps`` (scalar or per
    sample): exact, 2p + 2 LPs.

    Parameters
    ----------
    phi : (n, p) array
    y : (n,) array
    eps : float or (n,) array, > 0
    names : parameter names (default ``theta1..``)
    box : (lower, upper), optional
        Prior bounds on θ (scalars or (p,)), e.g. to keep a poorly excited parameter finite.
    threads : int, optional
        Worker threads for the 2p LPs (default: every core).

    Raises :class:`InfeasibleError` when ``eps`` is below the minimal bound.
    """
    P = np.asarray(phi, dtype=float)
    yy = np.asarray(y, dtype=float)
    if P.ndim != 2:
        raise InputError(f"phi must be (n, p), got shape {P.shape}")
    if P.shape[0] < 1 or P.shape[1] < 1:
        raise InputError(f"phi is empty: shape {P.shape}")
    nm = list(names) if names is not None else [f"theta{i + 1}" for i in range(P.shape[1])]
    if len(nm) != P.shape[1]:
        raise InputError(f"{len(nm)} names for {P.shape[1]} parameters")
    return _pui_core(P, yy, eps, nm, box=box, threads=threads)


def min_bound(phi: ArrayLike, y: ArrayLike) -> Tuple[float, np.ndarray]:
    """The minimal bound ``ε_min = min_θ max_t |y(t) − φ(t)ᵀθ|`` and its minimiser (one LP)."""
    P = np.asarray(phi, dtype=float)
    yy = np.asarray(y, dtype=float)
    if P.ndim != 2 or yy.shape != (P.shape[0],):
        raise InputError(f"phi (n, p) and y (n,) expected, got {P.shape} and {yy.shape}")
    scale = _residual_scale(P, yy)
    S = _Scaled(P, yy, np.full(yy.shape[0], scale), None)
    r, _ = _lp(*S.minimax_job())
    if r.status != 0:
        raise _status_error(r, "the minimal-bound LP")
    return float(r.x[-1]) * scale, S.theta(r.x[:-1])


def _unit(name: str) -> str:
    try:
        from .results import UNITS

        return UNITS.get(name, "")
    except Exception:  # pragma: no cover
        return ""


def pui(data: Any, structure: Structure, eps: EpsLike, *, box: Optional[Tuple[ArrayLike, ArrayLike]] = None,
        threads: Optional[int] = None, skip: int = 0, **window: Any) -> PUIResult:
    """Exact PUI of a FIR or ARX structure.

    Parameters
    ----------
    data : MeasuredRun, SimResult, DataFrame, mapping, IdData or (y, u)
        Channels are taken by the structure's ``inputs``/``output`` names.
    structure : Structure
        From :func:`fir` or :func:`arx`.
    eps : float or (N,) array
        Bound on |e(t)| [output unit] (ARX: on the equation error).
    box : prior bounds on the parameters, optional.
    threads : LP worker threads (default every core).
    skip : int
        Samples left out of the constraints after the lags.
    **window : ``t_start``, ``t_stop``, ``step``, ``derive_rates`` (see :func:`iddata`).
    """
    if structure.kind == "oe":
        raise ParameterError("pui: an OE structure is not linear in its parameters; use oe_pui() (or identify())")
    t = time.perf_counter()
    d = _resolve(data, structure, **window)
    reg = _regression(structure, d.y, d.u, skip)
    e = np.asarray(eps, dtype=float)
    if e.ndim == 1 and e.shape[0] == len(d):
        e = e[reg.rows]
    r = _pui_core(reg.phi, reg.y, e, reg.names, box=box, threads=threads, structure=structure, unit=_unit(d.output),
                  method=f"exact: {2 * structure.n_params + 2} LPs (HiGHS) on the polytope |y - Phi theta| <= eps ({structure.kind.upper()})")
    r.n_data, r.dt, r.notes = len(d), d.dt, list(d.notes)
    r.solve_time = time.perf_counter() - t
    return r


# ============================================================== output error
def _poly_stable(f: np.ndarray, margin: float = 1e-9) -> bool:
    if f.size == 0:
        return True
    return bool(np.all(np.abs(np.roots(np.r_[1.0, f])) < 1.0 - margin))


def _reflect(f: np.ndarray) -> np.ndarray:
    """Monic polynomial with the roots outside (or on) the unit circle reflected inside."""
    if f.size == 0:
        return f
    r = np.roots(np.r_[1.0, f])
    a = np.abs(r)
    r = np.where(a > 1.0, r / np.maximum(a, 1e-300) ** 2, r)  # 1/conj(r): same spectrum magnitude
    a = np.abs(r)
    r = np.where(a > 0.999, r * (0.999 / np.maximum(a, 1e-300)), r)
    return np.real(np.poly(r))[1:]


def simulate(structure: Structure, theta: ArrayLike, u: ArrayLike, e: Optional[ArrayLike] = None) -> np.ndarray:
    """The output of a structure from rest, (N,).

    * FIR: ``y = Σ B_j u_j + c + e``;
    * ARX: ``A y = Σ B_j u_j + c + e`` (``e`` the equation error);
    * OE: ``y = Σ B_j/F_j (u_j − u_j(0)) + c + e`` (the inputs as deviations from their
      first sample, the convention of :func:`oe_pui`).

    ``u``: (N,) or (N, m); ``e``: optional (N,) noise.
    """
    s = structure
    pc = s.split(theta)
    uu = np.asarray(u, dtype=float)
    if uu.ndim == 1:
        uu = uu[:, None]
    if uu.ndim != 2 or uu.shape[1] != s.n_inputs:
        raise InputError(f"u must be (N, {s.n_inputs}), got shape {np.shape(u)}")
    N = uu.shape[0]
    ee = np.zeros(N) if e is None else np.asarray(e, dtype=float)
    if ee.shape != (N,):
        raise InputError(f"e must have shape ({N},), got {ee.shape}")
    if s.kind == "oe":
        y = np.full(N, pc["c"]) + ee
        for j, name in enumerate(s.inputs):
            x = lfilter(np.r_[np.zeros(s.nk[j]), pc["b"][name]], np.r_[1.0, pc["f"][name]], uu[:, j] - uu[0, j])
            y = y + x
        return y
    v = np.full(N, pc["c"]) + ee
    for j, name in enumerate(s.inputs):
        if s.nb[j]:
            v = v + lfilter(np.r_[np.zeros(s.nk[j]), pc["b"][name]], [1.0], uu[:, j])
    if s.kind == "arx":
        return lfilter([1.0], np.r_[1.0, pc["a"]], v)
    return v


def multisine(n: int, rate: float = 100.0, *, amplitude: float = 0.05, f_max: float = 1.0, joints: Sequence[int] = (2, 3),
              n_sines: int = 10, pose: Sequence[float] = LAB_POSE, ramp_s: float = 2.0, seed: int = 0) -> Tuple[np.ndarray, np.ndarray]:
    """An identification experiment for an encoder replay (:meth:`popup.Model.replay`):
    ``n`` samples at ``rate`` [Hz] of the three motor angles [rad], at rest at ``pose``
    and then, after a smooth ramp of ``ramp_s`` [s], a sum of ``n_sines`` sines of random
    frequencies in [0.05, ``f_max``] Hz and phases on each joint of ``joints`` (1-based),
    scaled to a peak excursion ``amplitude`` [rad]. Returns ``(t (n,), q (n, 3))``."""
    if isinstance(n, bool) or int(n) < 2:
        raise ParameterError(f"n must be >= 2, got {n!r}")
    rng = np.random.default_rng(seed)
    t = np.arange(int(n)) / float(rate)
    q = np.tile(np.asarray(pose, dtype=float), (t.size, 1))
    x = np.clip(t / ramp_s, 0.0, 1.0) if ramp_s > 0 else np.ones_like(t)
    env = x * x * (3.0 - 2.0 * x)
    for j in joints:
        if j not in (1, 2, 3):
            raise ParameterError(f"joints are 1, 2, 3; got {j!r}")
        f = rng.uniform(0.05, f_max, n_sines)
        ph = rng.uniform(0.0, 2.0 * math.pi, n_sines)
        sig = np.sum(np.sin(2.0 * math.pi * f[:, None] * t[None, :] + ph[:, None]) - np.sin(ph[:, None]), axis=0)
        q[:, j - 1] += amplitude * env * sig / max(float(np.max(np.abs(sig))), 1e-300)
    return t, q


class _OE:
    """Pieces of the OE problem on fixed data (inputs as deviations, from rest)."""

    def __init__(self, s: Structure, y: np.ndarray, u: np.ndarray, skip: int) -> None:
        self.s = s
        self.y = y
        self.du = u - u[0]
        self.rows = np.arange(int(skip), y.shape[0])
        self.nb_total = sum(s.nb)
        self.nf_total = sum(s.nf)

    def numerator_regression(self, F: List[np.ndarray]) -> Tuple[np.ndarray, List[np.ndarray]]:
        """Columns q^-(nk+k)/F_j u_j (all rows) and the filtered inputs v_j = u_j/F_j."""
        s = self.s
        cols = []
        vs = []
        for j in range(s.n_inputs):
            v = lfilter([1.0], np.r_[1.0, F[j]], self.du[:, j])
            vs.append(v)
            for k in range(s.nb[j]):
                cols.append(_shift(v, s.nk[j] + k))
        if s.offset:
            cols.append(np.ones_like(self.y))
        return np.column_stack(cols), vs

    def outputs(self, F: List[np.ndarray], theta_bc: np.ndarray) -> Tuple[np.ndarray, List[np.ndarray]]:
        """ŷ and the per-input contributions x_j for denominators F and (b, c)."""
        s = self.s
        xs = []
        i = 0
        yhat = np.full_like(self.y, theta_bc[-1] if s.offset else 0.0)
        for j in range(s.n_inputs):
            b = theta_bc[i : i + s.nb[j]]
            i += s.nb[j]
            x = lfilter(np.r_[np.zeros(s.nk[j]), b], np.r_[1.0, F[j]], self.du[:, j])
            xs.append(x)
            yhat = yhat + x
        return yhat, xs

    def sensitivity(self, F: List[np.ndarray], xs: List[np.ndarray]) -> np.ndarray:
        """∂ŷ/∂f_ji = −q^-i x_j / F_j, (N, nf_total)."""
        cols = []
        for j in range(self.s.n_inputs):
            if self.s.nf[j] == 0:
                continue
            g = lfilter([1.0], np.r_[1.0, F[j]], xs[j])
            for i in range(1, self.s.nf[j] + 1):
                cols.append(-_shift(g, i))
        return np.column_stack(cols) if cols else np.zeros((self.y.shape[0], 0))

    def bc_names(self) -> List[str]:
        return [n for n in self.s.names if not n.startswith("f_")]

    def f_names(self) -> List[str]:
        return [n for n in self.s.names if n.startswith("f_")]

    def split_f(self, f: np.ndarray) -> List[np.ndarray]:
        out = []
        i = 0
        for j in range(self.s.n_inputs):
            out.append(np.asarray(f[i : i + self.s.nf[j]], dtype=float))
            i += self.s.nf[j]
        return out


def _residual_scale(phi: np.ndarray, y: np.ndarray) -> float:
    """A scale for the rows of a minimax LP: the largest least-squares residual (so the
    LP tolerance is relative to the minimal bound, not to |y|), or max |y| (when the
    regressors are numerically rank deficient)."""
    s = np.max(np.abs(phi), axis=0)
    s[~(s > 0)] = 1.0
    qt = _orth(phi / s)
    big = max(float(np.max(np.abs(y))), 1e-300)
    if qt is None:
        return big
    Q = qt[0]
    r = float(np.max(np.abs(y - Q @ (Q.T @ y))))
    return r if r > 1e-12 * big else big


def _minimax(phi: np.ndarray, y: np.ndarray, box: Optional[Tuple[np.ndarray, np.ndarray]] = None,
             strict: bool = True) -> Tuple[float, np.ndarray, float]:
    """min_θ max |y − Φθ| with an optional box on θ: (value, θ, LP time). ``strict=False``:
    a failed LP gives (inf, NaN, time) instead of raising."""
    scale = _residual_scale(phi, y)
    S = _Scaled(phi, y, np.full(y.shape[0], scale), box)
    r, t = _lp(*S.minimax_job())
    if r.status != 0:
        if not strict:
            return math.inf, np.full(phi.shape[1], np.nan), t
        raise _status_error(r, "a minimax LP of the output-error iteration")
    return float(r.x[-1]) * scale, S.theta(r.x[:-1]), t


def oe_pui(data: Any, structure: Structure, eps: float, *, denominators: Optional[Union[Mapping[str, ArrayLike], Sequence[ArrayLike]]] = None,
           iterations: int = 30, tol: float = 1e-3, sweep: int = 0, seed: int = 0, threads: Optional[int] = None,
           skip: int = 0, **window: Any) -> PUIResult:
    """Intervals of an output-error structure (the thesis's problem), by the scheme in
    the module docs: equation-error start, sequential-LP denominator F̂ (a local minimiser
    of the output-error bound), exact numerator intervals given F̂, first-order joint
    intervals, optional sweep of denominators verified by exact LPs.

    Parameters
    ----------
    data : MeasuredRun, SimResult, DataFrame, mapping, IdData or (y, u)
    structure : Structure
        From :func:`oe`.
    eps : float
        Bound on the output error |e(t)| [output unit].
    denominators : mapping ``{input: [f_1, …]}`` or one array per input, optional
        Fix the denominators (no iteration): the result is then exact given them
        (:attr:`PUIResult.approximation` says so; the f's are reported as point
        intervals).
    iterations : int
        Maximum sequential-LP iterations for F̂ (each: one step LP, one exact LP).
    tol : float
        Stop when the predicted decrease of the output-error bound is below ``tol``
        (relative), or when two accepted steps in a row decrease it by less.
    sweep : int
        Random convex combinations of the first-order end points' denominators to verify,
        besides those end points themselves (0: no sweep); see the module docs.
    seed : int
        Seed of the sweep.
    threads : LP worker threads (default every core).
    skip : int
        Samples left out of the constraints at the start (the filters still see them).
    **window : ``t_start``, ``t_stop``, ``step``, ``derive_rates`` (see :func:`iddata`).

    Raises :class:`InfeasibleError` when even F̂ needs a bound above ``eps``
    (``eps_min`` is then ``ε_min(F̂)``, an upper bound on the exact minimal bound).
    :attr:`PUIResult.iterations` records every denominator step (output-error bound,
    trust region, accepted or not).
    """
    s = structure
    if s.kind != "oe":
        raise ParameterError(f"oe_pui needs an OE structure, got {s.kind.upper()}; use pui()")
    t_all = time.perf_counter()
    d = _resolve(data, s, **window)
    if isinstance(skip, bool) or not float(skip).is_integer() or skip < 0:
        raise ParameterError(f"skip must be a whole number >= 0, got {skip!r}")
    e_ = np.asarray(eps, dtype=float)
    if e_.ndim != 0 or not math.isfinite(float(e_)) or float(e_) <= 0:
        raise ParameterError(f"oe_pui: eps must be one finite bound > 0, got {eps!r}")
    eps = float(e_)
    if isinstance(iterations, bool) or int(iterations) < 0:
        raise ParameterError(f"iterations must be >= 0, got {iterations!r}")
    if isinstance(sweep, bool) or int(sweep) < 0:
        raise ParameterError(f"sweep must be >= 0, got {sweep!r}")
    P = _OE(s, d.y, d.u, int(skip))
    n = P.rows.shape[0]
    if n < s.n_params:
        raise InputError(f"too few samples for {s.describe()}: {n} rows in the constraints for {s.n_params} parameters")
    unit = _unit(d.output)
    desc = s.describe()
    times: List[float] = []
    hist: List[Dict[str, Any]] = []
    rows = P.rows
    y = d.y[rows]

    def fit_given(F: List[np.ndarray], strict: bool = True) -> Tuple[float, np.ndarray, np.ndarray]:
        W, _ = P.numerator_regression(F)
        v, th, t = _minimax(W[rows], y, strict=strict)
        times.append(t)
        return v, th, W

    fixed = denominators is not None
    if fixed:
        F = _given_denominators(s, denominators)  # type: ignore[arg-type]
        e_best, bc, _ = fit_given(F)
        hist.append({"iteration": 0, "eps_oe": e_best, "step": 0.0, "accepted": True, "source": "given"})
    else:
        # 1. equation-error start: ARX with a common denominator of order max(nf)
        na = max(s.nf) if s.nf else 0
        ee = Structure("arx", s.inputs, s.output, s.nb, s.nk, na=na, offset=s.offset)
        du_full = P.du
        reg = _regression(ee, d.y, du_full, 0)
        _, th_ee, t_ee = _minimax(reg.phi, reg.y)
        times.append(t_ee)
        A = _reflect(th_ee[:na])
        F = [A[: s.nf[j]] if s.nf[j] <= na else np.r_[A, np.zeros(s.nf[j] - na)] for j in range(s.n_inputs)]
        F = [_reflect(f) for f in F]
        e_best, bc, _ = fit_given(F)
        hist.append({"iteration": 0, "eps_oe": e_best, "step": 0.0, "accepted": True, "source": "equation error"})
        # 2. sequential LP on the true output-error bound
        rho = 0.2
        it = 0
        small = 0
        while it < int(iterations) and P.nf_total > 0 and rho > 1e-7:
            it += 1
            yhat, xs = P.outputs(F, bc)
            Wb, _ = P.numerator_regression(F)
            Gf = P.sensitivity(F, xs)
            M = np.hstack([Gf, Wb])[rows]
            hi_ = np.r_[np.full(P.nf_total, rho), np.full(M.shape[1] - P.nf_total, np.inf)]
            v_lin, step, t_s = _minimax(M, y, (-hi_, hi_), strict=False)
            times.append(t_s)
            if not math.isfinite(v_lin):  # the step LP failed numerically: a smaller region
                hist.append({"iteration": it, "eps_oe": math.nan, "step": math.nan, "trust_region": rho,
                             "accepted": False, "predicted": math.nan, "source": "step LP failed"})
                rho *= 0.25
                continue
            df = step[: P.nf_total]
            if e_best - v_lin <= tol * e_best:  # first-order stationary: no predicted decrease
                hist.append({"iteration": it, "eps_oe": e_best, "step": 0.0, "trust_region": rho, "accepted": False,
                             "predicted": v_lin, "source": "converged"})
                break
            Fc = P.split_f(np.concatenate(F) + df) if P.nf_total else F
            ok = all(_poly_stable(f) for f in Fc)
            e_new = math.inf
            if ok:
                e_new, bc_new, _ = fit_given(Fc, strict=False)
                ok = math.isfinite(e_new)
            accepted = ok and e_new < e_best
            hist.append({"iteration": it, "eps_oe": e_new if ok else math.nan, "step": float(np.max(np.abs(df))) if df.size else 0.0,
                         "trust_region": rho, "accepted": bool(accepted), "predicted": v_lin, "source": "sequential LP"})
            if accepted:
                gain = (e_best - e_new) / e_best
                F, bc, e_best = Fc, bc_new, e_new
                small = small + 1 if gain < tol else 0
                if small >= 2:
                    break
                if np.max(np.abs(df)) >= 0.99 * rho:
                    rho = min(2.0 * rho, 1.0)
            else:
                rho *= 0.25
    # 3. exact numerator intervals given F̂
    W, _ = P.numerator_regression(F)
    Fhat = np.concatenate(F) if P.nf_total else np.zeros(0)
    eps_min = e_best
    if eps_min > eps * (1.0 + 1e-9):
        th_full = np.concatenate([Fhat, bc])
        detail = ("(with the denominators given)" if fixed else
                  "(with the denominators of the iteration: a local optimum of a nonconvex problem, so this eps_min is "
                  "an upper bound on the exact one)")
        raise InfeasibleError(eps, eps_min, desc, n, th_full, unit, detail)
    bc_names = P.bc_names()
    try:
        cond = _pui_core(W[rows], y, eps, bc_names, threads=threads, unit=unit,
                         method="exact given the denominators: LPs on |y - Phi(F) (b, c)| <= eps")
    except InfeasibleError as ex:
        raise InfeasibleError(eps, ex.eps_min, desc, n, np.concatenate([Fhat, ex.minimax]), unit, "(given the denominators)") from None
    times += list(cond.lp_times)
    nthr = cond.threads
    f_names = P.f_names()
    if fixed:
        lower = np.concatenate([Fhat, cond.lower])
        upper = np.concatenate([Fhat, cond.upper])
        center = np.concatenate([Fhat, cond.center])
        radius = cond.radius
        metric = cond.center_metric
        method = "OE with given denominators: exact numerator/offset intervals by LP"
        approx = ""
        notes = ["the denominators are given: their intervals are points; the rest is exact given them"]
        sw = None
    else:
        # 4. first-order joint intervals around F̂ (exact in b, c)
        _, xs = P.outputs(F, bc)
        Gf = P.sensitivity(F, xs)
        M = np.hstack([Gf, W])[rows]
        # prior: F_j stable, so |f_ji| <= C(nf_j, i) (coefficients of a monic polynomial
        # with every root in the unit disc)
        cmax = np.concatenate([[math.comb(s.nf[j], i) for i in range(1, s.nf[j] + 1)] for j in range(s.n_inputs)] + [[]])
        inf_ = np.full(M.shape[1] - P.nf_total, np.inf)
        lin = _pui_core(M, y, eps, f_names + bc_names, threads=threads, unit=unit, strict=False,
                        box=(np.r_[-cmax - Fhat, -inf_], np.r_[cmax - Fhat, inf_]))
        times += list(lin.lp_times)
        lower = np.concatenate([Fhat + lin.lower[: P.nf_total], lin.lower[P.nf_total:]])
        upper = np.concatenate([Fhat + lin.upper[: P.nf_total], lin.upper[P.nf_total:]])
        center = np.concatenate([Fhat + lin.center[: P.nf_total], lin.center[P.nf_total:]])
        radius = lin.radius
        metric = lin.center_metric
        # widen to the exact conditional intervals (verified feasible points)
        lower[P.nf_total:] = np.minimum(lower[P.nf_total:], cond.lower)
        upper[P.nf_total:] = np.maximum(upper[P.nf_total:], cond.upper)
        lower[: P.nf_total] = np.minimum(lower[: P.nf_total], Fhat)
        upper[: P.nf_total] = np.maximum(upper[: P.nf_total], Fhat)
        sw = None
        if sweep:
            assert lin.witnesses is not None
            dF = lin.witnesses[:, : P.nf_total]
            sw = _sweep(P, rows, y, eps, Fhat, dF[np.all(np.isfinite(dF), axis=1)], int(sweep), seed, threads, times)
            if sw["feasible"]:
                lower = np.minimum(lower, sw["lower"])
                upper = np.maximum(upper, sw["upper"])
        method = ("OE: equation-error start, sequential-LP denominator (local), exact numerator LPs given it, "
                  "first-order joint intervals" + (f", sweep of {int(sweep)} denominators" if sweep else ""))
        approx = ("denominator F̂ is a local minimiser of the output-error bound; the intervals are those of the model "
                  "linearised in F around F̂ (exact in b and c), widened to every point verified feasible "
                  "(the exact numerator intervals given F̂" + (" and the sweep" if sweep else "") + "). The exact OE "
                  "feasible set is not convex: these are not guaranteed outer bounds.")
        notes = [f"first-order intervals: {note}" for note in lin.notes]
    res = PUIResult(
        names=s.names, lower=lower, upper=upper, center=center, radius=radius,
        minimax=np.concatenate([Fhat, bc]), eps=eps, eps_min=eps_min, n=n, n_data=len(d), structure=s,
        method=method, approximation=approx, solve_time=time.perf_counter() - t_all, lp_times=np.asarray(times),
        threads=nthr, dt=d.dt, unit=unit, notes=list(d.notes) + notes + ["OE: inputs as deviations from their first sample, filters from rest"],
        conditional=cond, denominators={u: np.r_[1.0, f] for u, f in zip(s.inputs, F)}, iterations=hist, sweep=sw,
        center_metric=metric,
    )
    return res


def _given_denominators(s: Structure, den: Union[Mapping[str, ArrayLike], Sequence[ArrayLike]]) -> List[np.ndarray]:
    if isinstance(den, Mapping):
        missing = [u for u in s.inputs if u not in den]
        if missing:
            raise InputError(f"denominators: missing {missing}")
        seq = [den[u] for u in s.inputs]
    else:
        seq = list(den)
        if len(seq) != s.n_inputs:
            raise InputError(f"denominators: one per input ({s.n_inputs}) expected, got {len(seq)}")
    out = []
    for j, f in enumerate(seq):
        a = np.atleast_1d(np.asarray(f, dtype=float))
        if a.shape == (s.nf[j] + 1,) and a[0] == 1.0:
            a = a[1:]
        if a.shape != (s.nf[j],):
            raise InputError(f"denominator of {s.inputs[j]!r}: {s.nf[j]} coefficients f_1.. (or [1, f_1, ..]) expected, got {a.shape}")
        if not _poly_stable(a, 0.0):
            raise ParameterError(f"denominator of {s.inputs[j]!r} is unstable (a root on or outside the unit circle)")
        out.append(a)
    return out


def _sweep(P: _OE, rows: np.ndarray, y: np.ndarray, eps: float, Fhat: np.ndarray, dF: np.ndarray, m: int, seed: int,
           threads: Optional[int], times: List[float]) -> Dict[str, Any]:
    """Candidates F̂ + ΔF: the denominators of the first-order witnesses ``dF`` (K, nf)
    and ``m`` random convex combinations of them (Dirichlet weights). Keep the stable
    ones whose exact minimal bound is <= eps, bound their numerators by exact LPs, and
    return the hull of those verified points."""
    rng = np.random.default_rng(seed)
    p = len(P.s.names)
    lo = np.full(p, math.inf)
    hi = np.full(p, -math.inf)
    pts = np.unique(np.round(dF, 12), axis=0) if dF.size else np.zeros((0, P.nf_total))
    if pts.shape[0] and m:
        wts = rng.dirichlet(np.ones(pts.shape[0]), size=m)
        pts = np.vstack([pts, wts @ pts])
    cands = []
    for df in pts:
        F = P.split_f(Fhat + df)
        if all(_poly_stable(x) for x in F):
            cands.append(F)
    nthr = _threads(threads, max(1, len(cands)))

    def check(F: List[np.ndarray]) -> Tuple[List[np.ndarray], float, float]:
        W, _ = P.numerator_regression(F)
        v, _, t = _minimax(W[rows], y)
        return F, v, t

    if nthr > 1 and len(cands) > 1:
        with ThreadPoolExecutor(max_workers=nthr) as ex:
            checked = list(ex.map(check, cands))
    else:
        checked = [check(F) for F in cands]
    feasible = 0
    for F, v, t in checked:
        times.append(t)
        if v > eps:
            continue
        W, _ = P.numerator_regression(F)
        try:
            r = _pui_core(W[rows], y, eps, P.bc_names(), threads=threads)
        except InfeasibleError:
            continue
        times.extend(r.lp_times)
        feasible += 1
        fv = np.concatenate(F) if P.nf_total else np.zeros(0)
        lo = np.minimum(lo, np.concatenate([fv, r.lower]))
        hi = np.maximum(hi, np.concatenate([fv, r.upper]))
    return {"drawn": int(pts.shape[0]), "stable": len(cands), "feasible": feasible, "lower": lo, "upper": hi}


# ============================================================== dispatch
def identify(data: Any, structure: Structure, eps: EpsLike, **kwargs: Any) -> PUIResult:
    """:func:`pui` for FIR/ARX, :func:`oe_pui` for OE."""
    if structure.kind == "oe":
        return oe_pui(data, structure, eps, **kwargs)  # type: ignore[arg-type]
    return pui(data, structure, eps, **kwargs)
