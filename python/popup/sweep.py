"""Sweeps and robustness studies: many closed-loop runs of one scenario, from one laptop to a
cluster (``docs/sweeps.md``).

A sweep varies keys of a **scenario** (the TOML format of ``popup run`` / ``popup sweep``,
:class:`popup.Scenario`, ``docs/logging.md``) and runs every variant closed loop. Parameter
names are the scenario's key paths, the same as ``popup sweep --param``: ``payload_kg``,
``pressure_pa`` (both links) or ``pressure_pa[1]`` (link 2, 0-based), ``q0[1]`` (initial
pose), ``controller.gains.damp_kp`` (every joint) or ``controller.gains.vel_kp[2]`` (when the
scenario gives the array), ``effects.joint_friction.tau_c``, ``phases[0].track[2].to``
(a reference amplitude), ``duration_s``, ``dt``, ``seed``... Every variant is checked by the
core's scenario checker before anything runs; a bad name raises
:class:`UnknownParameterError`, a bad value :class:`popup.ScenarioError` naming the run.

Three designs, combinable (their product, the grid outermost, Monte Carlo innermost)::

    import popup
    from popup.sweep import sweep
    sc = popup.Scenario.read("examples/scenarios/pick_and_place.toml")
    res = sweep(sc, grid={"payload_kg": [0, 1, 2], "pressure_pa": [30e3, 50e3]}, duration=5)
    res = sweep(sc, points={"payload_kg": [0, 1], "q0[1]": [0.5, 0.7]})          # explicit list
    res = sweep(sc, distributions={"payload_kg": ("uniform", 0, 2.5),
                                   "pressure_pa": scipy.stats.norm(40e3, 2e3)}, n=200, seed=7)
    res.to_pandas()      # one row per run: the parameters and scalar metrics (METRICS)
    res.plot("peak_moment_ratio")                      # vs a parameter / heat map / histogram

Runs without sensor noise are run in Rust batches (``_core.closed_loop_rollout``: GIL
released, rayon on ``threads`` threads, 0 = all cores); runs whose scenario has sensor noise
run one by one through the scenario runner (seeded noise, as ``popup run``). Results are
bit-identical for any ``threads``, any ``batch_size`` and on any executor: each run is
independent and its metrics are computed from its own arrays.

**Beyond one machine**: ``executor=`` takes any :class:`concurrent.futures.Executor` (a
``ProcessPoolExecutor`` with the ``spawn`` context, a ``dask.distributed`` client's
``client.get_executor(pure=False)``, or the ``Client`` itself). Each task is
:func:`run_chunk` with plain data (the arm file text, model options, the control TOML text,
and the chunk's parameter rows as arrays); the worker builds the model, runs the chunk with
``threads_per_worker`` rayon threads (default 1: one process per core, no oversubscription)
and returns plain arrays.

Units are SI: kg, Pa, rad, s, m, N·m. Metric definitions: :data:`METRICS`.
"""

from __future__ import annotations

import concurrent.futures as cf
import copy
import itertools
import json
import math
import os
import socket
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import tomli_w

from . import _core
from . import effects as fx
from .control import CONTROL_CHANNELS, Event, gains_to_flat
from .exceptions import InputError, PopupError, ScenarioError
from .results import CHANNELS, WrinkleAlarm
from .scenario import Scenario

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

if TYPE_CHECKING:
    import pandas as pd

    from .control import Task
    from .model import Model

__all__ = [
    "SweepError",
    "UnknownParameterError",
    "METRICS",
    "CLI_COLUMNS",
    "MetricOptions",
    "Series",
    "SweepResult",
    "RobustnessRegion",
    "sweep",
    "robustness",
    "scenario_from_task",
    "run_chunk",
]


# ---------------------------------------------------------------- errors
class SweepError(InputError):
    """A sweep is specified wrongly: an empty grid, lists of different lengths, a bad
    distribution, a bad option. A :class:`popup.InputError`, so also a
    :class:`popup.PopupError` and a ``ValueError``."""


class UnknownParameterError(SweepError, LookupError):
    """A swept parameter name that is not a key of the scenario format (or cannot be set in
    this scenario). Also a ``LookupError``."""


# ---------------------------------------------------------------- metrics
#: Scalar metrics of one run: name -> (unit, definition). The first block is computed exactly
#: as ``popup sweep`` computes its ``summary.csv`` columns (same names, same values bit for
#: bit on runs without sensor noise); the rest are popup.sweep's own.
METRICS: Dict[str, Tuple[str, str]] = {
    "t_end": ("s", "time of the last finite sample"),
    "samples": ("1", "number of finite samples"),
    "peak_m1_ratio": ("1", "peak |M|/M_w of link 1 (bending moment over the wrinkling moment)"),
    "peak_m2_ratio": ("1", "peak |M|/M_w of link 2"),
    "rms_track_q1": ("rad", "RMS position tracking error ref_q1 − q1 over the run"),
    "rms_track_q2": ("rad", "RMS position tracking error ref_q2 − q2 over the run"),
    "rms_track_q3": ("rad", "RMS position tracking error ref_q3 − q3 over the run"),
    "peak_tau1": ("N·m", "peak |tau1| (joint-output torque channel)"),
    "peak_tau2": ("N·m", "peak |tau2|"),
    "peak_tau3": ("N·m", "peak |tau3|"),
    "ee_x": ("m", "final end-effector position, x (base frame W)"),
    "ee_y": ("m", "final end-effector position, y"),
    "ee_z": ("m", "final end-effector position, z"),
    "wrinkle_alarms": ("1", "wrinkling-alarm episodes (|M| rising above M_w)"),
    "faults": ("1", "fault events of the task state machine"),
    # popup.sweep's own
    "peak_moment_ratio": ("1", "max(peak_m1_ratio, peak_m2_ratio): peak |M|/M_w of the arm"),
    "rms_track_rad": ("rad", "RMS tracking error over the three motor joints together"),
    "peak_bending_rad": ("rad", "peak |d| over the four bending angles d11 d12 d21 d22"),
    "rms_bending_rad": ("rad", "RMS of the four bending angles together (static sag included)"),
    "rms_vib_bending_rad": ("rad", "RMS of the bending angles minus their final value (mean over the last vib_window_s): the vibration alone"),
    "peak_tip_accel_ms2": ("m/s²", "peak |f2(t) − f2(0)|, f2 the specific force of IMU 2 (tip of link 2)"),
    "settling_s": (
        "s",
        "end-effector settling time after settle_from_s: until |ee − ee_f| stays below max(settle_tol_rel·|ee_f − ee(settle_from_s)|, "
        "settle_tol_abs_m), ee_f the mean over the last settle_window_s; NaN if it is not in that band for at least settle_min_in_band_s "
        "before the end",
    ),
}
_METRIC_NAMES: List[str] = list(METRICS)
_NM = len(_METRIC_NAMES)
_MI = {n: i for i, n in enumerate(_METRIC_NAMES)}

#: The columns of ``popup sweep``'s ``summary.csv`` that :meth:`SweepResult.to_pandas` has
#: too, with the same definitions.
CLI_COLUMNS: List[str] = ["seed", "status"] + _METRIC_NAMES[:15]

_CH = {c: i for i, c in enumerate(CHANNELS)}
_CC = {c: i for i, c in enumerate(CONTROL_CHANNELS)}
_SERIES_CHANNELS: List[str] = list(CHANNELS) + [c for c in CONTROL_CHANNELS if c not in _CH]


@dataclass(frozen=True)
class MetricOptions:
    """Options of the metrics (:data:`METRICS`) that need a definition choice.

    ``settle_from_s`` [s]: start of the move whose settling is measured (e.g. the reference
    step time); ``settle_tol_rel`` (fraction of the move) and ``settle_tol_abs_m`` [m]: the band
    is the larger of the two; ``settle_window_s`` [s]: the final plateau is the mean
    end-effector position over this last window; ``settle_min_in_band_s`` [s]: the run must
    then stay in the band at least this long before it ends, else NaN (an oscillation passing
    near the plateau at the very end does not count); ``vib_window_s`` [s]: the final bending
    value subtracted for ``rms_vib_bending_rad``. Defaults as ``examples/thesis_scenarios.py``.
    """

    settle_from_s: float = 0.0
    settle_tol_rel: float = 0.02
    settle_tol_abs_m: float = 0.005
    settle_window_s: float = 0.25
    settle_min_in_band_s: float = 1.0
    vib_window_s: float = 1.0

    def __post_init__(self) -> None:
        for k, v in asdict(self).items():
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise SweepError(f"invalid metric option {k} = {v!r}: must be a finite number >= 0")


