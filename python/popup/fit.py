"""Fit chosen effect parameters of a model to a measured run.

::

    run = popup.read_run("examples/data/friction_run")
    res = popup.fit_params(model, run, ["joint_friction.tau_c", "joint_friction.b"])
    res.params            # {'joint_friction.tau_c[0]': 0.41, ...}
    res.to_pandas()       # start, fitted, 95 % half width, bounds per parameter
    res.model             # the model with the fitted values
    res.plot()            # measured vs simulated before/after, per channel

The same problem and objective as :func:`popup.diagnose` (a :class:`popup.ReplayProblem`;
Gaussian maximum likelihood with an unknown variance per channel, :mod:`popup.estimate`;
errors in noise units, :data:`popup.problem.ERROR_DEFINITION`), for any parameters of any
effects, including those the diagnosis does not fit by default (structural settings
excepted: they change the chain) and with the user's own bounds, typical scales, start,
seed grid and initial state. Multi-start by default: the start, the effects' seed points
and the grid are simulated in one batch, the best three are fitted, and
:attr:`FitResult.warnings` says when the starts end in different minima or the best fit
sits at a bound; :attr:`FitResult.identifiability` names parameters the run cannot pin
down (their interval is ``inf``).

A parameter is named ``"effect.name"`` (every entry: per joint or per link) or
``"effect.name[i]"`` (one entry, 0-based), e.g. ``"higher_bending_modes.e_pa[1]"``, the
Young's modulus of link 2's beam.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import re
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from . import effects as fx
from . import estimate as est
from .exceptions import InputError
from .io import MeasuredRun
from .problem import ReplayProblem

if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd

    from .model import Model

__all__ = ["FitResult", "fit_params"]

_NAME = re.compile(r"^\s*([a-z_]+)\.([a-z_0-9]+)\s*(?:\[\s*(\d+)\s*\])?\s*$")


def _parse(names: Sequence[str]) -> List[Tuple[fx.EffectParam, int, str]]:
    """(parameter, entry, display name) for every requested entry, in the order given."""
    if isinstance(names, str):
        names = [names]
    out: List[Tuple[fx.EffectParam, int, str]] = []
    for n in names:
        m = _NAME.match(str(n))
        if m is None:
            raise InputError(f"input params: {n!r} is not 'effect.name' or 'effect.name[i]'")
        eff, par, idx = m.group(1), m.group(2), m.group(3)
        if eff not in fx.EFFECTS:
            raise InputError(f"input params: {n!r}: unknown effect {eff!r}; effects are {sorted(fx.EFFECTS)}")
        ps = fx.EFFECTS[eff].params
        if par not in ps:
            raise InputError(f"input params: {n!r}: {eff} has no parameter {par!r}; it has {sorted(ps)}")
        p = ps[par]
        if p.integer:
            raise InputError(f"input params: {n!r} is structural (an integer setting of the chain): it cannot be fitted")
        entries = range(p.length) if idx is None else [int(idx)]
        for i in entries:
            if not 0 <= i < p.length:
                raise InputError(f"input params: {n!r}: index {i} out of range 0..{p.length - 1}")
            key = f"{eff}.{par}[{i}]"
            if any(k == key for _, _, k in out):
                raise InputError(f"input params: {key} is named twice")
            out.append((p, i, key))
    if not out:
        raise InputError("input params: no parameter to fit")
    return out


def _check_args(
    params: Any, bounds: Any, scale: Any, x0: Any, grid: Any, channels: Any, sample_rate: Any, threads: Any, max_iter: Any, starts: Any
) -> Tuple[Optional[List[str]], Optional[float]]:
    """Refuse arguments of the wrong kind with an InputError naming the argument (before
    anything is simulated); return ``channels`` and ``sample_rate`` normalised."""
    from .model import check_names, check_scalar, check_threads, check_count

    if not isinstance(params, str):
        check_names("params", params)
    for what, d in (("bounds", bounds), ("scale", scale), ("x0", x0), ("grid", grid)):
        if d is not None and not isinstance(d, Mapping):
            raise InputError(f"input {what}: expected a mapping of parameter names ('effect.name[i]') to values, got {d!r}")
        for k in d or {}:
            if not isinstance(k, str):
                raise InputError(f"input {what}: key {k!r} is not a parameter name ('effect.name[i]')")
    est.check_max_iter(max_iter)
    check_count("starts", starts, 1, 10**3)
    check_threads(threads)
    ch = None if channels is None else check_names("channels", channels)
    rate = None
    if sample_rate is not None:
        rate = check_scalar("sample_rate", sample_rate, "Hz")
        if not (np.isfinite(rate) and rate > 0):
            raise InputError(f"input sample_rate: {rate!r} Hz must be finite and > 0")
    return ch, rate


def _number(what: str, key: str, v: Any) -> float:
    """``v`` as one float, or an InputError naming argument ``what`` and entry ``key``."""
    try:
        if np.ndim(v) != 0:
            raise TypeError(f"shape {np.shape(v)}")
        return float(v)
    except (TypeError, ValueError) as e:
        raise InputError(f"input {what}: {key}: expected one number, got {v!r} ({e})") from None


def _bounds_pair(key: str, b: Any) -> Tuple[float, float]:
    """``(lower, upper)`` of ``bounds[key]``, or an InputError naming ``bounds``."""
    try:
        a = np.asarray(b, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InputError(f"input bounds: {key}: expected (lower, upper), got {b!r} ({e})") from None
    if a.shape != (2,):
        raise InputError(f"input bounds: {key}: expected (lower, upper), got {b!r}")
    return float(a[0]), float(a[1])


def _lookup(d: Optional[Mapping[str, Any]], key: str, per_entry_ndim: int) -> Any:
    """``d[key]`` for ``key = "effect.name[i]"``, else ``d["effect.name"]`` (its entry i
    when it has ``per_entry_ndim`` dimensions: one value per entry), else None."""
    if not d:
        return None
    if key in d:
        return d[key]
    base, i = key.rsplit("[", 1)
    if base in d:
        v = d[base]
        if np.ndim(v) != per_entry_ndim:
            return v
        try:
            return v[int(i[:-1])]
        except (IndexError, KeyError, TypeError):
            raise InputError(f"input: {base}: {v!r} has no entry {i[:-1]} (one value per entry of {base})") from None
    return None


@dataclass
class FitResult:
    """A fit of effect parameters to one measured run (:func:`fit_params`)."""

    names: List[str]
    """Fitted entries, ``"effect.name[i]"``."""
    x0: np.ndarray
    """Start values (after the seed grid, if any)."""
    x: np.ndarray
    """Fitted values (SI units of :mod:`popup.effects`)."""
    ci95: np.ndarray
    """95 % half widths (Gauss–Newton, inflated for residual correlation)."""
    lower: np.ndarray
    upper: np.ndarray
    error_before: float
    """Systematic error in noise units (:data:`popup.problem.ERROR_DEFINITION`) of the
    model as given."""
    error: float
    """Overall error with the fitted values."""
    per_channel_before: Dict[str, float]
    per_channel: Dict[str, float]
    model: Any
    """The model with the fitted values (``Model.with_effects``)."""
    channels: List[str]
    time: np.ndarray
    measured: np.ndarray
    """(n, C) measured channels on the run's stamps."""
    simulated_before: np.ndarray
    simulated: np.ndarray
    nfev: int
    """Rollouts run (seed grid, Jacobians, steps)."""
    seconds: float
    extra: Dict[str, Any] = field(default_factory=dict)
    warnings: List[str] = field(default_factory=list)
    """Fits that ended elsewhere from other starts, parameters at a bound."""
    identifiability: Dict[str, Any] = field(default_factory=dict)
    """Rank, condition, correlations and the parameters the run cannot pin down
    (:func:`popup.estimate.uncertainty`)."""
    noise: Dict[str, float] = field(default_factory=dict)
    """Each channel's white-noise floor σ (channel unit)."""

    @property
    def params(self) -> Dict[str, float]:
        """Fitted values by name."""
        return {n: float(v) for n, v in zip(self.names, self.x)}

    def __repr__(self) -> str:
        body = ", ".join(f"{n} = {v:.6g} ± {c:.2g}" for n, v, c in zip(self.names, self.x, self.ci95))
        return f"FitResult({body}; error {self.error_before:.4g} -> {self.error:.4g}, {self.nfev} rollouts)"

    def to_pandas(self) -> "pd.DataFrame":
        """One row per fitted entry: start, fitted, ci95, lower, upper."""
        import pandas as pd

        return pd.DataFrame(
            {"param": self.names, "start": self.x0, "fitted": self.x, "ci95": self.ci95, "lower": self.lower, "upper": self.upper}
        ).set_index("param")

    def plot(self, channels: Optional[Sequence[str]] = None, axes: Any = None) -> Any:
        """Measured, simulated before and after the fit, one axis per channel; returns the
        figure."""
        import matplotlib.pyplot as plt

        chans = list(self.channels if channels is None else channels)
        if axes is None:
            fig, axes = plt.subplots(len(chans), 1, sharex=True, figsize=(8, 2.2 * len(chans)), squeeze=False)
            axes = axes[:, 0]
        fig = axes[0].figure
        for ax, c in zip(axes, chans):
            j = self.channels.index(c)
            ax.plot(self.time, self.measured[:, j], "k", lw=1.0, label="measured")
            ax.plot(self.time, self.simulated_before[:, j], "C1--", lw=1.0, label=f"before ({self.per_channel_before[c]:.3g})")
            ax.plot(self.time, self.simulated[:, j], "C0", lw=1.0, label=f"fitted ({self.per_channel[c]:.3g})")
            ax.set_ylabel(c)
            ax.legend(loc="best", fontsize="small")
        axes[-1].set_xlabel("t [s]")
        return fig


