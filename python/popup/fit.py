"""Fit chosen effect parameters of a model to a measured run.

::

    run = popup.read_run("examples/data/friction_run")
    res = popup.fit_params(model, run, ["joint_friction.tau_c", "joint_friction.b"])
    res.params            # {'joint_friction.tau_c[0]': 0.41, ...}
    res.to_pandas()       # start, fitted, 95 % half width, bounds per parameter
    res.model             # the model with the fitted values
    res.plot()            # measured vs simulated before/after, per channel

The same machinery as :func:`popup.diagnose` (the free-run replay error of
:data:`popup.diagnosis.ERROR_DEFINITION`, bounded trust-region-reflective least squares,
forward-difference Jacobians as one batched rollout, Gauss–Newton 95 % intervals inflated
for residual correlation), for any parameters of any effects, including those the
diagnosis does not fit by default (structural settings excepted: they change the chain)
and with the user's own bounds, typical scales, start, seed grid and initial state.

A parameter is named ``"effect.name"`` (every entry: per joint or per link) or
``"effect.name[i]"`` (one entry, 0-based), e.g. ``"higher_bending_modes.e_pa[1]"``, the
Young's modulus of link 2's beam.
"""

from __future__ import annotations

import dataclasses
import itertools
import re
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from . import effects as fx
from .exceptions import InputError
from .io import MeasuredRun

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
        return v[int(i[:-1])] if np.ndim(v) == per_entry_ndim else v
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
    """Overall error (:data:`popup.diagnosis.ERROR_DEFINITION`) of the model as given."""
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


def _ci95(r: np.ndarray, J: np.ndarray, n_eff: float) -> np.ndarray:
    """95 % half widths from the Gauss–Newton covariance s²(JᵀJ)⁻¹, s² = RSS/(n − k)
    inflated by n/n_eff (as the diagnosis's intervals)."""
    n, k = r.size, J.shape[1]
    s2 = float(np.sum(r * r)) / max(n - k, 1) * max(n / n_eff, 1.0)
    try:
        return 1.96 * np.sqrt(np.clip(np.diag(s2 * np.linalg.pinv(J.T @ J)), 0.0, None))
    except np.linalg.LinAlgError:
        return np.full(k, np.inf)


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
    """
    from . import diagnosis as dg

    t_start = time.perf_counter()
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
        lo, hi = (p.lower, p.upper) if b is None else (float(b[0]), float(b[1]))
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
            raise InputError(f"input bounds: {key}: ({lo}, {hi}) must be finite with lower < upper")
        free.append((dataclasses.replace(p, lower=lo, upper=hi), i))
        v = _lookup(x0, key, 1)
        v = float(flat[p.offset + i]) if v is None else float(v)
        if not np.isfinite(v):
            raise InputError(f"input x0: {key} = {v}: give a finite start (x0={{{key!r}: ...}})")
        if not lo <= v <= hi:
            raise InputError(f"input x0: {key} = {v} is outside its bounds [{lo}, {hi}]")
        start.append(v)
        s = _lookup(scale, key, 1)
        s = dg._SCALE.get((p.effect, p.name), max(abs(v), 1e-12)) if s is None else float(s)
        if not (np.isfinite(s) and s > 0):
            raise InputError(f"input scale: {key} = {s} must be finite and > 0")
        sc.append(s)
    x_start = np.array(start)
    cmp, chans, sr = dg._prepare(model, run, channels, sample_rate)
    prob = dg._Problem(model, run, chans, sr, threads)
    if initial_q is not None or initial_v is not None:
        nv = len(model.joint_names)
        iq = np.zeros(nv) if initial_q is None else np.asarray(initial_q, dtype=float)
        iv = np.zeros(nv) if initial_v is None else np.asarray(initial_v, dtype=float)
        if iq.shape != (nv,) or iv.shape != (nv,):
            raise InputError(f"input initial_q/initial_v: shapes {iq.shape}, {iv.shape}; the model has {nv} joints")
        prob.iq, prob.iv = iq, iv
    idx = np.array([p.offset + i for p, i in free])
    sim_before = prob.simulate(flat[None])
    err_before, per_before = prob.error(prob.residuals(sim_before)[0])
    if grid:
        axes = []
        for j, (_, _, key) in enumerate(entries):
            g = _lookup(grid, key, 2)
            axes.append([x_start[j]] if g is None else [float(v) for v in np.atleast_1d(g)])
        cands = np.array(list(itertools.product(*axes)))
        flats = np.repeat(flat[None], len(cands), axis=0)
        flats[:, idx] = cands
        r = prob.residuals(prob.simulate(flats))
        rss = np.array([float(np.sum(rr * rr)) for rr in r])
        x_start = cands[int(np.nanargmin(np.where(np.isfinite(rss), rss, np.inf)))]
    x, flat_fit, r, J = dg._fit(prob, flat, free, x_start, max_iter, scale=np.array(sc))
    err, per = prob.error(r)
    half = _ci95(r, J, prob.n_eff(r))
    by_effect: Dict[str, Dict[str, List[float]]] = {}
    for p, _ in free:
        by_effect.setdefault(p.effect, {})[p.name] = [float(v) for v in flat_fit[p.slice]]
    fitted = model.with_effects(by_effect)
    return FitResult(
        names=[k for _, _, k in entries],
        x0=x_start,
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
        time=np.asarray(prob.t_meas),
        measured=np.asarray(prob.Y),
        simulated_before=sim_before[0],
        simulated=prob.simulate(flat_fit[None])[0],
        nfev=prob.nfev,
        seconds=time.perf_counter() - t_start,
    )