def _run_metrics(data: np.ndarray, ctrl: Optional[np.ndarray], events: Sequence[Tuple[Any, ...]], n_alarms: int, opts: MetricOptions) -> np.ndarray:
    """The :data:`METRICS` vector of one run from its sensor ``data`` (S, NCH) and controller
    ``ctrl`` (S, NCTRL) channels (NaN rows after a failure are left out)."""
    out = np.full(_NM, math.nan)
    out[_MI["wrinkle_alarms"]] = float(n_alarms)
    out[_MI["faults"]] = float(sum(1 for e in events if e[1] == "fault"))
    ok = np.isfinite(data[:, _CH["t"]]) if data.shape[0] else np.zeros(0, dtype=bool)
    n = int(ok.sum())
    out[_MI["samples"]] = float(n)
    if n == 0:
        return out
    d = data[ok]
    t = d[:, _CH["t"]]
    out[_MI["t_end"]] = t[-1]
    # the first block exactly as popup-cli's Metrics sink (sequential sums, max from 0)
    for l in range(2):
        r = d[:, _CH[f"m{l + 1}_ratio"]]
        out[_MI[f"peak_m{l + 1}_ratio"]] = max(0.0, float(np.nanmax(r))) if np.isfinite(r).any() else 0.0
    sse = np.zeros(3)
    if ctrl is not None:
        c = ctrl[ok]
        e = c[:, [_CC["ref_q1"], _CC["ref_q2"], _CC["ref_q3"]]] - d[:, [_CH["q1"], _CH["q2"], _CH["q3"]]]
        sse = np.cumsum(e * e, axis=0)[-1]
        for j in range(3):
            out[_MI[f"rms_track_q{j + 1}"]] = math.sqrt(sse[j] / n)
        out[_MI["rms_track_rad"]] = math.sqrt(float(sse.sum()) / (3 * n))
    for j in range(3):
        a = np.abs(d[:, _CH[f"tau{j + 1}"]])
        out[_MI[f"peak_tau{j + 1}"]] = max(0.0, float(np.nanmax(a))) if np.isfinite(a).any() else 0.0
    for j, k in enumerate(("ee_x", "ee_y", "ee_z")):
        out[_MI[k]] = d[-1, _CH[k]]
    out[_MI["peak_moment_ratio"]] = max(out[_MI["peak_m1_ratio"]], out[_MI["peak_m2_ratio"]])
    bend = d[:, [_CH[c] for c in ("d11", "d12", "d21", "d22")]]
    out[_MI["peak_bending_rad"]] = float(np.max(np.abs(bend)))
    out[_MI["rms_bending_rad"]] = math.sqrt(float(np.mean(bend**2)))
    final = bend[t >= t[-1] - opts.vib_window_s - 1e-12].mean(axis=0)
    out[_MI["rms_vib_bending_rad"]] = math.sqrt(float(np.mean((bend - final) ** 2)))
    imu = d[:, [_CH[c] for c in ("imu2_ax", "imu2_ay", "imu2_az")]]
    out[_MI["peak_tip_accel_ms2"]] = float(np.max(np.linalg.norm(imu - imu[:1], axis=1)))
    out[_MI["settling_s"]] = _settling(t, d[:, [_CH["ee_x"], _CH["ee_y"], _CH["ee_z"]]], opts)
    return out


def _settling(t: np.ndarray, ee: np.ndarray, o: MetricOptions) -> float:
    """Settling time [s] of the end effector after ``o.settle_from_s`` (see :data:`METRICS`)."""
    seg = t >= o.settle_from_s - 1e-9
    if not seg.any():
        return math.nan
    ts, es = t[seg], ee[seg]
    ee_f = es[ts >= ts[-1] - o.settle_window_s - 1e-12].mean(axis=0)
    tol = max(o.settle_tol_rel * float(np.linalg.norm(ee_f - es[0])), o.settle_tol_abs_m)
    out = np.flatnonzero(np.linalg.norm(es - ee_f, axis=1) >= tol)
    if out.size == 0:
        return 0.0
    if out[-1] + 1 >= len(ts):
        return math.nan
    t_in = float(ts[out[-1] + 1])
    if ts[-1] - t_in < o.settle_min_in_band_s:
        return math.nan
    return t_in - float(ts[0])


# ---------------------------------------------------------------- worker side
def _arm_of(spec: Mapping[str, Any]) -> "_core.Arm":
    if "builtin" in spec:
        return _core.Arm.builtin(spec["builtin"])
    return _core.Arm.from_toml(spec["toml"], spec.get("source", "<arm>"))


def run_chunk(config: Mapping[str, Any], chunk: Mapping[str, Any]) -> Dict[str, Any]:
    """Run one chunk of a sweep and return plain arrays: the worker-side entry point.

    ``config`` (one per group of runs that share the compiled model and the task) and
    ``chunk`` (the runs) hold only plain data (str, float, lists, numpy arrays), so any
    executor can ship them: ``config["kind"]`` is ``"batch"`` (keys ``arm`` {``builtin``:
    name} or {``toml``: text, ``source``}, ``effects`` (the scenario's ``[effects.*]`` tables
    of the group's first run: they fix the compiled structure; every run's own values are in
    its flat effect vector),
    ``dt`` [s], ``integrator``, ``gravity``, ``task`` (control TOML text), ``duration`` [s],
    ``sample_rate`` [Hz]; chunk keys ``runs``, ``payload_kg`` (B,), ``pressure_pa`` (B, 2),
    ``q0`` (B, 3), ``gains`` (B, NG), ``effects`` (B, NE)) or ``"scenario"`` (runs with
    sensor noise: ``arm`` as above, ``arm_name``; chunk keys ``runs``, ``texts``), and both
    ``series`` (channel names or None), ``metrics`` (:class:`MetricOptions` fields),
    ``threads``.

    Returns ``runs``, ``metrics`` (B, len(METRICS)), ``status``, ``errors``, ``events``,
    ``alarms``, ``warnings`` (per run), ``series`` ((B, S, C) or None), ``host``, ``pid``,
    ``wall_s``, ``popup_version``.
    """
    t0 = time.perf_counter()
    opts = MetricOptions(**config["metrics"])
    series: Optional[List[str]] = config.get("series")
    threads = int(config.get("threads", 1))
    runs = [int(r) for r in chunk["runs"]]
    if config["kind"] == "batch":
        out = _run_batch(config, chunk, threads)
    elif config["kind"] == "scenario":
        out = _run_scenarios(config, chunk, threads)
    else:
        raise SweepError(f"run_chunk: unknown chunk kind {config['kind']!r}")
    data, ctrl, errors, events, status, alarms, warns = out
    metrics = np.full((len(runs), _NM), math.nan)
    for b in range(len(runs)):
        if errors[b] is None:
            metrics[b] = _run_metrics(data[b], None if ctrl[b] is None else ctrl[b], events[b], len(alarms[b]), opts)
    ser = None
    if series is not None:
        idx = [(_CH[c], None) if c in _CH else (None, _CC[c]) for c in series]
        ns = max((0 if d is None else d.shape[0]) for d in data) if runs else 0
        ser = np.full((len(runs), ns, len(series)), math.nan)
        for b in range(len(runs)):
            if data[b] is None:
                continue
            s = data[b].shape[0]
            for k, (i, j) in enumerate(idx):
                if i is not None:
                    ser[b, :s, k] = data[b][:, i]
                elif ctrl[b] is not None:
                    ser[b, :s, k] = ctrl[b][:, j]
    return {
        "runs": runs,
        "metrics": metrics,
        "status": status,
        "errors": errors,
        "events": [[tuple(e) for e in ev] for ev in events],
        "alarms": [[tuple(a) for a in al] for al in alarms],
        "warnings": [list(w) for w in warns],
        "series": ser,
        "host": socket.gethostname(),
        "pid": os.getpid(),
        "wall_s": time.perf_counter() - t0,
        "popup_version": _core.__version__,
    }


