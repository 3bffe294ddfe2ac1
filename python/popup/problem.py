"""One measured run replayed in one model: the problem that :func:`popup.compare.compare`,
:func:`popup.diagnose`, :func:`popup.improve` and :func:`popup.fit_params` share.

::

    prob = popup.ReplayProblem(model, run)       # channels, rate, encoder, nominal replay, noise
    prob.noise                                   # {channel: σ} white-noise floor per channel
    prob.error()                                 # systematic error of the model [noise units]
    z = prob.residuals(prob.simulate(flats))     # (B, n, C) residuals in noise units

What it holds (set up once, reused by every fit):

* **Channels** (:func:`select_channels`): every measured output the model predicts,
  except the replay inputs ``q1..3``/``dq1..3`` and pressures that do not vary.
* **Output rate**: the coarsest multiple of ``dt`` at least the run's mean rate; every
  step (``1/dt``) when the measured stamps are not on that grid (jitter), so that the
  linear interpolation onto the stamps stays far below the noise.
* **Encoder** (encoder replay): the measured angles smoothed by
  :func:`popup.smoothing.smooth_encoder` (a quantised or noisy encoder interpolated as is
  makes q̈, and so the torques, noisy: the replay would sit above the noise floor).
* **Noise floor** σ_c of each channel (:func:`popup.noise.noise_stds` of the nominal
  model's residual: divided differences remove the smooth systematic part; strides up
  to :data:`popup.noise.CORRELATION_S` find noise coloured by a sensor's low-pass, and a
  channel whose misfit hides that colour takes its sensor kind's,
  :data:`popup.results.SENSORS`).
* **Encoder floor** (encoder replay, :attr:`ReplayProblem.encoder_floor`): the replay
  error that the encoder's own error causes in each channel, by a parametric bootstrap
  (the smoothed angles re-measured :data:`ENCODER_DRAWS` times as the encoder measures:
  quantised at its step on a random grid offset, with the white noise estimated beyond
  the quantisation; smoothed again; replayed). A 12-bit encoder on a quiet IMU leaves
  the replay with the true model above the IMU's noise: that is a limit of the data, not
  a missing effect (``floor = sqrt(σ_c² + σ_enc,c²)``, :meth:`ReplayProblem.floor_multiples`).
  The draws also bound it: the run's own encoder error is one more draw, so the
  one-sided :data:`ENCODER_LEVEL` prediction bound of one draw's mean square from their
  spread (Student's t, :attr:`ReplayProblem.encoder_sigma_upper`) is what the true
  model's replay error may reach. Where the arm's response is very sensitive to its
  angles (links wrinkled far past their moment, a 12-bit encoder) the draws' mean squares
  differ by ±45 % and the true model replayed 1.16-1.17 × the point estimate's floor;
  whether a model is at its floor is judged against the bound (the diagnosis's
  ``model_at_floor``).
  It is the model's: computed with the first model that asks and shared with derived
  problems; :meth:`ReplayProblem.encoder_bootstrap` computes it for another model and
  :meth:`ReplayProblem.with_encoder_sigma` puts it in (the diagnosis loop does so on each
  refitted model: a gear with play replays a coarse encoder far worse than the nominal).
* **Unseen motion** (encoder replay, :mod:`popup.unseen`, used by the diagnosis): a servo's
  motion inside an encoder reading, fitted as a joint compliance bounded to a reading
  (:meth:`ReplayProblem.with_unseen_motion`, :attr:`ReplayProblem.compliance`; zeros and
  the smoothed encoder as is unless it is significant).
* **Training and validation samples**: the run cut in equal time blocks, at least
  :data:`N_BLOCKS` and none longer than :data:`BLOCK_MAX_S` (:func:`holdout_split`); every
  third, from the second, is held out (33 %, spread over the run and short, a third of a
  second on a 10 s run, so that a joint that moves once is seen moving in both parts). Fits use the training samples; an effect is
  confirmed on the held-out ones. A record that starts in motion without an
  ``[initial]`` table has an unknown bending state at its start: its first
  :data:`BURN_IN_S` seconds (at most 20 %) are left out of every error and fit (noted).

The error (:data:`ERROR_DEFINITION`)
------------------------------------
With ``z_c = (ŷ_c − y_c)/σ_c`` the residual of channel c in units of its noise, the
*noise multiple* of channel c is ``r_c = sqrt(mean z_c²)`` (1 = at the noise floor) and
the model's error is the systematic part ``S = sqrt(max(mean_c r_c² − 1, 0))`` in noise
units (0 = everything left is noise). A channel whose measured signal is at its noise
floor has ``r_c ≈ 1`` whatever the model does and adds nothing.
"""

from __future__ import annotations

import math
import threading
import warnings
from typing import TYPE_CHECKING, Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from .exceptions import InputError, MeasuredRunError, StepTooLargeError
from .io import MeasuredRun
from .noise import CORRELATION_S, noise_std, noise_stds
from .results import CHANNELS, SENSORS

if TYPE_CHECKING:  # pragma: no cover
    from .model import Model

__all__ = [
    "ReplayProblem",
    "select_channels",
    "initial_state",
    "reference_setup",
    "output_rate",
    "ERROR_DEFINITION",
    "N_BLOCKS",
    "BLOCK_MAX_S",
    "DEFAULT_CHANNELS",
    "SPIKE_SIGMA",
    "SPIKE_WINDOW",
    "ENCODER_DRAWS",
    "ENCODER_LEVEL",
    "holdout_split",
    "Shifted",
    "Cancelled",
]

ERROR_DEFINITION = (
    "systematic error in units of the noise: S = sqrt(max(mean_c r_c^2 - 1, 0)) over the compared channels c, "
    "where r_c = RMSE_c/sigma_c is channel c's free-run replay error as a multiple of its white-noise floor sigma_c "
    "(estimated from the data by 4th divided differences of the model's residual: the nominal one, re-estimated by popup.improve "
    "on a refitted model where it differs by more than 1.2x); 0 = at the noise floor"
)
N_BLOCKS = 30
"""Fewest equal time blocks the run is cut into for training/validation (more where a
block would exceed :data:`BLOCK_MAX_S`). It was 10 until session 36: a MuJoCo trapezoid
run (10.5 s, 200 Hz) moved joints 2 and 3 once, in t = 4.0-5.0 s, nearly all inside
held-out block 4 (4.2-5.25 s); their friction, fitted on holds alone, went to the viscous
bound (b = 100 N·m·s/rad, mimicking a stiction the smooth law has not), the held-out
error rose 16.9 → 217 noise units and the effect was refused. With 30 blocks every
parameter lands on the truth (14.3 → 0.57 noise units)."""