def fit_params(
    model: "Model",
    run: MeasuredRun,
    params: Sequence[str],
    *,
    bounds: Optional[Mapping[str, Tuple[float, float]]] = None,
    scale: Optional[Mapping[str, float]] = None,
    x0: Optional[Mapping[str, float]] = None,
    grid: Optional[Mapping[str, Sequence[float]]] = None,
    channels: Optional[Sequence[str]] = None,
    sample_rate: Optional[float] = None,
    initial_q: Any = None,
    initial_v: Any = None,
    threads: int = 0,
    max_iter: int = 40,
    seeds: bool = True,
    starts: int = 3,
    offsets: bool = False,
) -> FitResult:
    """Fit the named effect parameters of ``model`` to the measured ``run`` (free-run
    replay of its encoders, or of its references in closed loop).

    Parameters
    ----------
    params : names ``"effect.name"`` or ``"effect.name[i]"`` (see the module docs).
    bounds : per name, ``(lower, upper)`` replacing the effect registry's range (a name
        without index applies to every entry; a (length, 2) array gives one per entry).
    scale : per name, the typical magnitude (finite-difference steps, trust-region
        scaling); default the diagnosis's table, else the start's magnitude.
    x0 : per name, the start; default the model's current values.
    grid : per name, candidate start values: their Cartesian product (the other entries at
        ``x0``) is simulated in one batched rollout and the best one starts the fit (a
        ringing response is not convex in a stiffness).
    channels, sample_rate : as :func:`popup.compare.compare`.
    initial_q, initial_v : the initial state (chain coordinates and rates, (nv,)); default
        from the run (at rest, or its ``[initial]`` table).
    max_iter : solver evaluations per start (0: the starts are evaluated, not moved; the
        result is the best start with its intervals).
    seeds : also start from the effects' seed points (:data:`popup.estimate.SEEDS`);
        every start is simulated in one batch.
    starts : the best ``starts`` starts are each fitted; the best fit is kept and
        :attr:`FitResult.warnings` says when another start ended elsewhere or the fit sits
        at a bound.
    offsets : also fit a constant offset per channel (a sensor bias), profiled out of
        every residual (:class:`~popup.problem.ReplayProblem`).
    """
    t_start = time.perf_counter()
    channels, sample_rate = _check_args(params, bounds, scale, x0, grid, channels, sample_rate, threads, max_iter, starts)
    entries = _parse(params)
    for what, d in (("bounds", bounds), ("scale", scale), ("x0", x0), ("grid", grid)):
        for k in d or {}:
            # "effect.name[i]" must be a fitted entry; "effect.name" any fitted entry of it
            if not any(key == k or ("[" not in k and key.rsplit("[", 1)[0] == k) for _, _, key in entries):
                raise InputError(f"input {what}: {k!r} is not among the fitted parameters {[key for _, _, key in entries]}")
    flat = np.asarray(model.effects_flat, dtype=float).copy()
    free: List[Tuple[fx.EffectParam, int]] = []
    start, sc = [], []
    for p, i, key in entries:
        b = _lookup(bounds, key, 2)
        lo, hi = (p.lower, p.upper) if b is None else _bounds_pair(key, b)
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
            raise InputError(f"input bounds: {key}: ({lo}, {hi}) must be finite with lower < upper")
        free.append((dataclasses.replace(p, lower=lo, upper=hi), i))
        v = _lookup(x0, key, 1)
        v = float(flat[p.offset + i]) if v is None else _number("x0", key, v)
        if not np.isfinite(v):
            raise InputError(f"input x0: {key} = {v}: give a finite start (x0={{{key!r}: ...}})")
        if not lo <= v <= hi:
            raise InputError(f"input x0: {key} = {v} is outside its bounds [{lo}, {hi}]")
        start.append(v)
        s = _lookup(scale, key, 1)
        s = est.PARAM_SCALE.get((p.effect, p.name), max(abs(v), 1e-12)) if s is None else _number("scale", key, s)
        if not (np.isfinite(s) and s > 0):
            raise InputError(f"input scale: {key} = {s} must be finite and > 0")
        sc.append(s)
    x_start = np.array(start)
    prob = ReplayProblem(model, run, channels=channels, sample_rate=sample_rate, threads=threads, offsets=offsets)
    chans = prob.channels
    if initial_q is not None or initial_v is not None:
        nv = len(model.joint_names)
        iq = np.zeros(nv) if initial_q is None else np.asarray(initial_q, dtype=float)
        iv = np.zeros(nv) if initial_v is None else np.asarray(initial_v, dtype=float)
        if iq.shape != (nv,) or iv.shape != (nv,):
            raise InputError(f"input initial_q/initial_v: shapes {iq.shape}, {iv.shape}; the model has {nv} joints")
        prob = prob.with_initial_state(iq, iv)
    everything = np.ones(len(prob.time), dtype=bool)
    idx = np.array([p.offset + i for p, i in free])
    sim_before = prob.nominal_simulation()[None]
    err_before, per_before = prob.error(prob.residuals(sim_before)[0])
    # starts: the given one, the effects' seed points (multi-start), the user's grid
    cands = [x_start]
    if seeds:
        for eff in sorted({p.effect for p, _ in free}):
            for seed in est.SEEDS.get(eff, []):
                x = x_start.copy()
                for j, (p, i) in enumerate(free):
                    if p.effect == eff and p.name in seed:
                        v = seed[p.name]
                        x[j] = min(max(float(v[i]) if np.ndim(v) else float(v), p.lower), p.upper)
                if not any(np.array_equal(x, c) for c in cands):
                    cands.append(x)
    if grid:
        axes = []
        for j, (_, _, key) in enumerate(entries):
            g = _lookup(grid, key, 2)
            axes.append([x_start[j]] if g is None else [float(v) for v in np.atleast_1d(g)])
        cands.extend(np.array(c, dtype=float) for c in itertools.product(*axes))
    flats = np.repeat(flat[None], len(cands), axis=0)
    flats[:, idx] = np.array(cands)
    z = prob.residuals(prob.simulate(flats))
    obj = np.array([_objective(prob, zz, everything) for zz in z])
    order = [int(i) for i in np.argsort(obj, kind="stable") if np.isfinite(obj[i])][: max(1, int(starts))]
    if not order:
        raise InputError("fit_params: every start failed to simulate (see the model's step check); give x0= or bounds= inside the stable region")
    fits = []
    for i in order:
        out = est.fit(prob, flat, free, cands[i], max_iter, scale=np.array(sc), mask=everything)
        fits.append((_objective(prob, out.z, everything), cands[i], out))
    fits.sort(key=lambda f: f[0])
    best_obj, x_first, out = fits[0]
    x, flat_fit = out.x, out.flat
    err, per = prob.error(out.z)
    _, ne = est.log_ratio(prob, out.z, out.z, everything)
    names = [k for _, _, k in entries]
    half, ident = est.uncertainty(out, free, names, ne, scale=np.array(sc))
    warns: List[str] = []
    if ident["at_bound"]:
        warns.append(f"the best fit sits at a bound: {', '.join(ident['at_bound'])}")
    for o, x_s, other in fits[1:]:
        if np.any(np.abs(other.x - x) > np.maximum(half, 1e-3 * np.array(sc))) :
            warns.append(
                f"another start ({', '.join(f'{n}={v:.4g}' for n, v in zip(names, x_s))}) ended elsewhere "
                f"({', '.join(f'{n}={v:.4g}' for n, v in zip(names, other.x))}) with a worse likelihood "
                f"(Δ = {0.5 * (o - best_obj):.3g}): the objective has several minima; the best is kept"
            )
    by_effect: Dict[str, Dict[str, List[float]]] = {}
    for p, _ in free:
        by_effect.setdefault(p.effect, {})[p.name] = [float(v) for v in flat_fit[p.slice]]
    fitted = model.with_effects(by_effect)
    return FitResult(
        names=names,
        x0=np.asarray(x_first, dtype=float),
        x=np.asarray(x, dtype=float),
        ci95=half,
        lower=np.array([p.lower for p, _ in free]),
        upper=np.array([p.upper for p, _ in free]),
        error_before=err_before,
        error=err,
        per_channel_before=per_before,
        per_channel=per,
        model=fitted,
        channels=list(chans),
        time=np.asarray(prob.time),
        measured=np.asarray(prob.measured),
        simulated_before=sim_before[0],
        simulated=prob.simulate(flat_fit[None])[0],
        nfev=prob.nfev,
        seconds=time.perf_counter() - t_start,
        warnings=warns,
        identifiability=ident,
        noise=prob.noise,
    )


def _objective(prob: ReplayProblem, z: np.ndarray, mask: np.ndarray) -> float:
    """−2 × the profile log-likelihood (up to a constant): Σ_c n_c ln mean z_c²."""
    ms, n, _ = prob.channel_stats(z, mask)
    return float(np.sum(n * np.log(np.maximum(ms, 1e-300)))) if np.all(np.isfinite(ms)) else math.inf