_Out = Tuple[List[Any], List[Any], List[Optional[str]], List[List[Any]], List[str], List[List[Any]], List[List[str]]]


def _run_batch(config: Mapping[str, Any], chunk: Mapping[str, Any], threads: int) -> _Out:
    arm = _arm_of(config["arm"])
    if config.get("effects"):
        arm = arm.with_overrides({"effects": config["effects"]})
    model = _core.Model(arm, dt=float(config["dt"]), integrator=str(config["integrator"]), disable=[] if config["gravity"] else ["gravity"])
    f64 = lambda k: np.ascontiguousarray(np.asarray(chunk[k], dtype=np.float64))  # noqa: E731
    data, ctrl, errors, events, status, alarms, warns = _core.closed_loop_rollout(
        model,
        config["task"],
        f64("payload_kg"),
        f64("pressure_pa"),
        f64("q0"),
        float(config["duration"]),
        1.0 / float(config["sample_rate"]),
        f64("gains"),
        f64("effects"),
        threads,
        True,
        "<sweep task>",
    )
    data = np.asarray(data)
    ctrl = np.asarray(ctrl)
    nb = len(chunk["runs"])
    errs = [None if e is None else f"{e[0]}: {e[1]}" for e in errors]
    return (
        [data[b] for b in range(nb)],
        [ctrl[b] for b in range(nb)],
        errs,
        [list(e) for e in events],
        [s if errs[b] is None else "error" for b, s in enumerate(status)],
        [list(a) for a in alarms],
        [list(w) for w in warns],
    )


_EPISODE_EVENTS = ("wrinkle_start", "wrinkle_end")


def _run_scenarios(config: Mapping[str, Any], chunk: Mapping[str, Any], threads: int) -> _Out:
    texts: List[str] = list(chunk["texts"])
    tmp: Optional[tempfile.TemporaryDirectory] = None  # type: ignore[type-arg]
    base_dir = "."
    if "toml" in config["arm"]:
        # the arm file travels as text: write it next to a rewritten scenario on this machine
        tmp = tempfile.TemporaryDirectory(prefix="popup-sweep-")
        base_dir = tmp.name
        Path(base_dir, "arm.toml").write_text(config["arm"]["toml"])
        re = []
        for tx in texts:
            d = tomllib.loads(tx)
            d["arm"] = "arm.toml"
            re.append(tomli_w.dumps(d))
        texts = re

    def one(tx: str) -> Tuple[Any, ...]:
        try:
            st, data, ctrl, events, alarms, warns, _nonfinite = _core.run_scenario(tx, "<sweep scenario>", base_dir, None, None, None)
            # the wrinkling episodes are in `alarms`; the batched runs' logs do not repeat them
            ev = [e for e in events if e[1] not in _EPISODE_EVENTS]
            return np.asarray(data), np.asarray(ctrl), None, ev, str(st), list(alarms), list(warns)
        except PopupError as e:
            return None, None, f"{type(e).__name__}: {e}", [], "error", [], []

    try:
        n = len(texts)
        workers = (os.cpu_count() or 1) if threads == 0 else max(1, threads)
        if workers > 1 and n > 1:
            with cf.ThreadPoolExecutor(max_workers=min(workers, n)) as pool:  # run_scenario releases the GIL
                res = list(pool.map(one, texts))
        else:
            res = [one(tx) for tx in texts]
    finally:
        if tmp is not None:
            tmp.cleanup()
    cols: List[List[Any]] = [list(c) for c in zip(*res)] if res else [[] for _ in range(7)]
    return tuple(cols)  # type: ignore[return-value]


# ---------------------------------------------------------------- designs
_DIST_NAMES = ("uniform", "normal", "lognormal", "loguniform", "triangular", "choice", "integers")


def _sampler(name: str, spec: Any) -> Callable[[int, np.random.Generator], np.ndarray]:
    """A function (n, rng) -> n samples for a distribution ``spec``: a scipy.stats frozen
    distribution (anything with ``.rvs(size=, random_state=)``), or ``(name, *args)``."""
    if hasattr(spec, "rvs") and callable(spec.rvs):
        return lambda n, rng: np.asarray(spec.rvs(size=n, random_state=rng), dtype=np.float64).reshape(n)
    if not isinstance(spec, (tuple, list)) or not spec or not isinstance(spec[0], str):
        raise SweepError(
            f"distribution of {name!r}: expected a scipy.stats frozen distribution or a tuple (name, *args) with name one of "
            f"{', '.join(_DIST_NAMES)}; got {spec!r}"
        )
    kind, args = spec[0], list(spec[1:])

    def need(k: int, what: str) -> List[float]:
        if len(args) != k:
            raise SweepError(f"distribution of {name!r}: ({kind!r}, {what}) takes {k} arguments, got {len(args)}: {spec!r}")
        try:
            v = [float(a) for a in args]
        except (TypeError, ValueError):
            raise SweepError(f"distribution of {name!r}: arguments of {kind!r} must be numbers, got {spec!r}") from None
        if not all(math.isfinite(x) for x in v):
            raise SweepError(f"distribution of {name!r}: arguments must be finite, got {spec!r}")
        return v

    if kind == "uniform":
        lo, hi = need(2, "low, high")
        if not lo < hi:
            raise SweepError(f"distribution of {name!r}: uniform needs low < high, got {spec!r}")
        return lambda n, rng: rng.uniform(lo, hi, n)
    if kind == "normal":
        mu, sd = need(2, "mean, std")
        if not sd > 0:
            raise SweepError(f"distribution of {name!r}: normal needs std > 0, got {spec!r}")
        return lambda n, rng: rng.normal(mu, sd, n)
    if kind == "lognormal":
        mu, sg = need(2, "mean, sigma of log")
        if not sg > 0:
            raise SweepError(f"distribution of {name!r}: lognormal needs sigma > 0, got {spec!r}")
        return lambda n, rng: rng.lognormal(mu, sg, n)
    if kind == "loguniform":
        lo, hi = need(2, "low, high")
        if not 0 < lo < hi:
            raise SweepError(f"distribution of {name!r}: loguniform needs 0 < low < high, got {spec!r}")
        return lambda n, rng: np.exp(rng.uniform(math.log(lo), math.log(hi), n))
    if kind == "triangular":
        a, m, b = need(3, "left, mode, right")
        if not (a <= m <= b and a < b):
            raise SweepError(f"distribution of {name!r}: triangular needs left <= mode <= right, left < right, got {spec!r}")
        return lambda n, rng: rng.triangular(a, m, b, n)
    if kind == "integers":
        lo, hi = need(2, "low, high (inclusive)")
        if not (lo == int(lo) and hi == int(hi) and lo <= hi):
            raise SweepError(f"distribution of {name!r}: integers needs whole numbers low <= high, got {spec!r}")
        return lambda n, rng: rng.integers(int(lo), int(hi), n, endpoint=True).astype(np.float64)
    if kind == "choice":
        if len(args) != 1:
            raise SweepError(f"distribution of {name!r}: ('choice', values) takes one list of values, got {spec!r}")
        vals = _values(name, args[0])
        return lambda n, rng: vals[rng.integers(0, len(vals), n)]
    raise SweepError(f"distribution of {name!r}: unknown distribution {kind!r}; known: {', '.join(_DIST_NAMES)} (or a scipy.stats frozen distribution)")


def _values(name: str, v: Any) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        raise SweepError(f"values of {name!r}: expected numbers, got {v!r}") from None
    if a.ndim == 0:
        a = a.reshape(1)
    if a.ndim != 1:
        raise SweepError(f"values of {name!r}: expected a 1-D list of numbers, got shape {a.shape}")
    if a.size == 0:
        raise SweepError(f"values of {name!r}: empty: give at least one value")
    if not np.all(np.isfinite(a)):
        raise SweepError(f"values of {name!r}: every value must be finite, got {a.tolist()}")
    return a


@dataclass
class _Design:
    names: List[str]
    rows: np.ndarray  # (N, K)
    sample: Optional[np.ndarray]  # (N,) Monte Carlo draw index
    kind: str
    grid: Dict[str, np.ndarray]
    points: Dict[str, np.ndarray]
    seed: Optional[int]
    n: Optional[int]
    distributions: Dict[str, str]


