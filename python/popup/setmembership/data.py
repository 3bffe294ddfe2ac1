"""Identification data (:class:`IdData`, :func:`iddata`) read from arrays, runs and results, and the
thesis's inputs and excitation (:func:`multisine`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from ..exceptions import InputError, ParameterError
from .structure import ArrayLike, Structure, as_names


#: The thesis's inputs (chapter 3): motor angles and rates of joints 2 and 3.
THESIS_INPUTS: Tuple[str, ...] = ("q2", "dq2", "q3", "dq3")


#: The pose about which :func:`multisine` moves the arm [rad] (that of
#: :func:`popup.synth.lab_trajectory`).
LAB_POSE: Tuple[float, float, float] = (0.0, -math.pi / 2 + 0.6, 0.5)


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


def as_data(y: ArrayLike, u: ArrayLike, output: str, inputs: Sequence[str], dt: float = math.nan, t0: float = 0.0,
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
    ins = as_names(inputs, "inputs")
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
    return as_data(y, u, output, ins, dt, float(tt[0]), name, notes)


def _channel_getter(source: Any) -> Tuple[Callable[[str], np.ndarray], set, np.ndarray, str]:
    from ..io import MeasuredRun
    from ..results import SimResult

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


def resolve(data: Any, s: Structure, **kw: Any) -> IdData:
    if isinstance(data, tuple) and len(data) == 2:
        if kw:
            raise InputError(f"{sorted(kw)} apply to runs, not to (y, u) arrays")
        return as_data(data[0], data[1], s.output, s.inputs)
    return iddata(data, s.output, s.inputs, **kw)


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
