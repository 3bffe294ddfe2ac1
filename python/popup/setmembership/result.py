"""What identification returns (:class:`PUIResult`) and the error of an empty feasible set."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Tuple, Union

import numpy as np

from ..exceptions import InputError, PopupError
from .structure import ArrayLike, Structure


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
        from ..plot import pyplot

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