def _design(grid: Optional[Mapping[str, Any]], points: Optional[Mapping[str, Any]], distributions: Optional[Mapping[str, Any]], n: Optional[int], seed: Optional[int]) -> _Design:
    for nm, m in (("grid", grid), ("points", points), ("distributions", distributions)):
        if m is not None and not isinstance(m, Mapping):
            raise SweepError(f"{nm}: expected a mapping {{parameter name: ...}}, got {type(m).__name__}")
    g = {str(k): _values(k, v) for k, v in (grid or {}).items()}
    p = {str(k): _values(k, v) for k, v in (points or {}).items()}
    dists = dict(distributions or {})
    if not g and not p and not dists:
        raise SweepError("empty sweep: give grid={name: values}, points={name: values} and/or distributions={name: spec} with n=")
    seen: Dict[str, str] = {}
    for nm, keys in (("grid", g), ("points", p), ("distributions", dists)):
        for k in keys:
            if not isinstance(k, str) or not k.strip():
                raise SweepError(f"{nm}: parameter names must be non-empty strings, got {k!r}")
            if k in seen:
                raise SweepError(f"parameter {k!r} is given twice (in {seen[k]} and {nm})")
            seen[k] = nm
    if p:
        lens = {k: len(v) for k, v in p.items()}
        if len(set(lens.values())) > 1:
            raise SweepError(f"points: every parameter needs the same number of values (one per run), got lengths {lens}")
    if dists:
        if n is None or isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise SweepError(f"distributions need n = the number of Monte Carlo draws (an integer >= 1), got n={n!r}")
        if seed is None:
            seed = int(np.random.SeedSequence().entropy) % (2**63)  # type: ignore[arg-type]  # drawn now, stored with the results
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise SweepError(f"seed must be an integer >= 0, got {seed!r}")
        samplers = {k: _sampler(k, s) for k, s in dists.items()}
        rng = np.random.default_rng(int(seed))
        mc = {}
        for k, f in samplers.items():  # in the order given
            v = f(int(n), rng)
            if v.shape != (int(n),) or not np.all(np.isfinite(v)):
                raise SweepError(f"distribution of {k!r}: draws must be {n} finite numbers, got {v[:5]!r}...")
            mc[k] = v
    elif n is not None or seed is not None:
        raise SweepError("n= and seed= are for the Monte Carlo draws: give distributions= too (or leave them out)")
    axes: List[Tuple[List[str], np.ndarray]] = []  # (names, (len, k) values) outermost first
    for k, v in g.items():
        axes.append(([k], v[:, None]))
    if p:
        axes.append((list(p), np.stack(list(p.values()), axis=1)))
    if dists:
        axes.append((list(mc), np.stack(list(mc.values()), axis=1)))
    names = [k for nm, _ in axes for k in nm]
    idx = list(itertools.product(*[range(a.shape[0]) for _, a in axes]))
    rows = np.array([np.concatenate([a[i] for (_, a), i in zip(axes, ix)]) for ix in idx], dtype=np.float64).reshape(len(idx), len(names))
    sample = np.array([ix[-1] for ix in idx], dtype=np.int64) if dists else None
    kinds = [k for k, on in (("grid", g), ("points", p), ("monte_carlo", dists)) if on]
    desc = {k: (repr(s) if not hasattr(s, "rvs") else _describe_frozen(s)) for k, s in dists.items()}
    return _Design(names, rows, sample, "+".join(kinds), g, p, None if not dists else int(seed), None if not dists else int(n), desc)  # type: ignore[arg-type]


def _describe_frozen(d: Any) -> str:
    name = getattr(getattr(d, "dist", None), "name", type(d).__name__)
    return f"scipy.stats.{name}(args={tuple(getattr(d, 'args', ()))}, kwds={dict(getattr(d, 'kwds', {}))})"


# ---------------------------------------------------------------- scenario -> jobs
_BATCHABLE_TOP = ("payload_kg", "pressure_pa", "q0", "effects", "seed", "noise", "log", "description", "format")


def _as_scenario(base: Any) -> Scenario:
    if isinstance(base, Scenario):
        return base
    if isinstance(base, Mapping):
        return Scenario.from_dict(dict(base))
    if isinstance(base, (str, os.PathLike)):
        s = os.fspath(base)
        if "\n" not in s and (s.endswith(".toml") or os.path.exists(s)):
            return Scenario.read(s)
        return Scenario.from_toml(s)
    raise SweepError(f"base: expected a popup.Scenario, a scenario file path, TOML text or a dict; got {type(base).__name__}")


def _noisy(d: Mapping[str, Any]) -> bool:
    return any(float(v) != 0.0 for v in dict(d.get("noise", {})).values())


def _arm_effects(effects: Mapping[str, Mapping[str, Any]]) -> Dict[str, Dict[str, Any]]:
    """A scenario's ``[effects.*]`` tables in the arm-file form (scalars broadcast to per-joint
    / per-link arrays, one-value parameters as numbers), as :meth:`popup.Model.with_effects`."""
    out: Dict[str, Dict[str, Any]] = {}
    for name, params in effects.items():
        out[name] = {}
        for k, v in fx.normalize(name, params).items():
            out[name][k] = float(v[0]) if len(v) == 1 else [float(x) for x in v]
    return out


class _Planner:
    """Turns checked variant scenarios into groups of batchable runs (one compiled model and
    one control text per group) and per-run vectors."""

    def __init__(self, sc: Scenario) -> None:
        self.sc = sc
        self._arms: Dict[str, Tuple[Dict[str, Any], "_core.Arm", Dict[str, Any]]] = {}
        self._base_gains: Dict[Tuple[str, str], np.ndarray] = {}

    def arm(self, name: str) -> Tuple[Dict[str, Any], "_core.Arm", Dict[str, Any]]:
        """(plain spec, Arm, parsed arm TOML) of the scenario's ``arm`` value."""
        if name not in self._arms:
            if name in _core.Arm.builtin_names():
                spec: Dict[str, Any] = {"builtin": name}
            else:
                p = Path(self.sc.base_dir, name)
                spec = {"toml": p.read_text(), "source": str(p)}
            arm = _arm_of(spec)
            self._arms[name] = (spec, arm, tomllib.loads(arm.to_toml()))
        return self._arms[name]

    def job(self, d: Dict[str, Any]) -> Tuple[str, Dict[str, Any], Dict[str, Any]]:
        """(group key, group config, this run's vectors) of one variant ``d``."""
        arm_name = str(d.get("arm", "popup-lab"))
        spec, arm, ad = self.arm(arm_name)
        ctrl = dict(d.get("controller", {}))
        rate = float(ctrl.get("rate_hz", 10_000.0))
        dt = float(d["dt"]) if "dt" in d else 1.0 / rate
        gains = dict(ctrl.pop("gains", {}))
        ctl: Dict[str, Any] = {k: d[k] for k in ("faults", "obstacles", "payload_radius_m", "phases") if k in d}
        ctl["controller"] = ctrl
        if not ctl.get("phases"):
            ctl["phases"] = [{"kind": "phase", "name": "Holding", "hold": True}]
        task = tomli_w.dumps(ctl)
        arm_fx = fx.to_flat(ad.get("effects", {}))
        scen_fx = _arm_effects(d.get("effects", {}))
        flat = fx.to_flat(scen_fx, base=arm_fx)
        hbm = fx.EFFECTS["higher_bending_modes"].params["segments"].slice
        kt = fx.EFFECTS["torsion"].params["k_t"].slice
        struct = [float(x) for x in flat[hbm]] + [bool(np.isfinite(x)) for x in flat[kt]]
        gravity = bool(d.get("gravity", True))
        integ = str(d.get("integrator", "rk4"))
        cfg = {
            "kind": "batch",
            "arm": spec,
            "effects": scen_fx,
            "dt": dt,
            "integrator": integ,
            "gravity": gravity,
            "task": task,
            "duration": float(d["duration_s"]),
            "sample_rate": float(d.get("sample_rate_hz", 100.0)),
        }
        key = json.dumps({"arm": arm_name, "struct": struct, "dt": dt, "integrator": integ, "gravity": gravity, "task": task, "duration": cfg["duration"], "sr": cfg["sample_rate"]}, sort_keys=True)
        gk = (key, arm_name)
        if gk not in self._base_gains:
            a = arm.with_overrides({"effects": scen_fx}) if scen_fx else arm
            model = _core.Model(a, dt=dt, integrator=integ, disable=[] if gravity else ["gravity"])
            self._base_gains[gk] = np.asarray(_core.check_control(model, task, "<sweep task>")[0], dtype=np.float64)
        default_p = [float(l["pressure_pa"]) for l in ad["links"]]
        pp = d.get("pressure_pa", default_p)
        pp = [float(pp)] * 2 if np.ndim(pp) == 0 else [float(x) for x in pp]
        vec = {
            "payload_kg": float(d.get("payload_kg", ad["payload"]["default_kg"])),
            "pressure_pa": pp,
            "q0": [float(x) for x in d.get("q0", [0.0, 0.0, 0.0])],
            "gains": gains_to_flat(gains, self._base_gains[gk]),
            "effects": flat,
        }
        return key, cfg, vec