BLOCK_MAX_S = 0.4
"""Longest training/validation block [s]: a run longer than ``N_BLOCKS × BLOCK_MAX_S``
(12 s) is cut into more blocks (a multiple of 3), so that any stretch of 1.2 s or more, a
joint's only move say, is at least a third training and a sixth held out whatever the
run's length (a lab's 60 s record would otherwise have held out whole 2 s blocks)."""

DEFAULT_CHANNELS: Tuple[str, ...] = (
    "tau1", "tau2", "tau3", "ee_x", "ee_y", "ee_z",
    "imu1_ax", "imu1_ay", "imu1_az", "imu2_ax", "imu2_ay", "imu2_az",
)
"""The channels compared by default in an encoder replay (when the run has them)."""

INPUTS_ENCODER = ("q1", "q2", "q3")
DERIVED = ("dq1", "dq2", "dq3")
PRESSURES = ("p1", "p2")
#: Joint speed [rad/s] over the first samples above which a record "starts in motion".
MOVING_AT_START = 0.05
#: Start-up transient left out of a record that starts in motion [s] (at most 20 % of it).
BURN_IN_S = 2.0
#: A channel whose measured standard deviation is below this multiple of its noise floor
#: carries no signal the model could explain.
FLOOR_SIGNAL_RATIO = 1.5
#: A residual sample this many noise deviations from the median of its 7 neighbours is an
#: isolated spike (:meth:`ReplayProblem.spikes`): with Gaussian noise one sample in ~10¹⁴.
SPIKE_SIGMA = 8.0
SPIKE_WINDOW = 7
#: Draws of the encoder's error in the bootstrap of :attr:`ReplayProblem.encoder_floor`.
ENCODER_DRAWS = 6
ENCODER_LEVEL = 0.95
"""One-sided level of the prediction bound :attr:`ReplayProblem.encoder_sigma_upper`."""
_ENCODER_SEED = 0xE1F  # fixed: the same run gives the same floor, bit for bit


# ---------------------------------------------------------------------------- setup


def select_channels(run: MeasuredRun, channels: Optional[Sequence[str]], where: str, notes: List[str], closed: bool = False) -> List[str]:
    """The channels to compare (module docs); ``notes`` says what was left out and why."""
    have = [c for c in run.columns if c in CHANNELS and c != "t"]
    if channels is not None:
        chans = [str(c) for c in channels]
        bad = [c for c in chans if c not in have]
        if bad:
            raise MeasuredRunError(
                f"{where}: cannot compare {bad}: a channel must be both measured and simulated; "
                f"comparable channels of this run: {have or 'none'} (run columns: {run.columns})"
            )
        if not chans:
            raise MeasuredRunError(f"{where}: channels=[] selects nothing to compare; comparable: {have}")
        twice = sorted({c for c in chans if chans.count(c) > 1})
        if twice:
            raise InputError(f"input channels: {twice} named more than once in {chans}; name each channel once")
        for c in chans:
            if closed:
                continue
            if c in INPUTS_ENCODER:
                notes.append(f"{c} is an input of the encoder replay: it matches by construction (up to the smoothing)")
            if c in DERIVED:
                notes.append(f"{c}: the simulated rate is the derivative of the encoder spline, not an independent prediction")
        return chans
    chans = []
    skipped = []
    for c in have:
        if not closed and (c in INPUTS_ENCODER or c in DERIVED):
            skipped.append(c)
            continue
        y = run.channel(c)
        if not np.any(np.isfinite(y)):
            notes.append(f"{c}: every measured sample is missing; not compared")
            continue
        if c in PRESSURES:
            yy = y[np.isfinite(y)]
            if yy.size < 2 or float(np.max(yy) - np.min(yy)) == 0.0:
                skipped.append(c)
                continue
        chans.append(c)
    if skipped:
        notes.append(f"not compared by default: {', '.join(skipped)} (replay inputs, spline derivatives or constant pressures)")
    if not chans:
        raise MeasuredRunError(
            f"{where}: nothing to compare: the run has no measured output the model predicts "
            f"(run columns: {', '.join(run.columns)}; comparable outputs are {', '.join(DEFAULT_CHANNELS)}"
            f", and p1/p2 when they vary)"
        )
    return chans


def initial_state(model: "Model", run: MeasuredRun, q0: np.ndarray, notes: List[str]) -> Tuple[Any, Any]:
    """The replay's initial chain state ``(q, v)`` from the run's ``[initial]`` table, or
    ``(None, None)`` (at rest: bending joints in static equilibrium at ``q0``)."""
    ini = run.initial
    if not ini:
        notes.append("the run starts at rest: bending joints in static equilibrium at the first encoder sample")
        return None, None
    names = ["d11", "d12", "d21", "d22"]
    rates = ["dd11", "dd12", "dd21", "dd22"]
    d = ini.get("bending")
    dd = ini.get("bending_rate")
    if d is None and any(n in ini for n in names):
        d = [float(ini.get(n, math.nan)) for n in names]
    if dd is None and any(n in ini for n in rates):
        dd = [float(ini.get(n, 0.0)) for n in rates]
    jn = model.joint_names
    if d is None or len(d) != 4 or not all(n in jn for n in names):
        notes.append(f"[initial] table {sorted(ini)} not understood (expected d11 d12 d21 d22 [rad] and dd11.. [rad/s]); the run starts at rest")
        return None, None
    q = model.rest_state([float(x) for x in q0])
    v = np.zeros(len(jn))
    locked = set(model.core.locked_index)
    for n, x in zip(names, d):
        if np.isfinite(float(x)) and jn.index(n) not in locked:
            q[jn.index(n)] = float(x)
    if dd is not None:
        for n, x in zip(rates, dd):
            if jn.index(n) not in locked:
                v[jn.index(n)] = float(x)
    notes.append("initial bending angles and rates from the run's [initial] table" + (" (a rigid link's stay 0)" if locked else ""))
    return q, v


