"""Compare a model with a measured run: replay the experiment, align in time, and say
how well (and where) the model fits.

::

    run = popup.read_run("runs/step")
    cmp = popup.compare.compare(run.model(), run)
    cmp.to_pandas()            # per-channel RMSE, fit %, max |error|
    cmp.overall                # mean fit %, normalised RMSE
    cmp.conditions             # which operating conditions carry the error
    cmp.plot("residuals")

What is computed
----------------
**Replay.** ``replay = "encoder"``: the motor joints follow the measured encoder angles
(:meth:`MeasuredRun.encoder`, rows with a missing angle skipped), smoothed at their
noise level (:func:`popup.smoothing.smooth_encoder`: a quantised encoder interpolated as
is would make q̈, and so the torques, noisy), through :meth:`Model.replay`; the run
starts at rest (bending joints in static equilibrium at
the first encoder sample) unless ``experiment.toml`` has an ``[initial]`` table with
the bending angles ``d11 d12 d21 d22`` [rad] and rates ``dd11 dd12 dd21 dd22``
[rad/s] (or lists ``bending`` / ``bending_rate``, 4 values each). ``replay =
"reference"``: the controller of the run's ``[controller]`` table tracks the references
in closed loop.

**Sample rate of the simulation.** The model's output period must be a multiple of its
step ``dt``. By default the output period is ``k·dt`` with the largest whole ``k`` such
that the simulated rate ``1/(k·dt)`` is at least the run's mean rate
``(N − 1)/(t_N − t_1)`` (so a 500 Hz run with ``dt = 1 ms`` is simulated at 500 Hz, a
300 Hz run at 500 Hz); a run sampled faster than ``1/dt``, or whose stamps are not on
that grid (jitter), is simulated at every step ``1/dt``. ``sample_rate=`` overrides it.

**Alignment.** The simulation is interpolated linearly onto the measured time stamps;
the measured data is never modified. Measured samples outside the simulated time span
and missing (NaN) measured cells are left out of every metric; :attr:`Comparison.notes`
says what was done.

**Channels.** Every measured column that the simulation also produces, except ``t``,
the replay inputs (``q1..q3``) and their spline derivatives (``dq1..dq3``), and the
pressures ``p1 p2`` when they are constant (a pressure that only carries sensor noise is
compared: it sits at its noise floor, ``at_noise_floor``, and adds nothing to the error). For an encoder replay the
default set is ``tau1..3, ee_x..z, imu1_a*, imu2_a*``. ``channels=`` overrides it (any
channel both sides have; comparing ``q``/``dq`` is allowed and noted).

**Metrics** (per channel, over the samples where both sides are finite), with the
residual ``e = y − ŷ`` (measured − simulated):

* ``rmse = sqrt(mean(e²))`` in the channel's unit;
* ``nrmse_fit_pct = 100·(1 − ‖y − ŷ‖/‖y − mean(y)‖)`` (100 % = perfect, 0 % = no
  better than the measured mean, negative = worse). This is the *free-run simulation*
  error of the model over the whole horizon (the model sees only the encoder inputs,
  never the measured outputs), not a one-step-ahead prediction error, so it is much
  stricter than the fit % of a one-step predictor;
* ``max_abs_error`` and ``t_max_error`` [s];
* ``mean_error = mean(e)`` [unit], the error's constant part (a sensor bias, a calibration
  offset, a static load), and ``mean_share = mean(e)²/rmse²``, the share of the mean
  squared error it makes (the residual spectrum leaves it out);
* ``nrmse = rmse / std(y)`` (dimensionless);
* ``noise_multiple = rmse / σ`` with σ the channel's white-noise floor estimated from
  the data (:mod:`popup.noise`): 1 = the model is at the noise floor on this channel.
  The overall ``error`` is the systematic error in noise units that the diagnosis
  fits and ranks by (:data:`popup.problem.ERROR_DEFINITION`).

The replay set-up (channels, output rate, the smoothed encoder, the noise floor) is a
:class:`popup.ReplayProblem`, shared with the diagnosis and the fits.

Overall: ``fit_pct`` is the mean of the per-channel fit %, ``nrmse`` the mean of the
per-channel ``rmse/std(y)``.

**Residual analysis** (on a uniform grid at the run's mean rate; the residuals are
interpolated onto it only when the measured rate varies, and gaps are filled linearly,
both noted), as MATLAB ``resid``:

* whiteness: the normalised autocorrelation ``r_e(k)`` for ``k = 0..L`` (default
  ``L = 25`` samples), the 99 % band ``±2.58/√N``, the fraction of lags ``1..L``
  outside it and ``is_white`` (at most 5 % of the lags, at least one allowed, outside
  the band); the Ljung–Box statistic and its p-value are given too;
* residual–input cross-correlation ``r_eu(τ) = Σ e(t+τ) u(t) / (N σ_e σ_u)`` for
  ``τ = −L..L`` (positive τ: the residual follows the input), against the joint rates
  ``dq1..dq3`` (the measured ``dq`` columns, or the derivative of the encoder angles
  when they are absent); the 99 % band ``2.58·sqrt(Σ_k r_e(k) r_u(k) / N)`` takes the
  autocorrelation of the input into account; the peak lag [s] and value, the fraction
  of lags outside the band and ``significant`` (more than 5 % of the lags outside);
* delay: the shift ``τ`` [s] in ``−L..L`` that minimises the mean squared difference
  of the measured ``y(t + τ)`` and the simulated ``ŷ(t)`` over their overlap
  (positive: the measurement lags the model, as a sensor delay does);
* spectrum: Welch PSD of the residual (``scipy.signal.welch``), the frequency of the
  peak, and the fraction of residual energy per octave band (``[f_N/2, f_N]``,
  ``[f_N/4, f_N/2]``, ..., the last band down to 0 Hz; ``f_N`` the Nyquist
  frequency), with the band carrying the most.

**Where the model fails.** The squared residuals, each channel divided by its measured
standard deviation so that channels of different units add up, are shared out over:

* time windows (``n_windows`` equal windows, default 10): RMSE per channel and
  normalised RMSE per window, share of squared error; the worst windows first in
  :attr:`Comparison.windows` order by ``rank``;
* operating conditions (:attr:`Comparison.conditions`): the sign of each joint rate
  (``-``, ``0`` when ``|dq| < max(1e-3 rad/s, 5 % of max |dq|)``, ``+``; from the
  measured ``dq`` or the encoder derivative), the simulated ``max(|M|/M_w)`` of the two
  links (``0-0.5``, ``0.5-0.8``, ``0.8-1``, ``>1``), the simulated tip speed
  ``|d ee/dt|`` (terciles ``low``, ``mid``, ``high``), and the time since the start
  (thirds). Each bin gets its share of the samples, its share of the squared error,
  their ratio (``> 1``: the bin carries more than its share) and the share of each
  channel. Per binning the shares sum to 1.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from .exceptions import InputError, MeasuredRunError
from .io import MeasuredRun
from .model import check_names, check_scalar
from .problem import DEFAULT_CHANNELS, ReplayProblem
from .results import UNITS, SimResult

if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd

    from .model import Model

__all__ = ["Comparison", "compare", "DEFAULT_CHANNELS"]

_Z99 = 2.58
_MOMENT_EDGES = (0.5, 0.8, 1.0)
_MOMENT_LABELS = ("0-0.5", "0.5-0.8", "0.8-1", ">1")
_GROUP_ORDER = (
    ("torque", ("tau1", "tau2", "tau3")),
    ("end effector", ("ee_x", "ee_y", "ee_z")),
    ("imu1", ("imu1_ax", "imu1_ay", "imu1_az")),
    ("imu2", ("imu2_ax", "imu2_ay", "imu2_az")),
    ("encoder", ("q1", "q2", "q3")),
    ("encoder rate", ("dq1", "dq2", "dq3")),
    ("pressure", ("p1", "p2")),
)


def _pd() -> Any:
    import pandas

    return pandas


# ---------------------------------------------------------------------------- result


@dataclass(eq=False)
class Comparison:
    """The comparison of a model with a measured run (see the module docs for every
    definition).

    Attributes
    ----------
    metrics : DataFrame
        One row per compared channel (index ``channel``): ``rmse`` [channel unit],
        ``nrmse_fit_pct`` [%], ``max_abs_error`` [unit], ``t_max_error`` [s], ``mean_error``
        [unit] and ``mean_share`` (the error's constant part and its share of rmse²), ``unit``,
        ``nrmse`` (rmse / measured std), ``n_samples``, ``noise_std`` (the channel's
        white-noise floor σ, :mod:`popup.noise`), ``noise_multiple`` (rmse/σ: 1 = at the
        noise floor), ``at_noise_floor`` (the measured signal itself is at its noise floor).
    overall : dict
        ``fit_pct`` (mean of the per-channel fit %), ``nrmse`` (mean of rmse/std),
        ``n_channels``, ``n_samples``, ``worst_channel``, ``white_fraction``, ``error``
        (the systematic error in noise units, :data:`popup.problem.ERROR_DEFINITION`),
        ``noise_multiple`` (RMS over channels of rmse/σ), ``at_noise_floor``.
    residuals : DataFrame
        Measured − simulated, indexed by the measured ``t`` [s], one column per channel
        (NaN where a side is missing).
    whiteness : DataFrame
        Per channel: ``n``, ``lags``, ``band``, ``fraction_outside``, ``is_white``,
        ``ljung_box_q``, ``ljung_box_p``.
    autocorrelation : DataFrame
        Normalised residual autocorrelation, index ``lag`` (samples 0..L), one column per
        channel.
    cross_correlation : DataFrame
        One row per (channel, input): ``peak_lag_s``, ``peak_lag_samples``,
        ``peak_value``, ``band``, ``fraction_outside``, ``significant``.
    cross_correlation_curves : dict
        Input name → DataFrame (index ``lag_s``, one column per channel).
    delay : DataFrame
        Per channel: ``delay_s``, ``delay_samples`` (the shift τ in −L..L minimising the
        mean squared difference of the measured ``y(t + τ)`` and the simulated ``ŷ(t)``
        over the overlap; positive = the measurement lags the model), ``rmse_at_delay``,
        ``rmse_at_zero``, ``at_limit`` (the best shift is ±L: no clear delay, or one
        longer than L samples).
    spectrum : DataFrame
        Per channel: ``peak_hz`` (the strongest frequency of the residual, from the
        periodogram of the whole record, placed to a fraction of 1/T), ``line_fraction`` (the
        share of the residual's power within ``line_halfwidth_hz`` = 2/T of that peak: near 1
        for a periodic error, a few bins' share for a broadband one), ``dominant_band``
        (``"lo-hi Hz"``, the octave band holding most of the Welch PSD), ``dominant_band_lo_hz``,
        ``dominant_band_hi_hz``, ``dominant_fraction`` and ``frac <band>`` columns.
    psd : DataFrame
        Welch PSD of the residuals, index ``f_hz``, [unit²/Hz].
    windows : DataFrame
        One row per time window: ``t_start``, ``t_end``, ``n``, ``nrmse`` (mean of
        rmse/std), ``error_share``, ``rank`` (1 = worst), ``rmse <channel>`` columns.
    conditions : DataFrame
        One row per (binning, bin): ``n``, ``sample_share``, ``error_share``, ``ratio``
        and ``share <channel>`` columns.
    notes : list of str
        What was done: sample rate, resampling, rows skipped, channels compared.
    simulated : SimResult
    measured : MeasuredRun
    params : dict
        ``model.describe()``.
    """

    metrics: "pd.DataFrame"
    overall: Dict[str, Any]
    residuals: "pd.DataFrame"
    whiteness: "pd.DataFrame"
    cross_correlation: "pd.DataFrame"
    spectrum: "pd.DataFrame"
    windows: "pd.DataFrame"
    conditions: "pd.DataFrame"
    notes: List[str]
    simulated: SimResult
    measured: MeasuredRun
    params: Dict[str, Any]
    autocorrelation: "pd.DataFrame" = field(default=None, repr=False)  # type: ignore[assignment]
    cross_correlation_curves: Dict[str, "pd.DataFrame"] = field(default_factory=dict, repr=False)
    delay: "pd.DataFrame" = field(default=None, repr=False)  # type: ignore[assignment]
    psd: "pd.DataFrame" = field(default=None, repr=False)  # type: ignore[assignment]
    simulated_aligned: "pd.DataFrame" = field(default=None, repr=False)  # type: ignore[assignment]

    @property
    def channels(self) -> List[str]:
        """The compared channels."""
        return [str(c) for c in self.metrics.index]

    def __repr__(self) -> str:
        o = self.overall
        return (
            f"Comparison(channels={self.channels}, fit_pct={o.get('fit_pct', math.nan):.2f}, "
            f"nrmse={o.get('nrmse', math.nan):.4g}, source={str(self.measured.source)!r})"
        )

    def to_pandas(self) -> "pd.DataFrame":
        """The per-channel metrics table (a copy of :attr:`metrics`)."""
        return self.metrics.copy()

    def to_dict(self) -> Dict[str, Any]:
        """Everything but the time series, as plain JSON-serialisable Python (NaN and
        infinities become None): ``params``, ``overall``, ``metrics``, ``whiteness``,
        ``cross_correlation``, ``delay``, ``spectrum``, ``windows``, ``conditions``,
        ``notes``, ``source``."""
        out: Dict[str, Any] = {
            "source": str(self.measured.source),
            "params": _jsonable(self.params),
            "overall": _jsonable(self.overall),
            "metrics": _records(self.metrics, "channel"),
            "whiteness": _records(self.whiteness, "channel"),
            "cross_correlation": _records(self.cross_correlation, None),
            "delay": _records(self.delay, "channel") if self.delay is not None else [],
            "spectrum": _records(self.spectrum, "channel"),
            "windows": _records(self.windows, None),
            "conditions": _records(self.conditions, None),
            "notes": list(self.notes),
        }
        json.dumps(out, allow_nan=False)  # fail here, not in the caller, if something slipped through
        return out

    def plot(self, kind: str = "overlay", *, channels: Optional[Sequence[str]] = None) -> Any:
        """``"overlay"``: measured and simulated per channel, one panel per channel group;
        ``"residuals"``: residual time series, autocorrelation with its 99 % band,
        residual–input cross-correlation, and residual spectrum. Returns the figure."""
        from .plot import pyplot

        plt = pyplot()
        chans = list(channels) if channels is not None else self.channels
        unknown = [c for c in chans if c not in self.channels]
        if unknown:
            raise InputError(f"plot channels {unknown} were not compared; compared: {self.channels}")
        t = self.residuals.index.to_numpy()
        if kind == "overlay":
            groups = _groups(chans)
            fig, axes = plt.subplots(len(groups), 1, sharex=True, figsize=(9, 2.4 * len(groups)), squeeze=False)
            for ax, (gname, g) in zip(axes[:, 0], groups):
                for i, c in enumerate(g):
                    col = f"C{i}"
                    ax.plot(t, self.measured.channel(c), color=col, lw=1.0, label=f"{c} measured")
                    ax.plot(t, self.simulated_aligned[c].to_numpy(), color=col, lw=1.0, ls="--", label=f"{c} model")
                ax.set_ylabel(f"{gname} [{UNITS.get(g[0], '')}]")
                ax.legend(loc="upper right", fontsize="x-small", ncol=2)
                ax.grid(True, alpha=0.3)
            axes[-1, 0].set_xlabel("t [s]")
            fig.suptitle(f"measured vs model: mean fit {self.overall['fit_pct']:.1f} %")
            return fig
        if kind == "residuals":
            fig, axes = plt.subplots(4, 1, figsize=(9, 11))
            ax = axes[0]
            for c in chans:
                s = float(self.metrics.loc[c, "std_measured"])
                ax.plot(t, self.residuals[c].to_numpy() / (s if s > 0 else 1.0), lw=0.8, label=c)
            ax.set_xlabel("t [s]")
            ax.set_ylabel("residual / std(y)")
            ax.set_title("residuals (measured − model)")
            ax = axes[1]
            ac = self.autocorrelation
            for c in chans:
                ax.plot(ac.index.to_numpy(), ac[c].to_numpy(), marker=".", lw=0.8, label=c)
            band = float(np.nanmax(self.whiteness["band"].to_numpy(dtype=float))) if len(self.whiteness) else 0.0
            ax.axhspan(-band, band, color="0.85", zorder=0, label="99 % band")
            ax.set_xlabel("lag [samples]")
            ax.set_ylabel("autocorrelation")
            ax = axes[2]
            for inp, df in self.cross_correlation_curves.items():
                for c in chans:
                    ax.plot(df.index.to_numpy(), df[c].to_numpy(), lw=0.8, label=f"{c} × {inp}")
            if len(self.cross_correlation):
                b = float(np.nanmax(self.cross_correlation["band"].to_numpy(dtype=float)))
                if np.isfinite(b):
                    ax.axhspan(-b, b, color="0.85", zorder=0)
            ax.set_xlabel("lag [s] (> 0: residual follows input)")
            ax.set_ylabel("cross-correlation")
            ax = axes[3]
            psd = self.psd
            f = psd.index.to_numpy()
            for c in chans:
                p = psd[c].to_numpy()
                if f.size > 1 and np.any(p[1:] > 0):
                    ax.semilogy(f[1:], np.where(p[1:] > 0, p[1:], np.nan), lw=0.8, label=c)
            ax.set_xlabel("f [Hz]")
            ax.set_ylabel("PSD [unit²/Hz]")
            for a in axes:
                a.grid(True, alpha=0.3)
                if a.get_legend_handles_labels()[0]:
                    a.legend(loc="upper right", fontsize="xx-small", ncol=3)
            fig.tight_layout()
            return fig
        raise InputError(f"plot kind {kind!r}: expected 'overlay' or 'residuals'")


# ---------------------------------------------------------------------------- compare


#: Most windows :func:`compare` reports (each costs a pass over the samples).
_MAX_WINDOWS = 1000


def compare(
    model: "Model",
    run: MeasuredRun,
    *,
    channels: Optional[Sequence[str]] = None,
    sample_rate: Optional[float] = None,
    lags: int = 25,
    n_windows: int = 10,
    problem: Optional["ReplayProblem"] = None,
) -> Comparison:
    """Replay ``run`` in ``model`` and compare (see the module docs).

    Parameters
    ----------
    model : Model
        The model to test (e.g. ``run.model()`` for the declared experiment).
    run : MeasuredRun
        From :func:`popup.read_run`: ``replay = "encoder"`` (the motors follow the encoder
        angles) or ``"reference"`` (closed loop: the controller of the run's ``[controller]``
        table tracks ``ref_q1..3`` and the encoder angles are predicted too; the model's
        ``dt`` must divide the controller period).
    channels : sequence of str, optional
        Channels to compare; default: every comparable channel (module docs).
    sample_rate : float, optional
        Output rate of the simulation [Hz] (``1/sample_rate`` a multiple of
        ``model.dt``); default: the coarsest such rate at least the run's mean rate.
    lags : int
        Largest lag L [samples] of the auto- and cross-correlations (default 25).
    n_windows : int
        Number of equal time windows (default 10).
    problem : ReplayProblem, optional
        The run already set up in this model (:class:`popup.ReplayProblem`: channels,
        rate, smoothed encoder, nominal replay, noise floor); built here when not given.

    Raises
    ------
    MeasuredRunError
        An unknown replay mode, a bad ``[controller]`` table, or no channel to compare.
    """
    pd = _pd()
    if not isinstance(run, MeasuredRun):
        raise InputError(f"compare: expected a popup.MeasuredRun (popup.read_run), got {type(run).__name__}")
    for name, val in (("lags", lags), ("n_windows", n_windows)):
        if isinstance(val, (bool, np.bool_)) or not isinstance(val, (int, np.integer)) or val < 1:
            raise InputError(f"compare: input {name}: expected an integer ≥ 1, got {val!r}")
    if n_windows > min(len(run), _MAX_WINDOWS):  # bounded work: a window needs a sample; each costs a pass
        raise InputError(
            f"compare: input n_windows: {n_windows} windows for a run of {len(run)} samples; at most "
            f"{min(len(run), _MAX_WINDOWS)} (one sample per window, and at most {_MAX_WINDOWS} rows in the window table)"
        )
    if channels is not None:
        channels = check_names("channels", channels)
    if sample_rate is not None:
        sample_rate = check_scalar("sample_rate", sample_rate, "Hz")
        if not (math.isfinite(sample_rate) and sample_rate > 0):
            raise InputError(f"compare: input sample_rate: {sample_rate!r} Hz must be finite and > 0")
    L = int(lags)
    if problem is None:
        problem = ReplayProblem(model, run, channels=channels, sample_rate=sample_rate)
    elif problem.run is not run or problem.model is not model:
        raise InputError("compare: problem= must be a ReplayProblem of this model and run")
    notes: List[str] = list(problem.notes)
    where = problem.where
    closed = problem.closed
    chans = list(problem.channels)

    # ---- declared experiment vs model
    if abs(float(model.payload_kg) - float(run.payload_kg)) > 0.0 or tuple(model.pressure_pa) != tuple(run.pressure_pa):
        notes.append(
            f"the model's payload {model.payload_kg:g} kg / pressures {model.pressure_pa} Pa differ from the "
            f"run's declared {run.payload_kg:g} kg / {run.pressure_pa} Pa (the model's are used)"
        )
    model_gravity = "gravity" not in list(model.core.disabled)
    if model_gravity != bool(run.gravity):
        notes.append(f"the model has gravity {'on' if model_gravity else 'off'} but the run declares gravity = {str(run.gravity).lower()}")

    # ---- replay (the problem's nominal replay)
    t_meas = run.time
    t_enc, q_enc = problem.t_enc, problem.q_enc_raw
    mean_dt = float(t_enc[-1] - t_enc[0]) / (len(t_enc) - 1)
    sr = problem.sample_rate
    sim: Any = problem.nominal_result()
    if closed:
        notes.append(
            f"closed-loop replay: the controller of the run's [controller] table tracks ref_q1..3 from rest at q = {np.round(problem.q0, 6).tolist()} rad; "
            "the encoder angles are predicted, not replayed"
        )

    # ---- align: simulation interpolated linearly onto the measured stamps
    t_sim = sim.time
    inside = (t_meas >= t_sim[0] - 1e-12) & (t_meas <= t_sim[-1] + 1e-12)
    n_out = int((~inside).sum())
    same_grid = len(t_sim) == len(t_meas) and np.array_equal(t_sim, t_meas)
    if same_grid:
        notes.append("the simulated samples fall on the measured time stamps: no interpolation needed")
    else:
        notes.append(f"simulation ({len(t_sim)} samples) interpolated linearly onto the {len(t_meas)} measured time stamps; the measured data is not modified")
    if n_out:
        notes.append(f"{n_out} measured row(s) outside the simulated span [{t_sim[0]:.6g}, {t_sim[-1]:.6g}] s left out")

    def sim_at(name: str) -> np.ndarray:
        y = sim.channel(name)
        out = np.full(t_meas.shape, np.nan)
        out[inside] = y if same_grid else np.interp(t_meas[inside], t_sim, y)
        return out

    ysim = {c: sim_at(c) for c in chans}
    ymeas = {c: run.channel(c) for c in chans}
    aligned = pd.DataFrame(ysim, index=pd.Index(t_meas, name="t"))
    resid = pd.DataFrame({c: ymeas[c] - ysim[c] for c in chans}, index=pd.Index(t_meas, name="t"))
    for c in chans:
        nmiss = int((~np.isfinite(ymeas[c]) & inside).sum())
        if nmiss:
            notes.append(f"{c}: {nmiss} missing (NaN) measured sample(s) skipped")

    # ---- metrics
    rows = []
    for c in chans:
        y, yh = ymeas[c], ysim[c]
        ok = np.isfinite(y) & np.isfinite(yh)
        n = int(ok.sum())
        if n == 0:
            rows.append(dict(channel=c, rmse=math.nan, nrmse_fit_pct=math.nan, max_abs_error=math.nan, t_max_error=math.nan,
                             mean_error=math.nan, mean_share=math.nan, unit=UNITS.get(c, ""), nrmse=math.nan, std_measured=math.nan,
                             n_samples=0))
            continue
        e = y[ok] - yh[ok]
        rmse = float(np.sqrt(np.mean(e * e)))
        dev = float(np.linalg.norm(y[ok] - np.mean(y[ok])))
        en = float(np.linalg.norm(e))
        fit = 100.0 * (1.0 - en / dev) if dev > 0 else (100.0 if en == 0 else -math.inf)
        std = float(np.std(y[ok]))
        i = int(np.argmax(np.abs(e)))
        me = float(np.mean(e))
        rows.append(dict(channel=c, rmse=rmse, nrmse_fit_pct=fit, max_abs_error=float(abs(e[i])),
                         t_max_error=float(t_meas[ok][i]), mean_error=me, mean_share=(me * me / (rmse * rmse) if rmse > 0 else 0.0),
                         unit=UNITS.get(c, ""),
                         nrmse=(rmse / std if std > 0 else (0.0 if rmse == 0 else math.inf)),
                         std_measured=std, n_samples=n))
    metrics = pd.DataFrame(rows).set_index("channel")
    sigma = problem.noise
    metrics["noise_std"] = [sigma[c] for c in chans]
    metrics["noise_multiple"] = metrics["rmse"] / metrics["noise_std"]
    metrics["at_noise_floor"] = [c in problem.at_floor for c in chans]
    valid = [c for c in chans if metrics.loc[c, "n_samples"] > 0]
    if not valid:
        raise MeasuredRunError(f"{where}: no sample where both the run and the simulation have {chans}")

    # ---- normalised squared error per sample (channels made comparable by std)
    scale = {c: (float(metrics.loc[c, "std_measured"]) or 1.0) for c in valid}
    e2 = {c: np.where(np.isfinite(resid[c].to_numpy()), (resid[c].to_numpy() / scale[c]) ** 2, 0.0) for c in valid}
    e2_all = np.sum([e2[c] for c in valid], axis=0)
    rowvalid = inside & np.any([np.isfinite(resid[c].to_numpy()) for c in valid], axis=0)

    # ---- residual analysis on a uniform grid
    fs = 1.0 / mean_dt
    uniform = bool(np.max(np.abs(np.diff(t_meas) - mean_dt)) <= 0.01 * mean_dt) if len(t_meas) > 2 else True
    tt = t_meas[inside]
    if uniform:
        tg = tt
    else:
        tg = tt[0] + np.arange(int(math.floor((tt[-1] - tt[0]) / mean_dt)) + 1) * mean_dt
        notes.append(f"the measured rate varies: residuals and inputs interpolated onto a uniform {fs:.6g} Hz grid for the correlation and spectral analysis")
    inputs, in_note = _inputs(run, t_enc, q_enc, t_meas)
    notes.append(in_note)
    ugrid: Dict[str, np.ndarray] = {}
    for c in valid:
        r = resid[c].to_numpy()[inside]
        okr = np.isfinite(r)
        if not okr.all() and okr.sum() >= 2:
            notes.append(f"{c}: {int((~okr).sum())} gap sample(s) filled linearly for the correlation and spectral analysis")
        ugrid[c] = np.interp(tg, tt[okr], r[okr]) if (not uniform or not okr.all()) else r
    uin = {k: (np.interp(tg, tt, v[inside]) if not uniform else v[inside]) for k, v in inputs.items()}
    N = len(tg)
    if N <= 2 * L + 2:
        notes.append(f"only {N} samples for lags up to {L}: correlation results are weak")

    # whiteness
    acf_cols: Dict[str, np.ndarray] = {}
    wrows = []
    band = _Z99 / math.sqrt(N)
    Lw = min(L, N - 1)
    for c in valid:
        acf = _acf(ugrid[c], Lw)
        acf_cols[c] = acf
        if np.all(np.isnan(acf[1:])):
            frac, white, q, p = 0.0, True, 0.0, 1.0
            notes.append(f"{c}: the residual is identically zero (or constant): counted as white")
        else:
            out = np.abs(acf[1:]) > band
            frac = float(out.mean())
            white = bool(out.sum() <= max(1, int(math.floor(0.05 * Lw))))
            kk = np.arange(1, Lw + 1)
            q = float(N * (N + 2) * np.sum(acf[1:] ** 2 / (N - kk)))
            p = _chi2_sf(q, Lw)
        wrows.append(dict(channel=c, n=N, lags=Lw, band=band, fraction_outside=frac, is_white=white, ljung_box_q=q, ljung_box_p=p))
    whiteness = pd.DataFrame(wrows).set_index("channel")
    autocorr = pd.DataFrame(acf_cols, index=pd.Index(np.arange(Lw + 1), name="lag"))

    # residual-input cross-correlation
    lagv = np.arange(-Lw, Lw + 1)
    xrows = []
    curves: Dict[str, Any] = {}
    for name, u in uin.items():
        cols = {}
        ru = _acf(u, Lw)
        for c in valid:
            x = _xcorr(ugrid[c], u, Lw)
            cols[c] = x
            re = acf_cols[c]
            if np.all(np.isnan(x)):
                xrows.append(dict(channel=c, input=name, peak_lag_s=math.nan, peak_lag_samples=0, peak_value=0.0,
                                  band=math.nan, fraction_outside=0.0, significant=False))
                continue
            # MATLAB resid: band 2.58*sqrt(P/N), P = sum_k r_e(k) r_u(k) over k = -M..M
            if np.all(np.isfinite(ru)):
                P = float(re[0] * ru[0] + 2.0 * np.sum(re[1:] * ru[1:]))
            else:
                P = 1.0
            xb = _Z99 * math.sqrt(max(P, 1.0 / N) / N)
            i = int(np.nanargmax(np.abs(x)))
            outx = np.abs(x) > xb
            fo = float(outx.mean())
            xrows.append(dict(channel=c, input=name, peak_lag_s=float(lagv[i] / fs), peak_lag_samples=int(lagv[i]),
                              peak_value=float(x[i]), band=xb, fraction_outside=fo, significant=bool(fo > 0.05)))
        curves[name] = pd.DataFrame(cols, index=pd.Index(lagv / fs, name="lag_s"))
    xcorr = pd.DataFrame(xrows, columns=["channel", "input", "peak_lag_s", "peak_lag_samples", "peak_value", "band", "fraction_outside", "significant"])

    # delay (measured vs simulated): the shift that best lines the measurement up with the model
    drows = []
    for c in valid:
        y = ymeas[c][inside]
        yh = ysim[c][inside]
        ok = np.isfinite(y) & np.isfinite(yh)
        if ok.sum() < 2:
            drows.append(dict(channel=c, delay_s=math.nan, delay_samples=0, rmse_at_delay=math.nan, rmse_at_zero=math.nan, at_limit=False))
            continue
        yu = np.interp(tg, tt[ok], y[ok])
        yhu = np.interp(tg, tt[ok], yh[ok])
        mse = _shift_mse(yu, yhu, Lw)
        i = int(np.nanargmin(mse))
        drows.append(dict(channel=c, delay_s=float(lagv[i] / fs), delay_samples=int(lagv[i]),
                          rmse_at_delay=float(np.sqrt(mse[i])), rmse_at_zero=float(np.sqrt(mse[Lw])),
                          at_limit=bool(abs(int(lagv[i])) == Lw)))
    delay = pd.DataFrame(drows).set_index("channel")

    # spectrum
    spectrum, psd = _spectrum(ugrid, valid, fs)

    # ---- windows
    nw = int(n_windows)
    t0, t1 = float(tt[0]), float(tt[-1])
    edges = np.linspace(t0, t1, nw + 1)
    widx = np.clip(np.searchsorted(edges, t_meas, side="right") - 1, 0, nw - 1)
    tot = float(e2_all[rowvalid].sum())
    wrows2 = []
    for w in range(nw):
        m = rowvalid & (widx == w)
        row: Dict[str, Any] = dict(window=w, t_start=float(edges[w]), t_end=float(edges[w + 1]), n=int(m.sum()))
        nr = []
        for c in valid:
            r = resid[c].to_numpy()[m]
            r = r[np.isfinite(r)]
            v = float(np.sqrt(np.mean(r * r))) if r.size else math.nan
            row[f"rmse {c}"] = v
            if r.size:
                nr.append(v / scale[c])
        row["nrmse"] = float(np.mean(nr)) if nr else math.nan
        row["error_share"] = float(e2_all[m].sum() / tot) if tot > 0 else (1.0 / nw)
        wrows2.append(row)
    windows = pd.DataFrame(wrows2)
    order = np.argsort(-np.nan_to_num(windows["nrmse"].to_numpy(dtype=float), nan=-1.0), kind="stable")
    rank = np.empty(nw, dtype=int)
    rank[order] = np.arange(1, nw + 1)
    windows.insert(4, "rank", rank)
    cols_order = ["window", "t_start", "t_end", "n", "rank", "nrmse", "error_share"] + [f"rmse {c}" for c in valid]
    windows = windows[cols_order]

    # ---- conditions
    conditions = _conditions(sim, t_meas, inputs, e2, e2_all, rowvalid, valid, model, notes)

    # ---- overall
    fits = metrics.loc[valid, "nrmse_fit_pct"].to_numpy(dtype=float)
    nrm = metrics.loc[valid, "nrmse"].to_numpy(dtype=float)
    overall: Dict[str, Any] = {
        "fit_pct": float(np.mean(fits)),
        "nrmse": float(np.mean(nrm)),
        "n_channels": len(valid),
        "n_samples": int(rowvalid.sum()),
        "worst_channel": str(valid[int(np.argmin(fits))]),
        "white_fraction": float(np.mean(whiteness["is_white"].to_numpy(dtype=bool))),
        "sample_rate_hz": sr,
        "measured_rate_hz": fs,
        "worst_window": [float(windows.loc[order[0], "t_start"]), float(windows.loc[order[0], "t_end"])],
        "error": problem.error()[0],
        "noise_multiple": float(np.sqrt(np.mean(np.square(metrics.loc[valid, "noise_multiple"].to_numpy(dtype=float))))),
        "at_noise_floor": list(problem.at_floor),
    }
    notes.append(f"compared {len(valid)} channel(s): {', '.join(valid)}")
    return Comparison(
        metrics=metrics,
        overall=overall,
        residuals=resid,
        whiteness=whiteness,
        cross_correlation=xcorr,
        spectrum=spectrum,
        windows=windows,
        conditions=conditions,
        notes=notes,
        simulated=sim,
        measured=run,
        params=model.describe(),
        autocorrelation=autocorr,
        cross_correlation_curves=curves,
        delay=delay,
        psd=psd,
        simulated_aligned=aligned,
    )


# ---------------------------------------------------------------------------- helpers


def _inputs(run: MeasuredRun, t_enc: np.ndarray, q_enc: np.ndarray, t_meas: np.ndarray) -> Tuple[Dict[str, np.ndarray], str]:
    """Joint rates on the measured stamps: the measured dq columns when complete, else
    the derivative of the encoder angles."""
    out: Dict[str, np.ndarray] = {}
    used_meas = []
    for j in range(3):
        name = f"dq{j + 1}"
        y = run.channel(name) if name in run.columns else None
        if y is not None and np.isfinite(y).sum() >= 2:
            ok = np.isfinite(y)
            out[name] = y if ok.all() else np.interp(t_meas, t_meas[ok], y[ok])
            used_meas.append(name)
        else:
            out[name] = np.interp(t_meas, t_enc, np.gradient(q_enc[:, j], t_enc))
    if len(used_meas) == 3:
        note = "inputs for the cross-correlation and condition bins: the measured encoder rates dq1..dq3"
    elif used_meas:
        note = f"inputs: measured {', '.join(used_meas)}, the others the derivative of the encoder angles"
    else:
        note = "inputs for the cross-correlation and condition bins: the derivative of the encoder angles q1..q3 (no dq columns)"
    return out, note


def _acf(x: np.ndarray, L: int) -> np.ndarray:
    """Normalised autocorrelation for lags 0..L (biased estimate, as MATLAB resid);
    NaN where the signal is constant."""
    x = np.asarray(x, dtype=float)
    x = x - np.mean(x)
    r0 = float(np.dot(x, x))
    if not r0 > 0 or not np.isfinite(r0):
        return np.full(L + 1, np.nan)
    n = len(x)
    return np.array([float(np.dot(x[k:], x[: n - k])) / r0 if k < n else 0.0 for k in range(L + 1)])


def _xcorr(e: np.ndarray, u: np.ndarray, L: int) -> np.ndarray:
    """r(τ) = Σ e(t+τ) u(t) / (N σ_e σ_u) for τ = −L..L; NaN if one side is constant."""
    e = np.asarray(e, dtype=float) - np.mean(e)
    u = np.asarray(u, dtype=float) - np.mean(u)
    d = math.sqrt(float(np.dot(e, e)) * float(np.dot(u, u)))
    if not d > 0 or not np.isfinite(d):
        return np.full(2 * L + 1, np.nan)
    n = len(e)
    out = np.zeros(2 * L + 1)
    for i, k in enumerate(range(-L, L + 1)):
        if abs(k) >= n:
            continue
        out[i] = float(np.dot(e[k:], u[: n - k])) if k >= 0 else float(np.dot(e[: n + k], u[-k:]))
    return out / d


def _shift_mse(y: np.ndarray, yh: np.ndarray, L: int) -> np.ndarray:
    """mean((y(t+τ) − ŷ(t))²) over the overlapping samples, τ = −L..L."""
    n = len(y)
    out = np.full(2 * L + 1, np.nan)
    for i, k in enumerate(range(-L, L + 1)):
        if abs(k) >= n:
            continue
        d = (y[k:] - yh[: n - k]) if k >= 0 else (y[: n + k] - yh[-k:])
        out[i] = float(np.mean(d * d))
    return out


def _chi2_sf(q: float, dof: int) -> float:
    from scipy.special import gammaincc  # chi2.sf(q, k) = Q(k/2, q/2), without importing scipy.stats

    return float(gammaincc(0.5 * dof, 0.5 * q))


#: Half-width of a spectral line, in bins of the record's resolution 1/T: the main lobe of
#: the Hann window (±2/T) holds 99.5 % of a sinusoid's power whatever its frequency.
LINE_HALFWIDTH_BINS = 2.0


def _line(x: np.ndarray, fs: float) -> Tuple[float, float]:
    """The residual's strongest frequency [Hz] and the share of its power within
    ±:data:`LINE_HALFWIDTH_BINS`/T of it (near 1 for a sinusoid, about 8/n for white noise
    of n samples: 4/T of the fs/2 band). From the periodogram of the whole record (Hann window,
    zero-padded 8×, the peak placed by a parabola through the log power of its three bins):
    a sinusoid's frequency to a small fraction of 1/T, where Welch's averaged segments
    resolve only 4/T."""
    from scipy.signal import periodogram

    x = np.asarray(x, dtype=float)
    n = x.size
    if n < 8 or not np.all(np.isfinite(x)):
        return math.nan, math.nan
    nfft = 1 << (int(math.ceil(math.log2(n))) + 3)
    f, p = periodogram(x, fs=fs, window="hann", nfft=nfft, detrend="constant")
    if p.size < 4 or not np.any(p[1:] > 0):
        return math.nan, math.nan
    k = 1 + int(np.argmax(p[1:-1]))
    peak = float(f[k])
    a, b, c = p[k - 1], p[k], p[k + 1]
    if a > 0 and b > 0 and c > 0:
        la, lb, lc = math.log(a), math.log(b), math.log(c)
        den = la - 2.0 * lb + lc
        if den < 0:
            peak += float(np.clip(0.5 * (la - lc) / den, -0.5, 0.5)) * float(f[1] - f[0])
    w = LINE_HALFWIDTH_BINS * fs / n
    tot = float(np.sum(p[1:]))
    near = (np.abs(f - peak) <= w) & (f > 0)
    return peak, float(np.sum(p[near]) / tot) if tot > 0 else math.nan


def _spectrum(ugrid: Dict[str, np.ndarray], valid: List[str], fs: float) -> Tuple[Any, Any]:
    pd = _pd()
    from scipy.signal import welch

    n = min(len(v) for v in ugrid.values())
    nperseg = int(min(n, max(256, n // 4)))
    nyq = fs / 2.0
    # octave bands down from Nyquist; the last goes to 0 Hz and holds at least 2 bins
    df = fs / nperseg
    edges = [nyq]
    while edges[-1] / 2.0 > 2.0 * df and len(edges) < 12:
        edges.append(edges[-1] / 2.0)
    edges.append(0.0)
    edges = edges[::-1]  # ascending: 0, ..., nyq
    labels = [f"{edges[i]:.3g}-{edges[i + 1]:.3g} Hz" for i in range(len(edges) - 1)]
    rows = []
    cols: Dict[str, np.ndarray] = {}
    f_ref: Optional[np.ndarray] = None
    for c in valid:
        x = np.asarray(ugrid[c][:n], dtype=float)
        f, p = welch(x, fs=fs, nperseg=nperseg, detrend="constant")
        f_ref = f
        cols[c] = p
        row: Dict[str, Any] = dict(channel=c)
        tot = float(np.sum(p[1:])) if p.size > 1 else 0.0
        if tot > 0:
            fracs = []
            for i in range(len(edges) - 1):
                lo, hi = edges[i], edges[i + 1]
                m = (f > lo if i > 0 else f > 0) & ((f <= hi) if i < len(edges) - 2 else (f <= nyq + 1e-12))
                fracs.append(float(np.sum(p[m]) / tot))
            j = int(np.argmax(fracs))
            peak, line = _line(x, fs)
            row.update(peak_hz=peak, line_fraction=line, line_halfwidth_hz=LINE_HALFWIDTH_BINS * fs / x.size,
                       dominant_band=labels[j], dominant_band_lo_hz=float(edges[j]),
                       dominant_band_hi_hz=float(edges[j + 1]), dominant_fraction=fracs[j])
            row.update({f"frac {lab}": fr for lab, fr in zip(labels, fracs)})
        else:
            row.update(peak_hz=math.nan, line_fraction=math.nan, line_halfwidth_hz=LINE_HALFWIDTH_BINS * fs / max(x.size, 1),
                       dominant_band="", dominant_band_lo_hz=math.nan, dominant_band_hi_hz=math.nan, dominant_fraction=math.nan)
            row.update({f"frac {lab}": math.nan for lab in labels})
        rows.append(row)
    spectrum = pd.DataFrame(rows).set_index("channel")
    psd = pd.DataFrame(cols, index=pd.Index(f_ref if f_ref is not None else np.zeros(0), name="f_hz"))
    return spectrum, psd


def _conditions(
    sim: SimResult,
    t_meas: np.ndarray,
    inputs: Dict[str, np.ndarray],
    e2: Dict[str, np.ndarray],
    e2_all: np.ndarray,
    rowvalid: np.ndarray,
    valid: List[str],
    model: "Model",
    notes: List[str],
) -> Any:
    pd = _pd()
    t_sim = sim.time
    binnings: List[Tuple[str, np.ndarray, Sequence[str]]] = []
    for name, dq in inputs.items():
        thr = max(1e-3, 0.05 * float(np.nanmax(np.abs(dq)))) if np.any(np.isfinite(dq)) else 1e-3
        lab = np.where(dq > thr, "+", np.where(dq < -thr, "-", "0"))
        binnings.append((f"sign {name}", lab, ("-", "0", "+")))
    ratio = np.max(sim.moment_ratio, axis=1)
    rm = np.interp(t_meas, t_sim, ratio)
    idx = np.searchsorted(np.array(_MOMENT_EDGES), rm, side="right")
    binnings.append(("|M|/M_w", np.array(_MOMENT_LABELS, dtype=object)[idx], _MOMENT_LABELS))
    ee = sim.ee
    if len(t_sim) >= 2:
        v = np.linalg.norm(np.gradient(ee, t_sim, axis=0), axis=1)
    else:
        v = np.zeros(len(t_sim))
    vs = np.interp(t_meas, t_sim, v)
    q1, q2 = np.quantile(vs[rowvalid], [1.0 / 3.0, 2.0 / 3.0]) if rowvalid.any() else (0.0, 0.0)
    lab = np.where(vs <= q1, "low", np.where(vs <= q2, "mid", "high"))
    binnings.append(("tip speed", lab, ("low", "mid", "high")))
    tv = t_meas[rowvalid] if rowvalid.any() else t_meas
    e1, e2t = tv[0] + (tv[-1] - tv[0]) / 3.0, tv[0] + 2.0 * (tv[-1] - tv[0]) / 3.0
    lab = np.where(t_meas < e1, "first third", np.where(t_meas < e2t, "second third", "last third"))
    binnings.append(("time", lab, ("first third", "second third", "last third")))
    notes.append(
        f"condition bins: joint-rate sign (0 below max(1e-3 rad/s, 5 % of max |dq|)), simulated max |M|/M_w of the links "
        f"(M_w = {', '.join(f'{x:.4g}' for x in model.wrinkling_moment)} N·m), simulated tip speed terciles "
        f"({q1:.4g}, {q2:.4g} m/s), time thirds"
    )

    nvalid = int(rowvalid.sum())
    tot = float(e2_all[rowvalid].sum())
    tot_c = {c: float(e2[c][rowvalid].sum()) for c in valid}
    rows = []
    for bname, lab, order in binnings:
        for b in order:
            m = rowvalid & (lab == b)
            n = int(m.sum())
            ss = n / nvalid if nvalid else math.nan
            if tot > 0:
                es = float(e2_all[m].sum() / tot)
            else:
                es = ss  # no error at all: shares follow the samples
            row: Dict[str, Any] = dict(binning=bname, bin=b, n=n, sample_share=ss, error_share=es,
                                       ratio=(es / ss if ss > 0 else math.nan))
            for c in valid:
                row[f"share {c}"] = float(e2[c][m].sum() / tot_c[c]) if tot_c[c] > 0 else ss
            rows.append(row)
    return pd.DataFrame(rows)


def _groups(chans: Sequence[str]) -> List[Tuple[str, List[str]]]:
    out: List[Tuple[str, List[str]]] = []
    seen = set()
    for gname, members in _GROUP_ORDER:
        g = [c for c in members if c in chans]
        if g:
            out.append((gname, g))
            seen.update(g)
    for c in chans:
        if c not in seen:
            out.append((c, [c]))
    return out


def _jsonable(v: Any) -> Any:
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return [_jsonable(x) for x in v.tolist()]
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        f = float(v)
        return f if math.isfinite(f) else None
    if v is None or isinstance(v, str):
        return v
    return str(v)


def _records(df: Any, index_name: Optional[str]) -> List[Dict[str, Any]]:
    if df is None:
        return []
    d = df.reset_index() if index_name is not None else df
    return [_jsonable(r) for r in d.to_dict(orient="records")]