# ---------------------------------------------------------------- results
@dataclass
class Series:
    """Stacked time series of a sweep: ``values[run, time, channel]`` (axes named by
    :attr:`dims`), NaN after a failed run's last sample or past a shorter run's end.
    ``time`` [s] = k / ``sample_rate_hz``; ``channels`` are sensor (:data:`popup.CHANNELS`)
    and controller (:data:`popup.control.CONTROL_CHANNELS`) names, in SI units."""

    values: np.ndarray
    time: np.ndarray
    channels: List[str]
    sample_rate_hz: float
    dims: Tuple[str, str, str] = ("run", "time", "channel")

    def channel(self, name: str) -> np.ndarray:
        """One channel, (run, time)."""
        if name not in self.channels:
            raise KeyError(f"channel {name!r} is not in this sweep's series; it has {self.channels}")
        return self.values[:, :, self.channels.index(name)]

    @property
    def shape(self) -> Tuple[int, ...]:
        """(runs, samples, channels)."""
        return tuple(self.values.shape)


@dataclass
class SweepResult:
    """The result of :func:`sweep`.

    ``table``: one row per run (column ``run``, the swept parameters by their key names,
    ``sample`` (Monte Carlo draw index) when there are distributions, ``seed`` (the scenario's
    sensor-noise seed, as ``popup sweep``), ``status`` (``completed``, ``unstable`` or
    ``error``), every :data:`METRICS` column (float; NaN for a failed run) and ``error``
    (None or the message)). ``params``: the swept names; ``kind``: ``grid``, ``points``,
    ``monte_carlo`` or a ``+``-joined mix; ``grid``: the grid axes {name: values} in
    order (row-major, the last varying fastest, as ``popup sweep``); ``seed``: the Monte
    Carlo seed (drawn and stored when not given); ``distributions``: their description;
    ``series``: stacked time series when asked; ``events``, ``alarms``, ``warnings``: per
    run; ``scenario``: the base scenario text; ``info``: how it ran (wall time, threads,
    batch size, executor, chunks, hosts) — not part of the results' identity.
    """

    table: "pd.DataFrame"
    params: List[str]
    kind: str
    grid: Dict[str, np.ndarray]
    seed: Optional[int]
    n_samples: Optional[int]
    distributions: Dict[str, str]
    series: Optional[Series]
    events: List[List[Event]]
    alarms: List[List[WrinkleAlarm]]
    warnings: List[List[str]]
    scenario: str
    info: Dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(len(self.table))

    @property
    def metrics(self) -> List[str]:
        """Names of the metric columns (:data:`METRICS`)."""
        return list(_METRIC_NAMES)

    @property
    def ok(self) -> np.ndarray:
        """Boolean mask of the runs that completed."""
        return (self.table["status"] == "completed").to_numpy()

    def metric(self, name: str) -> np.ndarray:
        """One metric per run, (N,)."""
        if name not in METRICS:
            raise UnknownParameterError(f"unknown metric {name!r}; metrics are {_METRIC_NAMES}")
        return self.table[name].to_numpy(dtype=np.float64)

    def to_pandas(self) -> "pd.DataFrame":
        """The table (a copy) with ``attrs``: params, kind, seed, distributions, units."""
        df = self.table.copy()
        df.attrs.update({"params": list(self.params), "kind": self.kind, "seed": self.seed, "distributions": dict(self.distributions), "units": {k: u for k, (u, _) in METRICS.items()}})
        return df

    def grid_array(self, metric: str) -> np.ndarray:
        """A metric reshaped onto the grid axes: shape ``(len(axis0), len(axis1), ...)``, plus
        one trailing axis over the points / Monte Carlo draws when the sweep has them."""
        if not self.grid:
            raise SweepError("grid_array: this sweep has no grid axes")
        shape = tuple(len(v) for v in self.grid.values())
        a = self.metric(metric)
        inner = len(a) // int(np.prod(shape))
        return a.reshape(shape + ((inner,) if inner > 1 or self.kind != "grid" else ()))

    def plot(self, metric: str = "peak_moment_ratio", x: Optional[str] = None, y: Optional[str] = None, *, kind: Optional[str] = None, agg: str = "mean", bins: int = 30, ax: Any = None) -> Any:
        """Common views; returns the figure.

        ``kind``: ``"line"`` (metric vs parameter ``x``, one line per value of the other grid
        parameters when there are few, else ``agg`` over them), ``"heatmap"`` (two parameters
        ``x``, ``y``; cells aggregated with ``agg`` over any others), ``"hist"`` (the metric's
        distribution: Monte Carlo), ``"scatter"`` (metric vs ``x`` per run). Default: a heat
        map for two or more grid axes, a histogram for a pure Monte Carlo sweep, else a line.
        """
        from .plot import pyplot

        if metric not in METRICS:
            raise UnknownParameterError(f"unknown metric {metric!r}; metrics are {_METRIC_NAMES}")
        for nm in (x, y):
            if nm is not None and nm not in self.params:
                raise UnknownParameterError(f"plot: {nm!r} is not a swept parameter; swept: {self.params}")
        if kind is None:
            if y is not None or (x is None and len(self.grid) >= 2):
                kind = "heatmap"
            elif self.kind == "monte_carlo" and x is None:
                kind = "hist"
            elif self.kind == "monte_carlo":
                kind = "scatter"
            else:
                kind = "line"
        if kind not in ("line", "heatmap", "hist", "scatter"):
            raise SweepError(f"plot: kind must be 'line', 'heatmap', 'hist' or 'scatter', got {kind!r}")
        plt = pyplot()
        if ax is None:
            fig, ax = plt.subplots(figsize=(7, 4.5))
        else:
            fig = ax.figure
        unit = METRICS[metric][0]
        lab = f"{metric} [{unit}]"
        df = self.table
        if kind == "hist":
            v = df[metric].to_numpy(dtype=float)
            v = v[np.isfinite(v)]
            ax.hist(v, bins=bins, color="C0", alpha=0.8)
            if v.size:
                ax.axvline(float(np.mean(v)), color="k", ls="--", lw=1, label=f"mean {np.mean(v):.4g}")
                ax.legend(fontsize="small")
            ax.set_xlabel(lab)
            ax.set_ylabel("runs")
            ax.set_title(f"{metric}: {v.size} of {len(df)} runs finite" + (f", seed {self.seed}" if self.seed is not None else ""))
        elif kind == "scatter":
            xx = x or self.params[0]
            ax.scatter(df[xx], df[metric], s=12, alpha=0.7)
            ax.set_xlabel(xx)
            ax.set_ylabel(lab)
        elif kind == "heatmap":
            names = list(self.grid) if len(self.grid) >= 2 else list(self.params)
            xx = x or names[0]
            yy = y or next(n for n in names if n != xx)
            if xx == yy:
                raise SweepError("plot: a heat map needs two different parameters x and y")
            piv = df.pivot_table(index=yy, columns=xx, values=metric, aggfunc=agg, dropna=False)
            xs, ys, z = piv.columns.to_numpy(dtype=float), piv.index.to_numpy(dtype=float), piv.to_numpy(dtype=float)
            im = ax.pcolormesh(_edges(xs), _edges(ys), np.ma.masked_invalid(z), shading="flat", cmap="viridis")
            fig.colorbar(im, ax=ax, label=lab)
            if z.size <= 225:
                for i, yv in enumerate(ys):
                    for j, xv in enumerate(xs):
                        if np.isfinite(z[i, j]):
                            ax.text(xv, yv, f"{z[i, j]:.3g}", ha="center", va="center", fontsize=7, color="w")
            ax.set_xlabel(xx)
            ax.set_ylabel(yy)
            ax.set_title(metric + (f" ({agg} over {', '.join(n for n in self.params if n not in (xx, yy))})" if len(self.params) > 2 else ""))
        else:
            xx = x or (list(self.grid) or self.params)[0]
            others = [n for n in (list(self.grid) + list(self.params)) if n != xx]
            others = list(dict.fromkeys(others))
            combos = df.groupby(others, sort=True) if others else None
            if combos is not None and combos.ngroups <= 10:
                for key, sub in combos:
                    key = key if isinstance(key, tuple) else (key,)
                    s = sub.sort_values(xx)
                    ax.plot(s[xx], s[metric], "o-", ms=4, label=", ".join(f"{n}={v:g}" for n, v in zip(others, key)))
                ax.legend(fontsize="small")
            else:
                s = df.groupby(xx)[metric].agg(agg)
                ax.plot(s.index, s.to_numpy(), "o-", ms=4, label=agg if others else metric)
                if others:
                    ax.legend(fontsize="small")
            ax.set_xlabel(xx)
            ax.set_ylabel(lab)
        ax.grid(True, alpha=0.3)
        return fig