def reference_setup(run: MeasuredRun) -> Tuple[Any, np.ndarray, float, float]:
    """The closed-loop replay of a ``replay = "reference"`` run: ``(task, q0 [rad], t0 [s],
    duration [s])``. The task is one phase tracking the measured references (linear
    interpolation) with the controller of the run's ``[controller]`` table; the run starts at
    rest at the first encoder sample (the first reference sample when q1..q3 are absent)."""
    from .control import Controller, Phase, Task, samples

    t_ref, q_ref = run.reference()
    where = str(run.source)
    ctl = dict(run.controller or {})
    try:
        controller = Controller(**ctl)
    except TypeError as e:
        raise MeasuredRunError(f"{where}: [controller] table: {e} (keys: rate_hz, gains, motor, motors, damping, damping_lpf_rad_s, v_max, anti_windup)") from None
    t0 = float(t_ref[0])
    task = Task([Phase("moving", name="Replay", track=[samples(t_ref - t0, q_ref[:, j]) for j in range(3)], until={"max_time": math.inf})], controller, faults={"wrinkle": "continue"})
    q0 = q_ref[0]
    if all(c in run.columns for c in ("q1", "q2", "q3")):
        q = np.column_stack([run.channel(c) for c in ("q1", "q2", "q3")])
        ok = np.all(np.isfinite(q), axis=1)
        if ok.any():
            q0 = q[int(np.argmax(ok))]
    return task, np.asarray(q0, dtype=np.float64), t0, float(t_ref[-1] - t0)


def output_rate(dt: float, t_in: np.ndarray, t_meas: np.ndarray, sample_rate: Optional[float], notes: List[str]) -> float:
    """The simulation's output rate [Hz] (module docs): ``sample_rate`` if given, else the
    coarsest multiple of ``dt`` at least the run's mean rate, or every step when the
    measured stamps are off that grid."""
    span = float(t_in[-1] - t_in[0])
    mean_dt = span / (len(t_in) - 1)
    if sample_rate is not None:
        sr = float(sample_rate)
        notes.append(f"simulated at {sr:.6g} Hz (sample_rate given; the run's mean rate is {1.0 / mean_dt:.6g} Hz)")
        return sr
    k = max(1, int(math.floor(mean_dt / dt * (1.0 + 1e-9))))
    if mean_dt < dt * (1.0 - 1e-9):
        notes.append(f"the run ({1.0 / mean_dt:.6g} Hz) is sampled faster than the model step allows; simulated at 1/dt = {1.0 / dt:.6g} Hz")
        return 1.0 / dt
    grid = t_in[0] + np.round((t_meas - t_in[0]) / (k * dt)) * (k * dt)
    if k > 1 and np.max(np.abs(grid - t_meas)) > 1e-9 * max(1.0, float(np.max(np.abs(t_meas)))):
        notes.append(f"the measured stamps are not on a {1.0 / (k * dt):.6g} Hz grid (jitter): simulated at every step (1/dt = {1.0 / dt:.6g} Hz) and interpolated")
        return 1.0 / dt
    sr = 1.0 / (k * dt)
    notes.append(f"simulated at {sr:.6g} Hz (output every {k} step(s) of dt = {dt:g} s; the run's mean rate is {1.0 / mean_dt:.6g} Hz)")
    return sr


# ---------------------------------------------------------------------------- problem


class Shifted:
    """A closed-loop result (time from 0) seen on the run's clock (time from ``t0``)."""

    def __init__(self, res: Any, t0: float) -> None:
        self.res = res
        self.t0 = float(t0)

    @property
    def time(self) -> np.ndarray:
        return self.res.time + self.t0

    def channel(self, name: str) -> np.ndarray:
        return self.time if name == "t" else self.res.channel(name)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.res, name)