def _edges(c: np.ndarray) -> np.ndarray:
    """Cell edges around sorted centres (for pcolormesh)."""
    if c.size == 1:
        w = abs(c[0]) * 0.1 or 0.5
        return np.array([c[0] - w, c[0] + w])
    mid = 0.5 * (c[1:] + c[:-1])
    return np.concatenate([[c[0] - (mid[0] - c[0])], mid, [c[-1] + (c[-1] - mid[-1])]])


# ---------------------------------------------------------------- progress
class _Progress:
    def __init__(self, total: int, progress: Union[None, bool, Callable[[int, int], Any]]) -> None:
        self.total, self.done, self.t0 = total, 0, time.perf_counter()
        self.cb: Optional[Callable[[int, int], Any]] = progress if callable(progress) else None
        self.on = bool(progress) if progress is not None and not callable(progress) else (progress is None and sys.stderr.isatty())
        self.tty = sys.stderr.isatty()

    def step(self, k: int) -> None:
        self.done += k
        if self.cb is not None:
            self.cb(self.done, self.total)
        if not self.on:
            return
        el = time.perf_counter() - self.t0
        frac = self.done / max(self.total, 1)
        left = el / frac - el if frac > 0 else math.nan
        bar = "#" * int(30 * frac) + "-" * (30 - int(30 * frac))
        msg = f"sweep [{bar}] {self.done}/{self.total} runs ({100 * frac:.0f} %), {el:.1f} s, ~{left:.0f} s left, {self.done / el if el > 0 else 0:.1f} runs/s"
        if self.tty:
            sys.stderr.write("\r" + msg + ("\n" if self.done >= self.total else ""))
        else:
            sys.stderr.write(msg + "\n")
        sys.stderr.flush()


# ---------------------------------------------------------------- the sweep
def _ncores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover
        return os.cpu_count() or 1


def _as_executor(executor: Any) -> Any:
    if executor is None:
        return None
    if hasattr(executor, "get_executor") and type(executor).__name__ == "Client":
        return executor.get_executor(pure=False)  # dask.distributed: one task per chunk, never cached
    if not hasattr(executor, "submit"):
        raise SweepError(f"executor: expected a concurrent.futures.Executor (with .submit) or a dask.distributed Client, got {type(executor).__name__}")
    return executor


def sweep(
    base: Any,
    *,
    grid: Optional[Mapping[str, Any]] = None,
    points: Optional[Mapping[str, Any]] = None,
    distributions: Optional[Mapping[str, Any]] = None,
    n: Optional[int] = None,
    seed: Optional[int] = None,
    duration: Optional[float] = None,
    series: Union[None, bool, Sequence[str]] = None,
    metrics: Optional[MetricOptions] = None,
    threads: int = 0,
    batch_size: Optional[int] = None,
    executor: Any = None,
    threads_per_worker: int = 1,
    timeout: Optional[float] = None,
    progress: Union[None, bool, Callable[[int, int], Any]] = None,
) -> SweepResult:
    """Run a scenario over a grid, a list of points and/or Monte Carlo draws.

    Parameters
    ----------
    base : popup.Scenario, path, TOML text or dict
        The base scenario (``docs/logging.md``; :func:`scenario_from_task` builds one from a
        :class:`popup.control.Task`).
    grid : {name: values}
        Full grid over every combination (row-major, the last name varying fastest).
    points : {name: values}
        An explicit list of runs: every name has one value per run (same lengths).
    distributions : {name: spec}, with ``n`` and ``seed``
        Monte Carlo: ``n`` draws of every name, from a scipy.stats frozen distribution or
        ``("uniform", low, high)``, ``("normal", mean, std)``, ``("lognormal", mu, sigma)``,
        ``("loguniform", low, high)``, ``("triangular", left, mode, right)``,
        ``("integers", low, high)`` (inclusive) or ``("choice", values)``, drawn in the order
        given from ``numpy.random.default_rng(seed)``. Without ``seed`` one is drawn and
        stored in the result (``.seed``), so every sweep can be repeated. Combined with a
        grid or points, the same ``n`` draws are used at every grid point (common random
        numbers).
    duration : float, optional
        Simulated time of every run [s] (overrides ``duration_s``, like ``popup sweep
        --duration``).
    series : True or list of channel names, optional
        Also return stacked time series (:class:`Series`) of these sensor/controller
        channels (True: all).
    metrics : MetricOptions, optional
        Settling and vibration metric options.
    threads : int
        Rayon threads of the local batches (0 = all cores). Ignored with ``executor``.
    batch_size : int, optional
        Runs per Rust batch (= per executor task). Default: local, 8 per thread (at least
        16); with an executor, 8. Results do not depend on it.
    executor : concurrent.futures.Executor or dask.distributed.Client, optional
        Run the chunks there (see the module docs); ``threads_per_worker`` rayon threads per
        task (default 1); ``timeout`` [s] for the whole sweep (``TimeoutError``).
    progress : bool or callable(done, total), optional
        A progress line on stderr after each batch (default: when stderr is a terminal), or
        your callback.

    Returns
    -------
    SweepResult
    """
    t_start = time.perf_counter()
    sc = _as_scenario(base)
    text = sc.text
    if duration is not None:
        if not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration > 0):
            raise SweepError(f"duration: {duration!r} s must be finite and > 0")
        text = _core.scenario_set_key(text, "duration_s", float(duration))
    des = _design(grid, points, distributions, n, seed)
    opts = metrics if metrics is not None else MetricOptions()
    if not isinstance(opts, MetricOptions):
        raise SweepError(f"metrics: expected a popup.sweep.MetricOptions, got {type(opts).__name__}")
    ser_names: Optional[List[str]] = None
    if series is True:
        ser_names = list(_SERIES_CHANNELS)
    elif series is not None and series is not False:
        if isinstance(series, str):
            series = [series]
        ser_names = [str(c) for c in series]
        bad = [c for c in ser_names if c not in _CH and c not in _CC]
        if bad or not ser_names:
            raise SweepError(f"series: unknown channel(s) {bad}; channels are {_SERIES_CHANNELS}")
    if not isinstance(threads, int) or not 0 <= threads < 2**63:
        raise SweepError(f"threads must be an integer >= 0 (0 = all cores), got {threads!r}")
    if not isinstance(threads_per_worker, int) or not 0 <= threads_per_worker < 2**63:
        raise SweepError(f"threads_per_worker must be an integer >= 0, got {threads_per_worker!r}")
    if batch_size is not None and (isinstance(batch_size, bool) or not isinstance(batch_size, (int, np.integer)) or batch_size < 1):
        raise SweepError(f"batch_size must be an integer >= 1, got {batch_size!r}")
    exe = _as_executor(executor)

    # every name is a key the scenario format knows (checked with the first value)
    for k, v in zip(des.names, des.rows[0]):
        try:
            t1 = _core.scenario_set_key(text, k, float(v))
        except PopupError as e:
            hint = " (give the whole array in the base scenario first, e.g. controller.gains.vel_kp = [5000.0, 5000.0, 5000.0])" if "missing array" in str(e) else ""
            raise UnknownParameterError(f"parameter {k!r} cannot be set in this scenario: {e}{hint}") from None
        probs = [p for p in _core.check_scenario(t1, sc.source, str(sc.base_dir)) if "unknown" in p[3]]
        if probs:
            raise UnknownParameterError(f"unknown parameter {k!r}: " + "; ".join(f"{p[2]}: {p[3]}" for p in probs))

    # every variant, checked before anything runs
    planner = _Planner(sc)
    nrun = des.rows.shape[0]
    groups: Dict[str, Tuple[Dict[str, Any], List[int], List[Dict[str, Any]]]] = {}
    noisy: List[Tuple[int, str, str]] = []
    noise_seed: List[int] = []
    for i in range(nrun):
        tx = text
        for k, v in zip(des.names, des.rows[i]):
            tx = _core.scenario_set_key(tx, k, float(v))
        probs = _core.check_scenario(tx, sc.source, str(sc.base_dir))
        if probs:
            at = ", ".join(f"{k}={v:g}" for k, v in zip(des.names, des.rows[i]))
            raise ScenarioError([(f, ln, key, f"{msg} (run {i}: {at})") for f, ln, key, msg in probs])
        d = tomllib.loads(tx)
        noise_seed.append(int(d.get("seed", 0)))
        if _noisy(d):
            noisy.append((i, tx, str(d.get("arm", "popup-lab"))))
            continue
        key, cfg, vec = planner.job(d)
        if key not in groups:
            groups[key] = (cfg, [], [])
        groups[key][1].append(i)
        groups[key][2].append(vec)

    nthreads = _ncores() if threads == 0 else threads
    bs = int(batch_size) if batch_size is not None else (8 if exe is not None else max(16, 8 * nthreads))
    worker_threads = threads_per_worker if exe is not None else threads
    common = {"series": ser_names, "metrics": asdict(opts), "threads": worker_threads}
    tasks: List[Tuple[Dict[str, Any], Dict[str, Any]]] = []
    for cfg, idx, vecs in groups.values():
        cfg = dict(cfg, **common)
        for s in range(0, len(idx), bs):
            part = vecs[s : s + bs]
            chunk = {"runs": idx[s : s + bs]}
            for k in ("payload_kg", "pressure_pa", "q0", "gains", "effects"):
                chunk[k] = np.array([v[k] for v in part], dtype=np.float64)  # type: ignore[assignment]
            tasks.append((cfg, chunk))
    if noisy:
        for an in sorted({a for _, _, a in noisy}):
            spec = planner.arm(an)[0]
            mine = [(i, tx) for i, tx, a in noisy if a == an]
            cfg = dict({"kind": "scenario", "arm": spec, "arm_name": an}, **common)
            for s in range(0, len(mine), bs):
                tasks.append((cfg, {"runs": [i for i, _ in mine[s : s + bs]], "texts": [tx for _, tx in mine[s : s + bs]]}))

    t_plan = time.perf_counter() - t_start
    prog = _Progress(nrun, progress)
    parts: List[Dict[str, Any]] = []
    if exe is None:
        for cfg, chunk in tasks:
            parts.append(run_chunk(cfg, chunk))
            prog.step(len(chunk["runs"]))
    else:
        futs = [exe.submit(run_chunk, cfg, chunk) for cfg, chunk in tasks]
        try:
            for f in cf.as_completed(futs, timeout=timeout):
                r = f.result()
                parts.append(r)
                prog.step(len(r["runs"]))
        except BaseException:
            for f in futs:
                f.cancel()
            raise

    # assemble, in run order
    met = np.full((nrun, _NM), math.nan)
    status: List[str] = [""] * nrun
    errors: List[Optional[str]] = [None] * nrun
    events: List[List[Event]] = [[] for _ in range(nrun)]
    alarms: List[List[WrinkleAlarm]] = [[] for _ in range(nrun)]
    warns: List[List[str]] = [[] for _ in range(nrun)]
    ser_parts: List[Tuple[List[int], np.ndarray]] = []
    for r in parts:
        for b, i in enumerate(r["runs"]):
            met[i] = r["metrics"][b]
            status[i] = r["status"][b]
            errors[i] = r["errors"][b]
            events[i] = [Event(*e) for e in r["events"][b]]
            alarms[i] = [WrinkleAlarm(*a) for a in r["alarms"][b]]
            warns[i] = list(r["warnings"][b])
        if r["series"] is not None:
            ser_parts.append((r["runs"], r["series"]))
    import pandas as pd

    cols: Dict[str, Any] = {"run": np.arange(nrun)}
    for j, k in enumerate(des.names):
        cols[k] = des.rows[:, j].copy()
    if des.sample is not None:
        cols["sample"] = des.sample
    if "seed" not in cols:
        cols["seed"] = np.array(noise_seed, dtype=np.int64)
    cols["status"] = status
    for j, k in enumerate(_METRIC_NAMES):
        cols[k] = met[:, j]
    cols["error"] = errors
    table = pd.DataFrame(cols)
    ser = None
    if ser_names is not None:
        srs = {c["sample_rate"] for c, _ in tasks if c["kind"] == "batch"} | {float(tomllib.loads(tx).get("sample_rate_hz", 100.0)) for _, tx, _ in noisy}
        if len(srs) > 1:
            raise SweepError(f"series: the runs have different sample rates {sorted(srs)}; sweep sample_rate_hz without series=")
        ns = max((a.shape[1] for _, a in ser_parts), default=0)
        vals = np.full((nrun, ns, len(ser_names)), math.nan)
        for runs_, a in ser_parts:
            vals[runs_, : a.shape[1]] = a
        sr = srs.pop() if srs else float(tomllib.loads(text).get("sample_rate_hz", 100.0))
        ser = Series(vals, np.arange(ns) / sr, ser_names, sr)
    hosts = sorted({f"{r['host']}:{r['pid']}" for r in parts})
    info = {
        "wall_s": time.perf_counter() - t_start,
        "plan_s": t_plan,
        "runs": nrun,
        "chunks": len(tasks),
        "batch_size": bs,
        "threads": worker_threads,
        "executor": None if exe is None else type(exe).__module__ + "." + type(exe).__name__,
        "workers": hosts,
        "batched_runs": nrun - len(noisy),
        "scenario_runs": len(noisy),
        "popup_version": _core.__version__,
        "worker_versions": sorted({r["popup_version"] for r in parts}),
        "simulated_s": float(np.nansum(met[:, _MI["t_end"]])),
    }
    return SweepResult(table, des.names, des.kind, des.grid, des.seed, des.n, des.distributions, ser, events, alarms, warns, text, info)