class ReplayProblem:
    """One measured run replayed in one model (module docs).

    Parameters
    ----------
    model : Model
    run : MeasuredRun
    channels : channels to compare (default: :func:`select_channels`).
    sample_rate : simulation output rate [Hz] (default: :func:`output_rate`).
    threads : rollout threads (0 = every core).
    smooth : smooth the encoder angles (encoder replay; default True).
    offsets : fit a constant offset per channel with every model (a sensor bias or a
        calibration offset the lab has not removed): every residual has its mean over the
        samples used taken out (:meth:`residuals`), so fits, errors and ranking see the
        rest; :meth:`offsets` gives the values. Default False: a constant is part of the
        error (a payload's torque is partly one).

    Attributes
    ----------
    channels : list of str
    time : (n,) measured stamps [s]
    measured : (n, C) measured channels (NaN where missing)
    noise : dict, channel → σ (channel unit)
    at_floor : list of channels whose measured signal is at its noise floor
    train, validation : (n,) boolean masks
    notes : what was done (rates, smoothing, channels)
    """

    channels: List[str]
    time: np.ndarray
    measured: np.ndarray
    notes: List[str]
    t_enc: np.ndarray
    q_enc: np.ndarray
    q_enc_raw: np.ndarray
    smoothing: Any
    train: np.ndarray
    validation: np.ndarray
    used: np.ndarray
    sample_rate: float
    iq: Any
    iv: Any
    task: Any
    q0: Any
    t0: float
    duration: float
    sigma: np.ndarray
    fit_offsets: bool
    _count: List[int]
    _nominal: Optional[Tuple[np.ndarray, Any]]
    _cancel: Optional[threading.Event]
    _threads: List[int]
    _enc: List[Optional[np.ndarray]]
    q_base: np.ndarray
    q_corr: np.ndarray
    compliance: np.ndarray
    _enc_up: List[Any]

    def __init__(
        self,
        model: "Model",
        run: MeasuredRun,
        *,
        channels: Optional[Sequence[str]] = None,
        sample_rate: Optional[float] = None,
        threads: int = 0,
        smooth: bool = True,
        offsets: bool = False,
        _parent: Optional["ReplayProblem"] = None,
    ) -> None:
        if not isinstance(run, MeasuredRun):
            raise InputError(f"input run: expected a popup.MeasuredRun (popup.read_run), got {type(run).__name__}")
        if _parent is None:
            run.check()  # a data glitch is named here, never blamed on missing physics
        self.model = model
        self.run = run
        # shared with the problems derived from this one, so that :meth:`fork`'s owner can
        # hand a candidate more threads once others have finished (bits do not depend on it)
        self._threads = _parent._threads if _parent is not None and int(threads) == _parent.threads else [int(threads)]
        self._count = _parent._count if _parent is not None else [0]
        self._cancel = _parent._cancel if _parent is not None else None
        self.where = str(run.data_file if run.data_file is not None else run.source)
        if run.replay not in ("encoder", "reference"):
            raise MeasuredRunError(f"{self.where}: unknown replay mode {run.replay!r}; expected \"encoder\" or \"reference\"")
        self.closed = run.replay == "reference"
        self.fit_offsets = bool(offsets) if _parent is None else _parent.fit_offsets
        if _parent is not None:
            p = _parent
            self.notes = list(p.notes)
            self.channels = list(p.channels)
            self.time, self.measured = p.time, p.measured
            self.t_enc, self.q_enc, self.q_enc_raw, self.smoothing = p.t_enc, p.q_enc, p.q_enc_raw, p.smoothing
            self.train, self.validation, self.used = p.train, p.validation, p.used
            self.sample_rate = p.sample_rate
            self.iq, self.iv = p.iq, p.iv
            self.task, self.q0, self.t0, self.duration = p.task, p.q0, p.t0, p.duration
            self.sigma = p.sigma
            # the encoder's error is the run's, its replay error the model's: shared with every
            # derived problem until :meth:`with_encoder_sigma` puts another model's in
            self._enc = p._enc
            self._enc_up = p._enc_up
            self.q_base, self.q_corr, self.compliance = p.q_base, p.q_corr, p.compliance
            self._nominal = None
            self.horizon: Optional[float] = p.horizon  # judged before this time [s] only (:meth:`until`)
            return
        self.horizon = None
        notes: List[str] = []
        self.notes = notes
        self._enc = [None]
        self._enc_up = [None]
        self.channels = select_channels(run, channels, self.where, notes, self.closed)
        self.time = np.asarray(run.time, dtype=np.float64)
        self.measured = np.column_stack([np.asarray(run.channel(c), dtype=np.float64) for c in self.channels])
        self.task = None
        self.q0 = None
        self.t0 = 0.0
        self.duration = 0.0
        self.iq = None
        self.iv = None
        self.smoothing = None
        self.compliance = np.zeros(3)
        if self.closed:
            self.t_enc, self.q_enc = run.reference()
            self.q_enc_raw = self.q_enc
            self.task, self.q0, self.t0, self.duration = reference_setup(run)
        else:
            self.t_enc, self.q_enc_raw = run.encoder()
            self.q_enc = self.q_enc_raw
            n_skip = len(self.time) - len(self.t_enc)
            if n_skip:
                notes.append(f"encoder replay: {n_skip} row(s) with a missing q1..3 skipped (interpolated over)")
            if smooth:
                self.smoothing = _smooth(self.t_enc, self.q_enc_raw)
                if self.smoothing is not None:
                    self.q_enc = self.smoothing.q
                    notes.append(f"encoder: {self.smoothing.method}")
            self.iq, self.iv = initial_state(model, run, self.q_enc[0], notes)
        self.q_base = self.q_enc
        self.q_corr = np.zeros_like(np.asarray(self.q_enc, dtype=np.float64))
        self.sample_rate = output_rate(model.dt, self.t_enc, self.time, sample_rate, notes)
        self.used = np.ones(len(self.time), dtype=bool)
        self.train, self.validation = holdout_split(self.time)
        self._nominal = None
        # noise floor from the nominal residual (its smooth systematic part is removed by the differences)
        z = self.nominal_simulation() - self.measured
        self.sigma = np.array(_floors(self.time, z, self.measured, self.channels))
        if not self.closed and not run.initial:
            # a record that starts in motion, with no [initial] table: the bending state at
            # its start is unknown and the replay (from rest) rings for a while; leave it out
            why = self._moving_at_start(z / np.where(self.sigma > 0, self.sigma, np.inf))
            if why:
                burn = min(BURN_IN_S, 0.2 * float(self.time[-1] - self.time[0]))
                self.used = self.time >= self.time[0] + burn
                self.train &= self.used
                self.validation &= self.used
                notes.append(f"the record starts in motion ({why}) and has no [initial] table: its first {burn:.3g} s "
                             "(the replay's start-up transient from rest) are left out of every error and fit")
        lost = [c for c, s in zip(self.channels, self.sigma) if not s > 0]
        if lost:
            raise MeasuredRunError(f"{self.where}: cannot estimate the noise floor of {lost} (constant or too few samples); leave them out with channels=")

    def _moving_at_start(self, z: np.ndarray) -> str:
        """Why the record does not start at rest ("" if it does): a motor moving over the
        first samples, or the nominal residual ``z`` (noise units) of a motion channel (IMU,
        mocap) over the first 0.5 s far above the noise and above the rest of the run (the
        links still ringing from before the record)."""
        i = min(5, len(self.t_enc) - 1)
        dq0 = np.abs(self.q_enc[i] - self.q_enc[0]) / max(float(self.t_enc[i] - self.t_enc[0]), 1e-12)
        if float(np.max(dq0)) > MOVING_AT_START:
            return f"|dq| = {float(np.max(dq0)):.3g} rad/s"
        win = self.time <= self.time[0] + min(0.5, 0.1 * float(self.time[-1] - self.time[0]))
        for j, c in enumerate(self.channels):
            if not (c.startswith("imu") or c.startswith("ee_")):
                continue
            a, b = z[win, j], z[~win, j]
            a, b = a[np.isfinite(a)], b[np.isfinite(b)]
            if a.size < 10 or b.size < 10:
                continue
            ra, rb = float(np.sqrt(np.mean(a * a))), float(np.sqrt(np.mean(b * b)))
            if ra > 3.0 and ra > 3.0 * rb:
                return f"{c}'s residual is {ra:.3g}× its noise over the first samples, {rb:.3g}× after"
        return ""

    # ------------------------------------------------------------------ derived problems
    def with_model(self, model: "Model") -> "ReplayProblem":
        """The same run, channels, encoder, noise floor and split in another model (a
        candidate structure, a smaller step); the output rate must be a multiple of its ``dt``."""
        return ReplayProblem(model, self.run, threads=self.threads, _parent=self)

    def with_horizon(self, t_end: float) -> "ReplayProblem":
        """The same problem on the measured samples up to ``t_end`` [s] only (encoder and
        references cut there, every kept sample a training one): a short horizon on which
        a lightly damped response has not yet drifted out of phase, so a fit's basin is
        wide (used for extra starts)."""
        keep = self.time <= t_end
        if keep.sum() < 20:
            return self
        p = self._cut(keep, t_end)
        p.train, p.validation = p.used.copy(), np.zeros(int(keep.sum()), dtype=bool)
        return p

    def until(self, t_end: float) -> "ReplayProblem":
        """The same problem judged on the measured samples before ``t_end`` [s] only, its
        held-out split kept where it lies (encoder and references cut there): the part of
        the run a model's replay can predict (a gear rattling in its play diverges from
        any replay past a few seconds, :func:`popup.diagnosis.candidate.predictable_until`).
        ``self`` where that keeps every sample or fewer than 20."""
        keep = self.time < t_end
        if keep.all() or keep.sum() < 20:
            return self
        p = self._cut(keep, t_end)
        p.horizon = float(t_end)
        return p

    def _cut(self, keep: np.ndarray, t_end: float) -> "ReplayProblem":
        """A copy on the measured samples ``keep`` (bool, one per sample), its split kept,
        with the encoder and references cut at ``t_end`` [s]."""
        p = ReplayProblem(self.model, self.run, threads=self.threads, _parent=self)
        p.time, p.measured = self.time[keep], self.measured[keep]
        p.used, p.train, p.validation = self.used[keep], self.train[keep], self.validation[keep]
        k_enc = self.t_enc <= t_end + 1e-9
        if k_enc.sum() >= 5:
            p.t_enc, p.q_enc, p.q_enc_raw = self.t_enc[k_enc], self.q_enc[k_enc], self.q_enc_raw[k_enc]
            p.q_base, p.q_corr = self.q_base[k_enc], self.q_corr[k_enc]
        if self.closed:
            p.duration = min(self.duration, float(t_end - self.t0))
        return p

    def with_unseen_motion(self, compliance: Any, q_corr: np.ndarray) -> "ReplayProblem":
        """The same problem with the replayed angles moved by ``q_corr`` (n_enc, 3) [rad]
        from the smoothed encoder, the motion inside a reading that
        :func:`popup.unseen.fit_unseen_motion` gives for joint compliances ``compliance``
        (3,) [rad/(N·m)]; zeros give the smoothed encoder again, bit for bit."""
        p = ReplayProblem(self.model, self.run, threads=self.threads, _parent=self)
        q_corr = np.asarray(q_corr, dtype=np.float64)
        if q_corr.shape != np.shape(self.q_enc):
            raise InputError(f"with_unseen_motion: q_corr has shape {q_corr.shape}, the encoder {np.shape(self.q_enc)}")
        p.q_corr = q_corr
        p.q_enc = self.q_base + q_corr if np.any(q_corr != 0) else self.q_base
        p.compliance = np.asarray(compliance, dtype=np.float64).copy()
        return p

    def with_noise(self, noise: Mapping[str, float]) -> "ReplayProblem":
        """The same problem with the noise floor σ [channel unit] of the channels named in
        ``noise`` replaced (the others kept); its simulation is not rerun."""
        bad = {c: v for c, v in noise.items() if c not in self.channels or not (math.isfinite(float(v)) and float(v) > 0)}
        if bad:
            raise InputError(f"with_noise: {bad} are not positive floors of this problem's channels {self.channels}")
        p = ReplayProblem(self.model, self.run, threads=self.threads, _parent=self)
        p.sigma = np.array([float(noise.get(c, s)) for c, s in zip(self.channels, self.sigma)])
        p._nominal = self._nominal
        return p

    def with_initial_state(self, q: Any, v: Any) -> "ReplayProblem":
        """The same problem started from chain coordinates ``q`` and rates ``v`` (nv,)."""
        p = ReplayProblem(self.model, self.run, threads=self.threads, _parent=self)
        p.iq, p.iv = q, v
        return p

    def fork(self, threads: int, cancel: Optional[threading.Event] = None) -> "ReplayProblem":
        """The same problem for one of several candidates fitted at once, each on its own
        thread: its own rollout counter (:attr:`nfev` from 0, so a candidate's count does not
        depend on what runs beside it) and ``threads`` rollout threads (its own, shared with
        the problems derived from it, which may be changed while it runs); the nominal
        simulation and the encoder's replay error are computed here, once, and shared.
        Once ``cancel`` is set, every simulation of this problem and of those derived from it
        raises :class:`Cancelled` (the other candidates are stopped after an interrupt)."""
        self.nominal_simulation()
        _ = self.encoder_sigma
        p = ReplayProblem(self.model, self.run, threads=self.threads, _parent=self)
        p._nominal = self._nominal
        p._threads = [int(threads)]
        p._count = [0]
        p._cancel = cancel
        return p

    def check_cancel(self) -> None:
        """Raise :class:`Cancelled` if this problem's cancel token (:meth:`fork`) is set."""
        if self._cancel is not None and self._cancel.is_set():
            raise Cancelled("cancelled: another candidate's thread was interrupted")

    # ------------------------------------------------------------------ properties
    @property
    def threads(self) -> int:
        """Rollout threads (0 = every core); shared with the problems derived from this one."""
        return self._threads[0]

    @threads.setter
    def threads(self, v: int) -> None:
        self._threads[0] = int(v)

    @property
    def nfev(self) -> int:
        """Simulations run so far by this problem and every problem derived from it."""
        return self._count[0]

    @nfev.setter
    def nfev(self, v: int) -> None:
        self._count[0] = int(v)

    @property
    def noise(self) -> Dict[str, float]:
        """White-noise floor σ per channel (channel unit)."""
        return {c: float(s) for c, s in zip(self.channels, self.sigma)}

    def noise_from(self, z: Optional[np.ndarray] = None) -> Dict[str, float]:
        """Each channel's noise floor σ [channel unit] estimated as at set-up (from the
        nominal residual), but from the residual ``z`` (n, C) in noise units (default: the
        model as given). A better model's residual has less systematic error to hide the
        noise's colour from the estimator (a sensor's low-pass makes neighbouring samples
        alike; under a large misfit the estimate falls back to neighbouring samples)."""
        if z is None:
            z = self.residuals(self.nominal_simulation())
        r = np.asarray(z) * self.sigma
        return dict(zip(self.channels, _floors(self.time, r, self.measured, self.channels)))

    @property
    def encoder_sigma(self) -> np.ndarray:
        """(C,) std [channel unit] of the replay error that the encoder's own error causes
        (module docs: parametric bootstrap; computed on first use with this problem's model
        and shared with the problems derived from it); zeros for
        a reference replay or an encoder replayed as measured."""
        e = self._enc[0]
        if e is None:
            e, self._enc_up[0] = self.encoder_bootstrap_bounds()
            self._enc[0] = e
        return e

    @property
    def encoder_sigma_upper(self) -> np.ndarray:
        """(C,) the one-sided :data:`ENCODER_LEVEL` prediction bound of the encoder's replay
        error [channel unit] for one more draw, such as the run's own encoder error, from
        the spread of the bootstrap's draws (:attr:`encoder_sigma` itself where no bound is
        known: a floor put in by :meth:`with_encoder_sigma` without one)."""
        e = self.encoder_sigma
        u = self._enc_up[0]
        return e if u is None else u

    def with_encoder_sigma(self, sigma: Any, upper: Any = None) -> "ReplayProblem":
        """The same problem with the encoder's replay error :attr:`encoder_sigma` replaced by
        ``sigma`` (C,) [channel unit] (e.g. :meth:`encoder_bootstrap` of a refitted model:
        a model whose output is more sensitive to the angles, such as a gear with play
        whose impacts the motor's timing sets, has a higher encoder floor); its simulation
        is not rerun. ``upper``: its prediction bound (:attr:`encoder_sigma_upper`; default
        ``sigma`` itself), at least ``sigma``."""
        e = np.asarray(sigma, dtype=np.float64)
        if e.shape != (len(self.channels),) or not np.all(np.isfinite(e)) or np.any(e < 0):
            raise InputError(f"with_encoder_sigma: sigma must be {len(self.channels)} finite values ≥ 0 (one per channel {self.channels}), got {e.tolist()}")
        u = e if upper is None else np.asarray(upper, dtype=np.float64)
        if u.shape != e.shape or not np.all(np.isfinite(u)) or np.any(u < e):
            raise InputError(f"with_encoder_sigma: upper must be {len(self.channels)} finite values ≥ sigma (one per channel {self.channels}), got {u.tolist()}")
        p = ReplayProblem(self.model, self.run, threads=self.threads, _parent=self)
        p._enc = [e]
        p._enc_up = [u]
        p._nominal = self._nominal
        return p

    @property
    def encoder_width(self) -> np.ndarray:
        """(3,) width [rad] of one encoder reading per joint: its quantisation step, or
        √12 × its white-noise std (a uniform error of the same variance) when that is wider;
        a joint whose reading never changes shows no step and gets the widest of the others;
        0 for an exact encoder or a reference replay. Motion inside it is not seen."""
        sm = self.smoothing
        w = np.zeros(3)
        if self.closed or sm is None:
            return w
        for j in range(3):
            step, wn = sm.params.get("resolution", [None] * 3)[j], sm.params.get("noise", [None] * 3)[j]
            w[j] = max(step or 0.0, math.sqrt(12.0) * (wn or 0.0))
        q = np.asarray(self.q_enc_raw)
        held = np.all(q == q[:1], axis=0)
        w[held & (w == 0)] = float(w.max())
        return w

    @property
    def encoder_floor(self) -> Dict[str, float]:
        """Per channel, the replay error the encoder's own error causes, as a multiple of
        the channel's noise: ``sqrt(1 + (σ_enc,c/σ_c)²)`` (1 = the encoder adds nothing)."""
        e = self.encoder_sigma / self.sigma
        return {c: float(math.sqrt(1.0 + v * v)) for c, v in zip(self.channels, e)}

    def floor_multiples(self, per: Dict[str, float], upper: bool = False) -> Dict[str, float]:
        """Noise multiples ``per`` (channel → r_c) as multiples of each channel's whole
        floor, the noise and the encoder's replay error: ``r_c / sqrt(1 + (σ_enc,c/σ_c)²)``;
        ``upper``: with σ_enc at its prediction bound (:attr:`encoder_sigma_upper`)."""
        if upper:
            e = self.encoder_sigma_upper / self.sigma
            f = {c: float(math.sqrt(1.0 + v * v)) for c, v in zip(self.channels, e)}
        else:
            f = self.encoder_floor
        return {c: float(v) / f.get(c, 1.0) for c, v in per.items()}

    def floor_error(self, per: Dict[str, float], upper: bool = False) -> float:
        """The systematic error S (:data:`ERROR_DEFINITION`) above the whole floor (noise and
        encoder) of the noise multiples ``per``; ``upper``: above the floor's upper bound
        (:meth:`floor_multiples`)."""
        fm = [v for v in self.floor_multiples(per, upper).values()]
        if not fm or not all(math.isfinite(v) for v in fm):
            return math.inf
        return systematic(np.square(np.asarray(fm)))

    def encoder_bootstrap(self) -> np.ndarray:
        """(C,) std [channel unit] of the replay error the encoder's own error causes with
        this problem's model (module docs: parametric bootstrap, :data:`ENCODER_DRAWS`
        replays with a fixed seed), computed afresh (:attr:`encoder_sigma` is the first
        model's unless :meth:`with_encoder_sigma` set another)."""
        return self.encoder_bootstrap_bounds()[0]

    def encoder_bootstrap_bounds(self) -> Tuple[np.ndarray, np.ndarray]:
        """:meth:`encoder_bootstrap` and its one-sided :data:`ENCODER_LEVEL` prediction bound
        for one more draw (C,) [channel unit], from the same draws: the square root of their
        mean square plus Student's t times ``s·sqrt(1 + 1/n)`` (``s`` the draws' standard
        deviation of the mean square, ``n`` the draws)."""
        C = len(self.channels)
        sm = self.smoothing
        if self.closed or sm is None or not any(v is not None for v in sm.params.get("lam", [None] * 3)):
            return np.zeros(C), np.zeros(C)
        from .smoothing import smooth_encoder

        par = sm.params
        rng = np.random.default_rng(_ENCODER_SEED)
        # the error of the readings as smoothed, around the smoothed angles: the same for any
        # unseen motion (popup.unseen) added to them, so shared by every derived problem
        t, g = self.t_enc, self.q_base
        base = self.replay_angles(g) if np.any(self.q_corr != 0) else self.nominal_simulation()
        ms: List[np.ndarray] = []
        for _ in range(ENCODER_DRAWS):
            y = g.copy()
            for j in range(3):
                if par["lam"][j] is None:
                    continue
                step, wn = par["resolution"][j], par["noise"][j]
                # the white noise the differences see beyond the quantisation's Δ²/12 (smoothing step 3)
                w = math.sqrt(max((wn or 0.0) ** 2 - (0.0 if step is None else step**2 / 12.0), 0.0))
                if w > 0:
                    y[:, j] += w * rng.standard_normal(len(t))
                if step is not None:
                    y[:, j] = np.round((y[:, j] + rng.uniform(-0.5, 0.5) * step) / step) * step
            try:
                d = self.replay_angles(smooth_encoder(t, y).q) - base
            except Exception:  # noqa: BLE001 - a draw the engine refuses is left out
                continue
            d = d[self.used]
            with np.errstate(invalid="ignore"):
                ms.append(np.nan_to_num(np.nanmean(d * d, axis=0)))
        if not ms:
            return np.zeros(C), np.zeros(C)
        m = np.array(ms)
        mean = m.mean(axis=0)
        if len(ms) < 2:
            return np.sqrt(mean), np.sqrt(mean)
        from scipy.stats import t as student_t

        spread = m.std(axis=0, ddof=1) * math.sqrt(1.0 + 1.0 / len(ms))
        return np.sqrt(mean), np.sqrt(mean + float(student_t.ppf(ENCODER_LEVEL, len(ms) - 1)) * spread)

    @property
    def at_floor(self) -> List[str]:
        """Channels whose measured signal is at its noise floor (std < 1.5 σ)."""
        out = []
        for j, c in enumerate(self.channels):
            y = self.measured[:, j]
            if float(np.nanstd(y)) < FLOOR_SIGNAL_RATIO * self.sigma[j]:
                out.append(c)
        return out

    # ------------------------------------------------------------------ simulation
    def simulate(self, flats: np.ndarray, model: Optional["Model"] = None, *, full: bool = False) -> Any:
        """Simulated channels on the measured stamps, (B, n, C), NaN where a run failed
        or outside the simulated span; ``full``: also the raw batch result."""
        self.check_cancel()
        m = self.model if model is None else model
        flats = np.atleast_2d(np.asarray(flats, dtype=np.float64))
        B = flats.shape[0]
        res: Any
        if self.closed:
            res = m.rollout_task(self.task, duration=self.duration, q0=self.q0, sample_rate=self.sample_rate,
                                 threads=self.threads, effects=flats, raise_on_error=False)
            ok = np.array([e is None and st == "completed" for e, st in zip(res.errors, res.status)])
            t0 = self.t0
        else:
            try:
                res = m.rollout(encoder_t=self.t_enc, encoder_q=self.q_enc, initial_q=self.iq, initial_v=self.iv,
                                sample_rate=self.sample_rate, threads=self.threads, effects=flats, raise_on_error=False)
            except StepTooLargeError:
                # the batch's step check refused one of its jobs: run them one by one, so
                # that only the unstable ones fail
                if B > 1:
                    return self._one_by_one(flats, m, full)
                self.nfev += 1
                out = np.full((1, len(self.time), len(self.channels)), np.nan)
                return (out, None) if full else out
            ok = np.asarray(res.ok)
            t0 = 0.0
        self.nfev += B
        out = np.full((B, len(self.time), len(self.channels)), np.nan)
        if ok.any():
            t_sim = res.time[int(np.argmax(ok))] + t0
            same = len(t_sim) == len(self.time) and np.array_equal(t_sim, self.time)
            inside = (self.time >= t_sim[0] - 1e-12) & (self.time <= t_sim[-1] + 1e-12)
            for j, c in enumerate(self.channels):
                y = res.channel(c)
                for b in range(B):
                    if not ok[b]:
                        continue
                    out[b, :, j] = y[b] if same else np.where(inside, np.interp(self.time, t_sim, y[b]), np.nan)
        return (out, res) if full else out

    def _one_by_one(self, flats: np.ndarray, m: "Model", full: bool) -> Any:
        out = np.full((flats.shape[0], len(self.time), len(self.channels)), np.nan)
        res = None
        for b in range(flats.shape[0]):
            sims, res_b = self.simulate(flats[b : b + 1], m, full=True)
            out[b] = sims[0]
            res = res_b if res_b is not None else res
        return (out, res) if full else out

    def nominal_simulation(self) -> np.ndarray:
        """(n, C) the model as given, simulated once (:meth:`nominal_result`) and kept."""
        if self._nominal is None:
            self.check_cancel()
            m = self.model
            if self.closed:
                res: Any = Shifted(m.run_task(self.task, duration=self.duration, q0=self.q0.tolist(), sample_rate=self.sample_rate), self.t0)
            else:
                res = m.replay(self.t_enc, self.q_enc, sample_rate=self.sample_rate, initial_q=self.iq, initial_v=self.iv)
            self.nfev += 1
            self._nominal = (self._on_stamps(res), res)
        return self._nominal[0]

    def _on_stamps(self, res: Any) -> np.ndarray:
        t_sim = res.time
        same = len(t_sim) == len(self.time) and np.array_equal(t_sim, self.time)
        inside = (self.time >= t_sim[0] - 1e-12) & (self.time <= t_sim[-1] + 1e-12)
        out = np.full((len(self.time), len(self.channels)), np.nan)
        for j, c in enumerate(self.channels):
            y = res.channel(c)
            out[:, j] = y if same else np.where(inside, np.interp(self.time, t_sim, y), np.nan)
        return out

    def replay_angles(self, q_enc: np.ndarray) -> np.ndarray:
        """(n, C) the model replaying encoder angles ``q_enc`` [rad] (n_enc, 3) on :attr:`t_enc`,
        on the measured stamps (the encoder bootstrap, :mod:`popup.unseen`)."""
        self.check_cancel()
        res = self.model.replay(self.t_enc, q_enc, sample_rate=self.sample_rate, initial_q=self.iq, initial_v=self.iv)
        self.nfev += 1
        return self._on_stamps(res)

    def nominal_result(self) -> Any:
        """The nominal replay's full result (a :class:`~popup.SimResult`, or the closed-loop
        result on the run's clock)."""
        self.nominal_simulation()
        assert self._nominal is not None
        return self._nominal[1]

    # ------------------------------------------------------------------ residuals and errors
    def residuals(self, sims: np.ndarray) -> np.ndarray:
        """Residuals in noise units ``(ŷ − y)/σ``, same shape as ``sims``; NaN where a side
        is missing; a failed run is NaN everywhere. With ``offsets`` each channel's mean
        over the samples used is taken out."""
        z = (np.asarray(sims) - self.measured) / self.sigma
        if self.fit_offsets:
            # the constant per channel profiled out (its least-squares value: the mean)
            with np.errstate(invalid="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # a failed run: all NaN, stays NaN
                z = z - np.nanmean(z[..., self.used, :], axis=-2, keepdims=True)
        return z

    def channel_stats(self, z: np.ndarray, mask: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per channel over ``mask`` (default :attr:`used`: every sample but a start-up
        transient, module docs): mean z² (= r_c²), the number of
        finite samples and the lag-1 autocorrelation of the residual."""
        z = np.asarray(z)
        z = z[self.used if mask is None else mask]
        C = z.shape[1]
        ms, n, rho = np.full(C, np.nan), np.zeros(C), np.zeros(C)
        for j in range(C):
            x = z[:, j]
            x = x[np.isfinite(x)]
            n[j] = x.size
            if x.size == 0:
                continue
            ms[j] = float(np.mean(x * x))
            if x.size > 2:
                xc = x - x.mean()
                d = float(np.dot(xc, xc))
                rho[j] = float(np.dot(xc[1:], xc[:-1]) / d) if d > 0 else 0.0
        return ms, n, rho

    def error(self, z: Optional[np.ndarray] = None, mask: Optional[np.ndarray] = None) -> Tuple[float, Dict[str, float]]:
        """The systematic error S (:data:`ERROR_DEFINITION`) and each channel's noise
        multiple r_c, of residual ``z`` (n, C) (default: the model as given)."""
        if z is None:
            z = self.residuals(self.nominal_simulation())
        ms, n, _ = self.channel_stats(z, mask)
        if not np.all(np.isfinite(ms)):
            return math.inf, {c: math.inf for c in self.channels}
        return systematic(ms), {c: float(math.sqrt(m)) for c, m in zip(self.channels, ms)}

    def _spike_devs(self, z: np.ndarray) -> List[Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]]]:
        """Per channel of the residual ``z`` (n, C): the :attr:`used` finite rows, their
        values and their deviations from the median of the :data:`SPIKE_WINDOW` around them
        (``None`` for a channel with fewer rows than that)."""
        from scipy.ndimage import median_filter

        out: List[Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]]] = []
        for j in range(z.shape[1]):
            ok = np.flatnonzero(np.isfinite(z[:, j]) & self.used)
            if len(ok) < SPIKE_WINDOW:
                out.append(None)
                continue
            x = z[ok, j]
            out.append((ok, x, x - median_filter(x, size=SPIKE_WINDOW, mode="nearest")))
        return out

    def spike_mask(self, z: np.ndarray) -> np.ndarray:
        """The isolated spikes of the residual ``z`` (n, C) in noise units, as a boolean
        (n, C) array: the :attr:`used` samples further than :data:`SPIKE_SIGMA` from the
        median of the :data:`SPIKE_WINDOW` finite samples around them (:meth:`spikes`)."""
        z = np.asarray(z, dtype=float)
        hit = np.zeros(z.shape, dtype=bool)
        for j, d in enumerate(self._spike_devs(z)):
            if d is not None:
                hit[d[0], j] = np.abs(d[2]) > SPIKE_SIGMA
        return hit

    def spikes(self, z: Optional[np.ndarray] = None) -> Dict[str, Dict[str, Any]]:
        """Isolated spikes in the residual ``z`` (n, C) in noise units (default: the model as
        given): per channel with any, the samples further than :data:`SPIKE_SIGMA` from the
        median of the :data:`SPIKE_WINDOW` around them, as ``{"count", "times" (s, first 5),
        "share"}``, ``share`` the part of the channel's excess ``Σ z² − n`` they make.
        Sensor glitches (or impacts shorter than a sample) that no smooth model fits."""
        if z is None:
            z = self.residuals(self.nominal_simulation())
        z = np.asarray(z, dtype=float)
        out: Dict[str, Dict[str, Any]] = {}
        t = np.asarray(self.time, dtype=float)
        for c, d in zip(self.channels, self._spike_devs(z)):
            if d is None:
                continue
            ok, x, dev = d
            hit = np.abs(dev) > SPIKE_SIGMA
            if not hit.any():
                continue
            excess = float(np.sum(x * x)) - len(x)
            part = float(np.sum(x[hit] ** 2 - (x[hit] - dev[hit]) ** 2))
            out[c] = {"count": int(hit.sum()), "times": [float(v) for v in t[ok[hit]][:5]],
                      "share": float(min(max(part / excess, 0.0), 1.0)) if excess > 0 else 0.0}
        return out

    def offsets(self, z: Optional[np.ndarray] = None) -> Dict[str, Dict[str, float]]:
        """The constant part of the residual ``z`` (n, C) in noise units (default: the model
        as given, its offsets not taken out whatever ``offsets``), per channel with a finite one: ``offset`` = mean(y − ŷ) in the channel's
        unit (what the measured channel reads above the model: a sensor bias, a calibration
        offset), ``z_mean`` the same in noise units and ``share`` the part of the channel's
        excess ``Σ z² − n`` it makes (``n·mean(z)²`` of it, 0..1), with ``n`` and ``excess``
        themselves. The spectrum of the
        residual leaves the mean out (:attr:`~popup.Comparison.spectrum`); this is it."""
        if z is None:
            z = (self.nominal_simulation() - self.measured) / self.sigma
        out: Dict[str, Dict[str, float]] = {}
        for j, c in enumerate(self.channels):
            x = z[self.used, j]
            x = x[np.isfinite(x)]
            if x.size < 2:
                continue
            m = float(np.mean(x))
            excess = float(np.sum(x * x)) - x.size
            out[c] = {"offset": -m * float(self.sigma[j]), "z_mean": m, "n": float(x.size), "excess": excess,
                      "share": float(min(max(x.size * m * m / excess, 0.0), 1.0)) if excess > 0 else 0.0}
        return out


class Cancelled(BaseException):
    """A candidate's work stopped because another thread was interrupted
    (:meth:`ReplayProblem.fork`). A ``BaseException``, like ``KeyboardInterrupt``: the
    handlers that keep one failing candidate from stopping a ranking do not catch it. It
    never reaches the user: the interrupt that caused it is raised instead."""


def systematic(ms: np.ndarray) -> float:
    """S = sqrt(max(mean_c r_c² − 1, 0)) from the per-channel mean squares r_c²."""
    return float(math.sqrt(max(float(np.mean(ms)) - 1.0, 0.0)))


def _floors(t: np.ndarray, resid: np.ndarray, y: np.ndarray, channels: Sequence[str]) -> List[float]:
    """The noise floor of each channel (columns of ``resid``) from its residual, with the
    colour a channel leaves unresolved taken from its sensor kind (:func:`noise_stds`);
    from the measured ``y`` where the residual gives none."""
    s = noise_stds(t, [resid[:, j] for j in range(resid.shape[1])], [SENSORS.get(c, c) for c in channels], correlation_s=CORRELATION_S)
    out = []
    for j, v in enumerate(s):
        if not (math.isfinite(v) and v > 0):
            v = noise_std(t, y[:, j], correlation_s=CORRELATION_S)
        out.append(v if math.isfinite(v) else 0.0)
    return out


def holdout_split(t: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """``(train, validation)`` boolean masks of the stamps ``t`` [s]: the span cut in
    ``n`` equal blocks (at least :data:`N_BLOCKS`, a multiple of 3 with none longer than
    :data:`BLOCK_MAX_S`), every third from the second (0-based 1, 4, 7, …) held out."""
    span = float(t[-1] - t[0]) if len(t) else 0.0
    n = max(N_BLOCKS, 3 * math.ceil(span / (3.0 * BLOCK_MAX_S) - 1e-9))
    edges = np.linspace(t[0], t[-1], n + 1)
    b = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, n - 1)
    val = b % 3 == 1
    return ~val, val


def _smooth(t: np.ndarray, q: np.ndarray) -> Any:
    try:
        from .smoothing import smooth_encoder
    except ImportError:  # pragma: no cover - the module lands with the smoothing work
        return None
    return smooth_encoder(t, q)