# ---------------------------------------------------------------- robustness
@dataclass
class RobustnessRegion:
    """Where a controller keeps the bending moment under the wrinkling moment with a margin.

    ``feasible[i, j]``: the run at ``payload_kg[i]`` [kg], ``pressure_pa[j]`` [Pa] completed
    without a fault and its peak |M|/M_w (both links) stayed at or below ``limit`` =
    1 − ``margin``; ``ratio[i, j]``: that peak; ``table``: the sweep's table with a
    ``feasible`` column; ``sweep``: the :class:`SweepResult`.
    """

    payload_kg: np.ndarray
    pressure_pa: np.ndarray
    ratio: np.ndarray
    feasible: np.ndarray
    margin: float
    limit: float
    table: "pd.DataFrame"
    sweep: SweepResult

    def to_pandas(self) -> "pd.DataFrame":
        """The table (one row per run, with ``feasible``)."""
        return self.table.copy()

    def max_payload(self) -> Dict[float, float]:
        """For each pressure [Pa]: the largest payload [kg] such that it and every smaller
        payload of the grid are feasible (NaN: not even the smallest)."""
        out = {}
        for j, p in enumerate(self.pressure_pa):
            ok = self.feasible[:, j]
            k = int(np.argmin(ok)) if not ok.all() else len(ok)
            out[float(p)] = float(self.payload_kg[k - 1]) if k > 0 else math.nan
        return out

    def summary(self) -> str:
        """A few lines: the margin, how many grid points are feasible, the payload limit per
        pressure."""
        n, k = self.feasible.size, int(self.feasible.sum())
        lines = [f"bending moment under M_w with margin {self.margin:g} (peak |M|/M_w <= {self.limit:g}): {k} of {n} (payload, pressure) points"]
        for j, p in enumerate(self.pressure_pa):
            ok = self.payload_kg[self.feasible[:, j]]
            lines.append(f"  {p / 1e3:g} kPa: feasible payloads " + (", ".join(f"{x:g}" for x in ok) + " kg" if ok.size else "none"))
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()

    def plot(self, *, ax: Any = None) -> Any:
        """Heat map of peak |M|/M_w over (pressure, payload), the ``limit`` contour and the
        feasible points marked; returns the figure."""
        from .plot import pyplot

        plt = pyplot()
        if ax is None:
            fig, ax = plt.subplots(figsize=(7, 4.5))
        else:
            fig = ax.figure
        xs, ys = self.pressure_pa / 1e3, self.payload_kg
        im = ax.pcolormesh(_edges(xs), _edges(ys), np.ma.masked_invalid(self.ratio), shading="flat", cmap="RdYlGn_r", vmin=0.0, vmax=max(1.2, self.limit * 1.2))
        fig.colorbar(im, ax=ax, label="peak |M|/M_w")
        if len(xs) > 1 and len(ys) > 1 and np.isfinite(self.ratio).any():
            ax.contour(xs, ys, self.ratio, levels=[self.limit], colors="k", linewidths=1.5)
        jj, ii = np.meshgrid(np.arange(len(xs)), np.arange(len(ys)))
        f = self.feasible
        ax.scatter(xs[jj[f]], ys[ii[f]], marker="o", s=22, facecolor="w", edgecolor="k", label=f"feasible (<= {self.limit:g})")
        ax.scatter(xs[jj[~f]], ys[ii[~f]], marker="x", s=22, color="k", label="not feasible")
        ax.set_xlabel("pressure [kPa]")
        ax.set_ylabel("payload [kg]")
        ax.set_title(f"bending moment under M_w with margin {self.margin:g}")
        ax.legend(fontsize="small", loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, frameon=False)
        fig.tight_layout()
        return fig


def robustness(
    base: Any,
    *,
    payload_kg: Sequence[float],
    pressure_pa: Sequence[float],
    margin: float = 0.1,
    pressure_key: str = "pressure_pa",
    **sweep_kwargs: Any,
) -> RobustnessRegion:
    """For which payloads [kg] and pressures [Pa] does the scenario's controller keep the
    bending moment under the wrinkling moment M_w with ``margin``?

    Runs the grid ``payload_kg`` x ``pressure_pa`` (``pressure_key``: ``"pressure_pa"``
    sets both links, ``"pressure_pa[0]"`` one) through :func:`sweep` (``sweep_kwargs``:
    ``duration``, ``threads``, ``executor``, ...). A point is feasible when its run completed
    without a fault and peak |M|/M_w <= 1 − ``margin`` on both links (``margin`` in [0, 1),
    a fraction of M_w). Returns the region (boolean grid, peak ratios, table) with
    ``.plot()``.
    """
    if not (isinstance(margin, (int, float)) and 0.0 <= margin < 1.0):
        raise SweepError(f"margin must be a fraction of M_w in [0, 1), got {margin!r}")
    if pressure_key not in ("pressure_pa", "pressure_pa[0]", "pressure_pa[1]"):
        raise SweepError(f"pressure_key must be 'pressure_pa', 'pressure_pa[0]' or 'pressure_pa[1]', got {pressure_key!r}")
    for k in ("grid", "points", "distributions", "n"):
        if k in sweep_kwargs:
            raise SweepError(f"robustness: {k}= is set by the helper (payload_kg x pressure_pa)")
    pay = _values("payload_kg", payload_kg)
    pre = _values(pressure_key, pressure_pa)
    res = sweep(base, grid={"payload_kg": pay, pressure_key: pre}, **sweep_kwargs)
    limit = 1.0 - float(margin)
    df = res.table.copy()
    ok = (df["status"] == "completed") & (df["faults"] == 0) & (df["peak_moment_ratio"] <= limit)
    df["feasible"] = ok.to_numpy()
    shape = (len(pay), len(pre))
    return RobustnessRegion(pay, pre, res.metric("peak_moment_ratio").reshape(shape), df["feasible"].to_numpy(dtype=bool).reshape(shape), float(margin), limit, df, res)


# ---------------------------------------------------------------- building a base scenario
def scenario_from_task(
    task: "Task",
    *,
    duration: float,
    model: Optional["Model"] = None,
    arm: str = "popup-lab",
    arm_file: Optional[Union[str, "os.PathLike[str]"]] = None,
    q0: Sequence[float] = (0.0, 0.0, 0.0),
    payload_kg: Optional[float] = None,
    pressure_pa: Optional[Sequence[float]] = None,
    gravity: bool = True,
    dt: Optional[float] = None,
    integrator: str = "rk4",
    sample_rate: float = 500.0,
    effects: Optional[Mapping[str, Mapping[str, Any]]] = None,
    description: str = "",
) -> Scenario:
    """A checked scenario running ``task`` (a :class:`popup.control.Task`) for ``duration``
    [s] from rest at motor angles ``q0`` [rad]: the base of a sweep built in Python.

    With ``model`` (a :class:`popup.Model`) its arm, payload [kg], pressures [Pa], gravity,
    ``dt`` [s], integrator and effects are used (explicit arguments win for payload and
    pressures). A built-in arm is written by name; any other arm needs ``arm_file``, where it
    is saved (the scenario refers to it, workers receive its text).
    """
    d: Dict[str, Any] = {"format": "popup-scenario/1", "description": description or "built by popup.sweep.scenario_from_task"}
    fxd: Dict[str, Any] = {k: dict(v) for k, v in (effects or {}).items()}
    base_dir = "."
    if model is not None:
        dis = list(model.core.disabled)
        if set(dis) - {"gravity"}:
            raise SweepError(f"scenario_from_task: a scenario cannot disable {sorted(set(dis) - {'gravity'})} (only gravity)")
        gravity = "gravity" not in dis
        dt = model.dt if dt is None else dt
        integrator = model.integrator
        payload_kg = model.payload_kg if payload_kg is None else payload_kg
        pressure_pa = model.pressure_pa if pressure_pa is None else pressure_pa
        name = model.arm.name

        def bare(a: "_core.Arm") -> Dict[str, Any]:
            t = tomllib.loads(a.to_toml())
            t.pop("effects", None)
            return t

        if name in _core.Arm.builtin_names() and bare(_core.Arm.builtin(name)) == bare(model.arm):
            arm = name  # the built-in arm, the model's effects as the scenario's [effects.*]
            mfx: Dict[str, Any] = {k: {p: (v[0] if len(v) == 1 else v) for p, v in ps.items()} for k, ps in model.effects.items()}
            mfx.update(fxd)
            fxd = mfx
        elif arm_file is None:
            raise SweepError(f"scenario_from_task: the model's arm {name!r} is not a built-in one: give arm_file= (a path to save it to)")
        else:
            p = Path(arm_file)
            model.arm.save(str(p))  # its effects included
            arm, base_dir = p.name, str(p.parent)
    elif arm_file is not None:
        p = Path(arm_file)
        arm, base_dir = p.name, str(p.parent)
    d["arm"] = arm
    if payload_kg is not None:
        d["payload_kg"] = float(payload_kg)
    if pressure_pa is not None:
        pp = [float(pressure_pa)] * 2 if np.ndim(pressure_pa) == 0 else [float(x) for x in pressure_pa]  # type: ignore[arg-type]
        d["pressure_pa"] = pp
    d["gravity"] = bool(gravity)
    d["q0"] = [float(x) for x in q0]
    d["duration_s"] = float(duration)
    if dt is not None:
        d["dt"] = float(dt)
    d["integrator"] = integrator
    d["sample_rate_hz"] = float(sample_rate)
    if fxd:
        d["effects"] = fxd
    d.update(copy.deepcopy(task.to_dict()))
    return Scenario.from_dict(d, "<scenario_from_task>", base_dir)
