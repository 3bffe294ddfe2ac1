"""Diagnose a model against a measured run: which effect of the library is missing?

::

    run = popup.read_run("examples/data/friction_run")
    model = run.model()
    d = popup.diagnose(model, run)          # every effect ranked
    d.to_pandas()                           # score, significant, error after, parameters
    better = d.best.apply(model)            # model.with_effect(...) with the fitted values
    h = popup.improve(model, run)           # the loop: add, refit, until nothing is left
    h.plot(); h.to_dict()

How a suspect is scored
-----------------------
**Error.** The free-run error of an encoder replay (the model sees only the encoder
angles, never the measured outputs), per channel ``NRMSE = RMSE / std(measured)``
(as :func:`popup.compare.compare` reports it), and overall the root mean square over
the compared channels (:data:`ERROR_DEFINITION`), so that the least-squares objective
and the reported error are the same quantity (``RSS = n·C·error²``).

**Fit.** For each effect, its parameters marked ``fit`` in the registry
(:mod:`popup.effects`) are fitted by bounded nonlinear least squares
(``scipy.optimize.least_squares``, trust-region reflective) on the normalised residuals
``(ŷ − y)/std(y)`` of every compared channel and sample. The Jacobian is by forward
differences, all columns in one batched rollout (Rust, GIL released, all cores).

**Significance.** Residuals of a free-run simulation are strongly autocorrelated, so
the ``n`` samples are not ``n`` independent observations. The effective count is
``n_eff = Σ_c n_c (1 − ρ_c)/(1 + ρ_c)`` with ``ρ_c`` the lag-1 autocorrelation of channel
c's residual after the fit (the AR(1) variance-inflation factor). The score is the BIC
improvement ``n_eff ln(RSS₀/RSS₁) − k ln(n_eff)`` (k fitted parameters); an effect is
*significant* when the score is above :data:`SCORE_THRESHOLD` and the overall error
drops by at least :data:`MIN_RELATIVE_DROP`. A model with nothing missing leaves white
noise, every candidate only fits noise, and none passes.

**Confidence intervals.** 95 %, from the Gauss–Newton covariance at the optimum
``s² (JᵀJ)⁻¹`` with ``s² = RSS/(n − k)``, inflated by ``n/n_eff`` for the residual
correlation.

**Evidence.** Each suspect carries the residual signature of ``effects.md`` measured on
the nominal residual (e.g. the regression of the torque residual on sign(q̇) and q̇ for
friction, the delay that best aligns the measurement for a sensor delay).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from . import effects as fx
from .compare import Comparison, compare
from .exceptions import InputError, MeasuredRunError
from .io import MeasuredRun

if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd

    from .model import Model

__all__ = [
    "Suspect",
    "Diagnosis",
    "History",
    "HistoryStep",
    "diagnose",
    "improve",
    "model_error",
    "ERROR_DEFINITION",
    "SCORE_THRESHOLD",
    "MIN_RELATIVE_DROP",
]

ERROR_DEFINITION = (
    "root mean square over the compared channels of NRMSE = RMSE/std(measured), the free-run error of the "
    "encoder replay (the model sees only the encoder angles, never the measured outputs): sqrt(mean_c NRMSE_c^2)"
)
_NUDGE = 0.2
_METHOD = "trf"
SCORE_THRESHOLD = 10.0
"""BIC improvement (with the effective sample count) above which an effect is significant."""
MIN_RELATIVE_DROP = 0.05
"""Smallest relative drop of the overall error for an effect to be significant."""

#: Typical magnitude of each fitted parameter (finite-difference steps and x_scale).
_SCALE: Dict[Tuple[str, str], float] = {
    ("joint_friction", "tau_c"): 1.0,
    ("joint_friction", "b"): 0.5,
    ("joint_friction", "tau_s"): 1.0,
    ("joint_friction", "v_s"): 0.05,
    ("backlash", "gap"): 0.01,
    ("higher_bending_modes", "k_scale"): 0.5,
    ("higher_bending_modes", "e_pa"): 1e8,
    ("higher_bending_modes", "lambda_s"): 1e-4,
    ("pressure_leak", "rate"): 0.01,
    ("wrinkling", "ratio"): 0.3,
    ("wrinkling", "mw_scale"): 0.3,
    ("payload_mass", "delta_kg"): 0.3,
    ("payload_mass", "com_offset_m"): 0.02,
    ("sensor_delay", "imu"): 0.005,
    ("sensor_delay", "encoder"): 0.005,
    ("sensor_delay", "torque"): 0.005,
    ("sensor_delay", "mocap"): 0.005,
    ("actuator_saturation", "tau_max"): 2.0,
    ("air_drag", "cd"): 1.0,
    ("torsion", "k_t"): 100.0,
    ("torsion", "c_t"): 0.5,
}

#: Candidate starting points tried in one batched rollout before the least-squares fit
#: (the effects are non-convex in their parameters: thresholds, dead zones, delays); a
#: value applies to every joint/link entry of the parameter.
_SEEDS: Dict[str, List[Dict[str, float]]] = {
    "joint_friction": [{"tau_c": 0.5, "b": 0.1}, {"tau_c": 2.0, "b": 0.5}],
    "backlash": [{"gap": 0.005}, {"gap": 0.02}, {"gap": 0.05}],
    "pressure_leak": [{"rate": 0.005}, {"rate": 0.05}],
    "wrinkling": [{"ratio": r, "mw_scale": m} for r in (0.3, 0.6) for m in (0.4, 0.7, 1.0)],
    "payload_mass": [{"delta_kg": -0.5}, {"delta_kg": 0.5}],
    "sensor_delay": [{"imu": d, "torque": d, "mocap": d} for d in (0.005, 0.02, 0.05)],
    "air_drag": [{"cd": 1.0}, {"cd": 5.0}, {"cd": 20.0}],
    "higher_bending_modes": [{"k_scale": 0.5}, {"k_scale": 2.0}],
    "torsion": [{"k_t": 30.0, "c_t": 0.1}, {"k_t": 300.0, "c_t": 0.5}],
}

#: Effects whose fit needs more iterations than ``max_iter`` (coupled, lightly damped modes).
_MIN_ITER: Dict[str, int] = {"torsion": 40, "higher_bending_modes": 25, "wrinkling": 20}

#: Structural settings used when an effect is tried (its discrete parameters).
_STRUCTURE: Dict[str, Dict[str, Any]] = {
    "higher_bending_modes": {"segments": [2.0, 2.0]},
    "torsion": {"k_t": [200.0, 200.0]},
}


def _pd() -> Any:
    import pandas as pd

    return pd


# ---------------------------------------------------------------------------- problem


class _Problem:
    """One measured run replayed in one compiled model: the normalised residual vector of
    any batch of effect vectors."""

    def __init__(self, model: "Model", run: MeasuredRun, channels: Sequence[str], sample_rate: float, threads: int) -> None:
        self.model = model
        self.run = run
        self.channels = list(channels)
        self.sample_rate = float(sample_rate)
        self.threads = int(threads)
        self.t_meas = run.time
        notes: List[str] = []
        from .compare import _initial_state, reference_setup

        self.closed = run.replay == "reference"
        if self.closed:
            # the references stand in for the encoder angles in the evidence statistics
            self.t_enc, self.q_enc = run.reference()
            self.task, self.q0, self.t0, self.duration = reference_setup(run)
        else:
            self.t_enc, self.q_enc = run.encoder()
            self.iq, self.iv = _initial_state(model, run, self.q_enc[0], notes)
        Y = np.column_stack([run.channel(c) for c in self.channels])
        self.std = np.array([float(np.nanstd(Y[:, j])) or 1.0 for j in range(Y.shape[1])])
        self.Y = Y
        self.nfev = 0

    def simulate(self, flats: np.ndarray, model: Optional["Model"] = None) -> np.ndarray:
        """Simulated channels on the measured stamps, (B, n, C)."""
        m = self.model if model is None else model
        flats = np.atleast_2d(flats)
        res: Any
        if self.closed:
            res = m.rollout_task(
                self.task,
                duration=self.duration,
                q0=self.q0,
                sample_rate=self.sample_rate,
                threads=self.threads,
                effects=flats,
                raise_on_error=False,
            )
            ok = np.array([e is None and st == "completed" for e, st in zip(res.errors, res.status)])
            t0 = self.t0
        else:
            res = m.rollout(
                encoder_t=self.t_enc,
                encoder_q=self.q_enc,
                initial_q=self.iq,
                initial_v=self.iv,
                sample_rate=self.sample_rate,
                threads=self.threads,
                effects=flats,
                raise_on_error=False,
            )
            ok = np.asarray(res.ok)
            t0 = 0.0
        self.nfev += flats.shape[0]
        if not ok.any():
            return np.full((flats.shape[0], len(self.t_meas), len(self.channels)), np.nan)
        t_sim = res.time[int(np.argmax(ok))] + t0
        out = np.full((flats.shape[0], len(self.t_meas), len(self.channels)), np.nan)
        same = len(t_sim) == len(self.t_meas) and np.array_equal(t_sim, self.t_meas)
        inside = (self.t_meas >= t_sim[0] - 1e-12) & (self.t_meas <= t_sim[-1] + 1e-12)
        for j, c in enumerate(self.channels):
            y = res.channel(c)
            for b in range(flats.shape[0]):
                if same:
                    out[b, :, j] = y[b]
                else:
                    out[b, inside, j] = np.interp(self.t_meas[inside], t_sim, y[b])
        return out

    def residuals(self, sims: np.ndarray) -> np.ndarray:
        """Normalised residuals (ŷ − y)/std, (B, n, C); missing cells 0; failed runs inf."""
        r = (sims - self.Y[None]) / self.std[None, None, :]
        bad_run = ~np.isfinite(sims).any(axis=(1, 2))
        r = np.where(np.isfinite(r), r, 0.0)
        r[bad_run] = np.inf
        return r

    def error(self, r: np.ndarray) -> Tuple[float, Dict[str, float]]:
        """Overall error (RMS over channels of NRMSE) and per channel, from one residual array (n, C)."""
        ok = np.isfinite(self.Y)
        per = {}
        for j, c in enumerate(self.channels):
            n = max(int(ok[:, j].sum()), 1)
            per[c] = float(np.sqrt(np.sum(r[:, j] ** 2) / n))
        return float(np.sqrt(np.mean(np.square(list(per.values()))))), per

    def n_eff(self, r: np.ndarray) -> float:
        ok = np.isfinite(self.Y)
        total = 0.0
        for j in range(r.shape[1]):
            x = r[ok[:, j], j]
            n = len(x)
            if n < 3:
                continue
            x = x - x.mean()
            d = float(np.dot(x, x))
            rho = float(np.dot(x[1:], x[:-1]) / d) if d > 0 else 0.0
            rho = min(max(rho, 0.0), 0.999)
            total += n * (1.0 - rho) / (1.0 + rho)
        return max(total, 1.0)


# ---------------------------------------------------------------------------- results


@dataclass
class Suspect:
    """One effect of the library tried on the run.

    Attributes
    ----------
    effect : str
        Effect name (``effects.md``).
    significant : bool
        Passes the significance test (module docs).
    score : float
        BIC improvement with the effective sample count (higher = more error explained
        beyond the complexity penalty; negative = not worth its parameters).
    params : dict
        Fitted parameters ``{name: [values]}`` (structural ones included), units in
        ``popup.effects.EFFECTS[effect].params``.
    ci95 : dict
        95 % confidence half-widths, same keys as the fitted parameters.
    error_before, error_after : float
        Overall error (``ERROR_DEFINITION``) without and with the fitted effect: the
        predicted error after adding it.
    channel_error_after : dict
        Per-channel NRMSE with the effect.
    evidence : dict
        The residual signature: ``signature`` (what to look for), ``statistic``,
        ``value`` and ``text``.
    n_eff : float
        Effective number of independent residual samples used in the score.
    n_rollouts : int
        Simulations this effect's seeds and fit used.
    message : str
        Why the effect could not be tried, if it could not ("" otherwise).
    """

    effect: str
    significant: bool
    score: float
    params: Dict[str, List[float]]
    ci95: Dict[str, List[float]]
    error_before: float
    error_after: float
    channel_error_after: Dict[str, float]
    evidence: Dict[str, Any]
    n_eff: float = 0.0
    n_rollouts: int = 0
    message: str = ""

    @property
    def relative_drop(self) -> float:
        """1 − error_after/error_before."""
        return 1.0 - self.error_after / self.error_before if self.error_before > 0 else 0.0

    def params_text(self) -> str:
        """The fitted parameters with their 95 % half-widths, e.g. ``delta_kg=0.3006±0.00039``."""
        return _fmt_params({k: v for k, v in self.params.items() if k in self.ci95}, self.ci95)

    def apply(self, model: "Model") -> "Model":
        """``model`` with this effect switched on at its fitted values."""
        return model.with_effect(self.effect, **self.params)

    def to_dict(self) -> Dict[str, Any]:
        """JSON-ready numbers (the ``suspects`` entries of the CLI's ``--json``)."""
        return {
            "effect": self.effect,
            "significant": bool(self.significant),
            "score": _num(self.score),
            "params": {k: [_num(x) for x in v] for k, v in self.params.items()},
            "ci95": {k: [_num(x) for x in v] for k, v in self.ci95.items()},
            "error_after": _num(self.error_after),
            "relative_drop": _num(self.relative_drop),
            "evidence": {k: (_num(v) if isinstance(v, float) else v) for k, v in self.evidence.items()},
            "n_eff": _num(self.n_eff),
            "message": self.message,
        }


def _num(x: Any) -> Optional[float]:
    x = float(x)
    return x if math.isfinite(x) else None


@dataclass
class Diagnosis:
    """Every effect of the library ranked by how much error it explains on one run.

    Attributes
    ----------
    suspects : list of Suspect
        Ranked: significant ones first, then by score.
    nominal_error : float
        Overall error of the model as given (``ERROR_DEFINITION``).
    channel_error : dict
        Per-channel NRMSE of the model as given.
    comparison : Comparison
        The comparison of the model as given with the run (residual views).
    residual_white : bool
        Whether the model's residual is white on every channel (Comparison.whiteness).
    conclusion : str
        One sentence: the top suspect, or that nothing significant is missing, or that
        the residual is not white and no library effect explains it.
    seconds : float
        Wall time of the diagnosis [s].
    """

    suspects: List[Suspect]
    nominal_error: float
    channel_error: Dict[str, float]
    comparison: Comparison
    residual_white: bool
    conclusion: str
    run: str = ""
    seconds: float = 0.0
    n_rollouts: int = 0

    @property
    def significant(self) -> List[Suspect]:
        """The significant suspects, best first."""
        return [s for s in self.suspects if s.significant]

    @property
    def best(self) -> Optional[Suspect]:
        """The top significant suspect, or None."""
        sig = self.significant
        return sig[0] if sig else None

    def __getitem__(self, effect: str) -> Suspect:
        for s in self.suspects:
            if s.effect == effect:
                return s
        raise KeyError(effect)

    def __repr__(self) -> str:
        top = ", ".join(f"{s.effect}{'*' if s.significant else ''} ({s.error_after:.3g})" for s in self.suspects[:3])
        return f"Diagnosis(nominal_error={self.nominal_error:.4g}, top=[{top}], conclusion={self.conclusion!r})"

    def to_pandas(self) -> "pd.DataFrame":
        """One row per effect (ranked): significant, score, error after, relative drop,
        fitted parameters, evidence."""
        pd = _pd()
        rows = []
        for rank, s in enumerate(self.suspects, 1):
            rows.append(
                {
                    "rank": rank,
                    "effect": s.effect,
                    "significant": s.significant,
                    "score": s.score,
                    "error_after": s.error_after,
                    "relative_drop": s.relative_drop,
                    "params": _fmt_params(s.params, s.ci95),
                    "evidence": s.evidence.get("text", ""),
                }
            )
        return pd.DataFrame(rows).set_index("rank")

    def to_dict(self) -> Dict[str, Any]:
        """JSON-ready: ``nominal_error``, ``error_definition``, ``suspects``, ``conclusion``."""
        return {
            "run": self.run,
            "nominal_error": _num(self.nominal_error),
            "error_definition": ERROR_DEFINITION,
            "channel_error": {k: _num(v) for k, v in self.channel_error.items()},
            "residual_white": bool(self.residual_white),
            "suspects": [s.to_dict() for s in self.suspects],
            "conclusion": self.conclusion,
            "seconds": self.seconds,
            "n_rollouts": self.n_rollouts,
        }

    def plot(self, ax: Any = None) -> Any:
        """Bar chart: overall error with each effect fitted (significant ones coloured)."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(7, 3.5))
        names = [s.effect for s in self.suspects]
        vals = [s.error_after for s in self.suspects]
        colors = ["tab:red" if s.significant else "tab:gray" for s in self.suspects]
        ax.barh(names[::-1], vals[::-1], color=colors[::-1])
        ax.axvline(self.nominal_error, color="k", ls="--", label=f"nominal {self.nominal_error:.3g}")
        ax.set_xlabel("overall error with the effect fitted (RMS of channel NRMSE)")
        ax.set_title("suspects (red: significant)")
        ax.legend(loc="lower right")
        return ax


def _fmt_params(p: Mapping[str, Sequence[float]], ci: Mapping[str, Sequence[float]]) -> str:
    out = []
    for k, v in p.items():
        c = ci.get(k)
        if c is None:
            out.append(f"{k}={_fmt_list(v)}")
        else:
            out.append(f"{k}={'/'.join(f'{x:.4g}±{e:.2g}' for x, e in zip(v, c))}")
    return ", ".join(out)


def _fmt_list(v: Sequence[float]) -> str:
    return "/".join(f"{x:.4g}" for x in v)


@dataclass
class HistoryStep:
    """One model of the loop: the effects it has, its fitted parameters and its error."""

    effects: List[str]
    params: Dict[str, Dict[str, List[float]]]
    error: float
    channel_error: Dict[str, float]
    model: Any = field(repr=False, default=None)

    def to_dict(self) -> Dict[str, Any]:
        return {
            "effects": list(self.effects),
            "error": _num(self.error),
            "params": {e: {k: [_num(x) for x in v] for k, v in p.items()} for e, p in self.params.items()},
            "channel_error": {k: _num(v) for k, v in self.channel_error.items()},
        }


@dataclass
class History:
    """The loop nominal → +effect → +effect …: each step's error per channel and overall,
    and the diagnosis of every round.

    Attributes
    ----------
    steps : list of HistoryStep
        ``steps[0]`` is the model as given; each later step adds one effect (all added
        effects refitted jointly).
    diagnoses : list of Diagnosis
        The diagnosis of each round (round i diagnoses ``steps[i]``).
    conclusion : str
        Why the loop stopped.
    """

    steps: List[HistoryStep]
    diagnoses: List[Diagnosis]
    conclusion: str
    run: str = ""
    seconds: float = 0.0

    @property
    def model(self) -> Any:
        """The final model (every significant effect added and fitted)."""
        return self.steps[-1].model

    @property
    def effects(self) -> List[str]:
        """Effects added, in order."""
        return list(self.steps[-1].effects)

    def __repr__(self) -> str:
        fall = " → ".join(f"{s.error:.3g}" for s in self.steps)
        return f"History(effects={self.effects}, error {fall})"

    def to_pandas(self) -> "pd.DataFrame":
        """One row per step: effects, overall error and per-channel NRMSE."""
        pd = _pd()
        rows = []
        for i, s in enumerate(self.steps):
            row: Dict[str, Any] = {"step": i, "effects": " + ".join(s.effects) or "nominal", "error": s.error}
            row.update({f"nrmse {c}": v for c, v in s.channel_error.items()})
            rows.append(row)
        return pd.DataFrame(rows).set_index("step")

    def to_dict(self) -> Dict[str, Any]:
        """The CLI's ``--json`` contract: ``run``, ``nominal_error``, ``error_definition``,
        ``suspects`` (first round, every effect ranked), ``history`` (each step's effects
        and error), plus ``rounds`` and ``conclusion``."""
        first = self.diagnoses[0]
        return {
            "run": self.run,
            "nominal_error": _num(self.steps[0].error),
            "error_definition": ERROR_DEFINITION,
            "suspects": [s.to_dict() for s in first.suspects],
            "history": [s.to_dict() for s in self.steps],
            "rounds": [d.to_dict() for d in self.diagnoses],
            "residual_white": bool(self.diagnoses[-1].residual_white),
            "conclusion": self.conclusion,
            "seconds": self.seconds,
        }

    def to_json(self, **kw: Any) -> str:
        return json.dumps(self.to_dict(), **kw)

    def plot(self, ax: Any = None) -> Any:
        """The fall of the error: overall (bold) and per channel, step by step."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(7, 4))
        x = np.arange(len(self.steps))
        labels = ["nominal"] + [f"+{s.effects[-1]}" for s in self.steps[1:]]
        chans = list(self.steps[0].channel_error)
        for c in chans:
            ax.plot(x, [s.channel_error.get(c, np.nan) for s in self.steps], color="0.7", lw=1)
        ax.plot(x, [s.error for s in self.steps], "o-", color="tab:red", lw=2.5, label="overall (RMS of channel NRMSE)")
        ax.set_xticks(x)
        ax.set_xticklabels(labels, rotation=15)
        ax.set_yscale("log")
        ax.set_ylabel("NRMSE (free-run replay)")
        ax.set_title("error history (grey: channels)")
        ax.legend()
        return ax


# ---------------------------------------------------------------------------- fitting


def _fit(
    prob: _Problem,
    base_flat: np.ndarray,
    free: List[Tuple[fx.EffectParam, int]],
    x0: np.ndarray,
    max_iter: int,
    scale: Optional[np.ndarray] = None,
) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Bounded least squares over the `free` (parameter, index) entries of the flat vector
    (bounds: the parameters' ``lower``/``upper``; typical magnitudes ``scale``, default
    :data:`_SCALE`). Returns (x, flat, residual (n, C), J at x (m, k))."""
    from scipy.optimize import least_squares

    lo = np.array([p.lower for p, _ in free])
    hi = np.array([p.upper for p, _ in free])
    sc = np.array([_SCALE.get((p.effect, p.name), 1.0) for p, _ in free]) if scale is None else np.asarray(scale, dtype=float)
    idx = np.array([p.offset + i for p, i in free])
    # a start on a bound stalls the trust-region-reflective steps (their scaling is the
    # distance to the bound): start a fraction of the typical scale inside
    nudge = np.minimum(_NUDGE * sc, 0.5 * (hi - lo))
    x0 = np.clip(x0, lo + nudge, hi - nudge)
    cache: Dict[bytes, np.ndarray] = {}

    def flat_of(x: np.ndarray) -> np.ndarray:
        f = base_flat.copy()
        f[idx] = x
        return f

    def eval_batch(xs: List[np.ndarray]) -> List[np.ndarray]:
        todo = [x for x in xs if x.tobytes() not in cache]
        if todo:
            r = prob.residuals(prob.simulate(np.array([flat_of(x) for x in todo])))
            for x, rr in zip(todo, r):
                cache[x.tobytes()] = rr.reshape(-1)
        return [cache[x.tobytes()] for x in xs]

    def fun(x: np.ndarray) -> np.ndarray:
        r = eval_batch([np.asarray(x, dtype=float)])[0]
        return r if np.all(np.isfinite(r)) else np.full_like(r, 1e6)

    def jac(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        pts = []
        hs = []
        for j in range(len(x)):
            h = 1e-4 * max(sc[j], abs(x[j]) * 0.1)
            if x[j] + h > hi[j]:
                h = -h
            xp = x.copy()
            xp[j] += h
            pts.append(xp)
            hs.append(h)
        r0, *rs = eval_batch([x] + pts)
        J = np.empty((r0.size, len(x)))
        for j, (rj, h) in enumerate(zip(rs, hs)):
            J[:, j] = (np.where(np.isfinite(rj), rj, 0.0) - r0) / h
        return J

    sol = least_squares(fun, x0, jac=jac, bounds=(lo, hi), x_scale=sc, method=_METHOD, max_nfev=max_iter, xtol=1e-6, ftol=1e-6, gtol=1e-8)
    x = sol.x
    r = eval_batch([x])[0].reshape(len(prob.t_meas), len(prob.channels))
    return x, flat_of(x), r, jac(x)


def _x0(prob: _Problem, free: List[Tuple[fx.EffectParam, int]], base_flat: np.ndarray) -> np.ndarray:
    x0 = []
    for p, i in free:
        v = base_flat[p.offset + i]
        if p.effect == "actuator_saturation":
            c = f"tau{i + 1}"
            if c in prob.channels:
                # the plateau of the measured |torque|: the median of the samples within
                # 4 noise deviations of the peak (the peak itself is biased up by the noise;
                # in closed loop a limit 1 % high already changes the whole trajectory)
                y = np.abs(prob.Y[:, prob.channels.index(c)])
                y = y[np.isfinite(y)]
                sd = float(np.std(np.diff(y))) / math.sqrt(2.0) if y.size > 2 else 0.0
                top = y[y >= float(np.max(y)) - 4.0 * sd]
                v = float(np.median(top))
            else:
                v = 1e3
        elif p.effect == "torsion" and p.name == "k_t" and not math.isfinite(v):
            v = 200.0
        x0.append(v)
    return np.array(x0, dtype=float)


def _best_seed(prob: _Problem, effect: str, free: List[Tuple[fx.EffectParam, int]], flat: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """The best of ``x0`` and the effect's seed points, all simulated in one batch."""
    cands = [x0]
    for seed in _SEEDS.get(effect, []):
        x = x0.copy()
        for j, (p, _) in enumerate(free):
            if p.name in seed:
                x[j] = min(max(seed[p.name], p.lower), p.upper)
        cands.append(x)
    if effect == "actuator_saturation":
        # x0 puts every limit at its joint's measured peak; a joint that never saturated is
        # better left unlimited (its peak is only clipped by noise), so also try each joint
        # limited alone (the objective is flat above a peak: the fit cannot find this itself)
        for k in range(len(free)):
            x = np.full_like(x0, 1e3)
            x[k] = x0[k]
            cands.append(x)
    if len(cands) == 1:
        return x0
    idx = np.array([p.offset + i for p, i in free])
    flats = np.repeat(flat[None], len(cands), axis=0)
    flats[:, idx] = np.array(cands)
    r = prob.residuals(prob.simulate(flats))
    rss = [float(np.sum(rr * rr)) for rr in r]
    return cands[int(np.argmin(rss))]


def _free_params(effect: str, only: Optional[Sequence[str]] = None) -> List[Tuple[fx.EffectParam, int]]:
    out: List[Tuple[fx.EffectParam, int]] = []
    for p in fx.EFFECTS[effect].params.values():
        if (only is None and p.fit) or (only is not None and p.name in only):
            out.extend((p, i) for i in range(p.length))
    return out


def _params_dict(effect: str, flat: np.ndarray) -> Dict[str, List[float]]:
    return {k: [float(x) for x in flat[p.slice]] for k, p in fx.EFFECTS[effect].params.items()}


def _ci(prob: _Problem, r: np.ndarray, J: np.ndarray, free: List[Tuple[fx.EffectParam, int]], n_eff: float) -> Dict[str, List[float]]:
    n = r.size
    k = len(free)
    rss = float(np.sum(r * r))
    s2 = rss / max(n - k, 1) * max(n / n_eff, 1.0)
    try:
        cov = s2 * np.linalg.pinv(J.T @ J)
        half = 1.96 * np.sqrt(np.clip(np.diag(cov), 0.0, None))
    except np.linalg.LinAlgError:
        half = np.full(k, np.inf)
    out: Dict[str, List[float]] = {}
    for (p, i), h in zip(free, half):
        out.setdefault(p.name, [math.nan] * p.length)[i] = float(h)
    return out


# ---------------------------------------------------------------------------- evidence


def _evidence(effect: str, cmp: Comparison, prob: _Problem) -> Dict[str, Any]:
    sig = fx.SIGNATURES.get(effect, "")
    res = cmp.residuals
    t = res.index.to_numpy()
    ev: Dict[str, Any] = {"signature": sig, "statistic": "", "value": math.nan, "text": ""}
    try:
        dq = {j: _rate(prob, j, t) for j in range(3)}
        if effect == "joint_friction":
            best = (0.0, "", 0.0, 0.0)
            for j in range(3):
                c = f"tau{j + 1}"
                if c not in res:
                    continue
                e = res[c].to_numpy()
                ok = np.isfinite(e)
                X = np.column_stack([np.tanh(dq[j] / 1e-2), dq[j], np.ones_like(e)])[ok]
                coef, *_ = np.linalg.lstsq(X, e[ok], rcond=None)
                r2 = 1.0 - float(np.var(e[ok] - X @ coef)) / max(float(np.var(e[ok])), 1e-300)
                if r2 > best[0]:
                    best = (r2, c, float(coef[0]), float(coef[1]))
            ev.update(statistic="R² of torque residual on sign(q̇), q̇", value=best[0],
                      text=f"{best[1]} residual ≈ {best[2]:.3g}·sign(q̇) + {best[3]:.3g}·q̇ explains {100 * best[0]:.0f} % of its variance" if best[1] else "no torque channel")
        elif effect == "backlash":
            e2 = _e2(cmp, ["ee_x", "ee_y", "ee_z", "imu2_ax", "imu2_ay", "imu2_az"])
            near = np.zeros(len(t), bool)
            for j in range(3):
                s = np.sign(dq[j])
                flips = np.nonzero((s[1:] * s[:-1]) < 0)[0]
                for f in flips:
                    near |= (t >= t[f]) & (t <= t[f] + 0.3)
            ratio = _share_ratio(e2, near)
            ev.update(statistic="error share / sample share within 0.3 s after velocity reversals", value=ratio,
                      text=f"the 0.3 s after velocity reversals carry {ratio:.2f}× their share of the tip error")
        elif effect == "higher_bending_modes":
            f1 = _first_mode_hz(prob)
            psd = cmp.psd
            f = psd.index.to_numpy()
            tot = psd.sum(axis=1).to_numpy() if psd is not None else np.zeros(1)
            above = float(tot[f > 1.5 * f1].sum() / max(tot.sum(), 1e-300)) if psd is not None else math.nan
            ev.update(statistic="share of residual power above 1.5× the first bending mode", value=above,
                      text=f"{100 * above:.0f} % of the residual power lies above 1.5 × {f1:.2f} Hz (first locked mode)")
        elif effect == "pressure_leak":
            e2 = _e2(cmp, list(res.columns))
            thirds = np.array_split(np.arange(len(t)), 3)
            m = [float(np.mean(e2[ix])) for ix in thirds]
            growth = m[2] / max(m[0], 1e-300)
            ev.update(statistic="mean squared error last third / first third", value=growth,
                      text=f"the squared residual grows {growth:.2f}× from the first to the last third of the run")
        elif effect == "wrinkling":
            c = cmp.conditions
            rows = c[c["binning"] == "|M|/M_w"]
            hi = rows[rows["bin"].isin(["0.8-1", ">1"])]
            ratio = float(hi["error_share"].sum() / max(hi["sample_share"].sum(), 1e-300)) if len(hi) and hi["sample_share"].sum() > 0 else math.nan
            ev.update(statistic="error share / sample share where |M|/M_w > 0.8", value=ratio,
                      text=f"samples with |M| > 0.8·M_w carry {ratio:.2f}× their share of the error" if math.isfinite(ratio) else "no sample near M_w")
        elif effect == "payload_mass":
            chans = [c for c in ("tau2", "tau3", "ee_z") if c in res]
            means = {c: float(np.nanmean(res[c])) / max(float(np.nanstd(prob.Y[:, prob.channels.index(c)])), 1e-300) for c in chans}
            c = max(means, key=lambda k: abs(means[k])) if means else ""
            ev.update(statistic="mean residual / measured std of the gravity-loaded channels", value=abs(means.get(c, 0.0)),
                      text=f"{c} has a bias of {means.get(c, 0.0):+.2f} std (gravity load or sag)" if c else "no gravity-loaded channel")
        elif effect == "sensor_delay":
            d = cmp.delay
            if d is not None and len(d):
                d2 = d[~d["at_limit"]]
                if len(d2):
                    gain = (1 - d2["rmse_at_delay"] / d2["rmse_at_zero"]).astype(float)
                    c = str(gain.idxmax())
                    ev.update(statistic="best aligning shift [s] of the channel it helps most", value=float(d2.loc[c, "delay_s"]),
                              text=f"{c}: shifting the measurement by {1e3 * float(d2.loc[c, 'delay_s']):.1f} ms lowers its RMSE by {100 * float(gain[c]):.0f} %")
        elif effect == "actuator_saturation":
            sat: Tuple[float, str] = (0.0, "")
            for j in range(3):
                c = f"tau{j + 1}"
                if c not in res:
                    continue
                y = prob.Y[:, prob.channels.index(c)]
                at = np.abs(y) >= 0.98 * np.nanmax(np.abs(y))
                e2 = res[c].to_numpy() ** 2
                r = _share_ratio(np.where(np.isfinite(e2), e2, 0.0), at)
                if r > sat[0]:
                    sat = (r, c)
            ev.update(statistic="error share / sample share while |τ| is within 2 % of its maximum", value=sat[0],
                      text=f"{sat[1]}: samples at the torque maximum carry {sat[0]:.2f}× their share of its error" if sat[1] else "no torque channel")
        elif effect == "air_drag":
            c = cmp.conditions
            rows = c[(c["binning"] == "tip speed") & (c["bin"] == "high")]
            ratio = float(rows["ratio"].iloc[0]) if len(rows) else math.nan
            ev.update(statistic="error share / sample share in the fastest tip-speed tercile", value=ratio,
                      text=f"the fastest third of the tip speeds carries {ratio:.2f}× its share of the error")
        elif effect == "torsion":
            e2 = _e2(cmp, [c for c in ("ee_y", "imu1_ay", "imu2_ay") if c in res])
            moving = np.abs(dq[0]) > 0.05 * max(float(np.max(np.abs(dq[0]))), 1e-9)
            ratio = _share_ratio(e2, moving)
            ev.update(statistic="lateral error share / sample share while q1 moves", value=ratio,
                      text=f"lateral channels carry {ratio:.2f}× their share of the error while q1 turns")
    except Exception as e:  # noqa: BLE001 - evidence must never break a diagnosis
        ev["text"] = f"evidence not computed: {e}"
    return ev


def _rate(prob: _Problem, j: int, t: np.ndarray) -> np.ndarray:
    return np.interp(t, prob.t_enc, np.gradient(prob.q_enc[:, j], prob.t_enc))


def _e2(cmp: Comparison, chans: Sequence[str]) -> np.ndarray:
    res = cmp.residuals
    tot = np.zeros(len(res))
    for c in chans:
        if c in res:
            y = cmp.measured.channel(c)
            s = float(np.nanstd(y)) or 1.0
            e = res[c].to_numpy() / s
            tot += np.where(np.isfinite(e), e * e, 0.0)
    return tot


def _share_ratio(e2: np.ndarray, mask: np.ndarray) -> float:
    if not mask.any() or mask.all():
        return math.nan
    return float(e2[mask].sum() / max(e2.sum(), 1e-300)) / float(mask.mean())


def _first_mode_hz(prob: _Problem) -> float:
    try:
        modes = [float(x) for x in np.asarray(prob.model.locked_modes(list(prob.q_enc[0])), float) if x > 0]
        return min(modes) / (2 * math.pi) if modes else math.nan
    except Exception:  # noqa: BLE001
        return math.nan


# ---------------------------------------------------------------------------- API


def _prepare(model: "Model", run: MeasuredRun, channels: Optional[Sequence[str]], sample_rate: Optional[float]) -> Tuple[Comparison, List[str], float]:
    if not isinstance(run, MeasuredRun):
        raise InputError(f"diagnose: expected a popup.MeasuredRun (popup.read_run), got {type(run).__name__}")
    cmp = compare(model, run, channels=channels, sample_rate=sample_rate)
    sr = float(cmp.simulated.params.get("sample_rate_hz", 0.0)) or 1.0 / float(np.median(np.diff(cmp.simulated.time)))
    return cmp, cmp.channels, sr


def model_error(model: "Model", run: MeasuredRun, *, channels: Optional[Sequence[str]] = None, sample_rate: Optional[float] = None) -> Tuple[float, Dict[str, float]]:
    """Overall error (:data:`ERROR_DEFINITION`) and per-channel NRMSE of ``model`` on
    ``run``, computed exactly as the diagnosis predicts it."""
    cmp, chans, sr = _prepare(model, run, channels, sample_rate)
    prob = _Problem(model, run, chans, sr, 0)
    r = prob.residuals(prob.simulate(model.effects_flat[None]))[0]
    return prob.error(r)


def diagnose(
    model: "Model",
    run: MeasuredRun,
    *,
    effects: Optional[Sequence[str]] = None,
    channels: Optional[Sequence[str]] = None,
    sample_rate: Optional[float] = None,
    threads: int = 0,
    max_iter: int = 15,
) -> Diagnosis:
    """Rank every effect of the library (or ``effects``) by how much of the model's error
    on ``run`` it explains, each with fitted parameters, confidence intervals, the
    predicted error after adding it and its residual evidence (module docs).

    Effects that ``model`` already has are skipped. ``threads=0`` uses every core.
    """
    t_start = time.perf_counter()
    names = list(fx.EFFECT_NAMES if effects is None else effects)
    for n in names:
        fx.normalize(n, {})
    cmp, chans, sr = _prepare(model, run, channels, sample_rate)
    base_flat = model.effects_flat
    prob = _Problem(model, run, chans, sr, threads)
    r0 = prob.residuals(prob.simulate(base_flat[None]))[0]
    e0, per0 = prob.error(r0)
    rss0 = float(np.sum(r0 * r0))
    have = set(fx.active(base_flat))
    suspects: List[Suspect] = []
    for name in names:
        if name in have:
            continue
        ev = _evidence(name, cmp, prob)
        s = _try_effect(model, run, prob, name, base_flat, rss0, e0, ev, sr, threads, max_iter)
        suspects.append(s)
    suspects.sort(key=lambda s: (not s.significant, -s.score if math.isfinite(s.score) else math.inf))
    white = bool(cmp.whiteness["is_white"].all())
    conclusion = _conclude(suspects, white, e0)
    return Diagnosis(
        suspects=suspects,
        nominal_error=e0,
        channel_error=per0,
        comparison=cmp,
        residual_white=white,
        conclusion=conclusion,
        run=str(run.source),
        seconds=time.perf_counter() - t_start,
        n_rollouts=2 + sum(s.n_rollouts for s in suspects),  # the comparison, the nominal residual, the fits
    )


def _try_effect(
    model: "Model", run: MeasuredRun, prob: _Problem, name: str, base_flat: np.ndarray, rss0: float, e0: float, ev: Dict[str, Any], sr: float, threads: int, max_iter: int
) -> Suspect:
    struct = _STRUCTURE.get(name)
    m = model
    p = prob
    flat = base_flat.copy()
    start = prob.nfev
    try:
        if struct is not None:
            m = model.with_effect(name, **struct)
            p = _Problem(m, run, prob.channels, sr, threads)
            start = 0
            flat = m.effects_flat
        free = _free_params(name)
        x0 = _best_seed(p, name, free, flat, _x0(p, free, flat))
        x, flat_fit, r, J = _fit(p, flat, free, x0, max(max_iter, _MIN_ITER.get(name, 0)))
    except Exception as e:  # noqa: BLE001 - one effect failing must not stop the ranking
        return Suspect(name, False, -math.inf, {}, {}, e0, e0, {}, ev, n_rollouts=p.nfev - start, message=f"{type(e).__name__}: {e}")
    e1, per1 = p.error(r)
    rss1 = float(np.sum(r * r))
    neff = p.n_eff(r)
    k = len(free)
    score = neff * math.log(max(rss0, 1e-300) / max(rss1, 1e-300)) - k * math.log(neff)
    drop = 1.0 - e1 / e0 if e0 > 0 else 0.0
    sig = bool(score > SCORE_THRESHOLD and drop >= MIN_RELATIVE_DROP)
    params = _params_dict(name, flat_fit)
    ci = _ci(p, r, J, free, neff)
    return Suspect(name, sig, float(score), params, ci, e0, e1, per1, ev, n_eff=neff, n_rollouts=p.nfev - start)


def _conclude(suspects: List[Suspect], white: bool, e0: float) -> str:
    sig = [s for s in suspects if s.significant]
    if sig:
        b = sig[0]
        return f"{b.effect} explains the most error: adding it is predicted to take the error from {e0:.3g} to {b.error_after:.3g} ({100 * b.relative_drop:.0f} % less)"
    tried = [s for s in suspects if math.isfinite(s.score)]
    best = max(tried, key=lambda s: s.relative_drop) if tried else None
    if white:
        return "no significant effect: the residual is white and no library effect lowers the error beyond its complexity penalty"
    extra = f" (the best, {best.effect}, lowers the error by only {100 * best.relative_drop:.0f} %)" if best else ""
    return "the residual is not white and no library effect explains it" + extra + ": something outside the library is missing (look at the residual spectrum and windows)"


def improve(
    model: "Model",
    run: MeasuredRun,
    *,
    max_rounds: int = 4,
    effects: Optional[Sequence[str]] = None,
    channels: Optional[Sequence[str]] = None,
    sample_rate: Optional[float] = None,
    threads: int = 0,
    max_iter: int = 15,
) -> History:
    """The loop: diagnose, add the top significant effect, refit every added effect
    jointly, compare again; until no effect is significant or ``max_rounds``."""
    t_start = time.perf_counter()
    d = diagnose(model, run, effects=effects, channels=channels, sample_rate=sample_rate, threads=threads, max_iter=max_iter)
    steps = [HistoryStep([], {}, d.nominal_error, d.channel_error, model)]
    diags = [d]
    added: List[str] = []
    current = model
    conclusion = d.conclusion
    while d.best is not None and len(added) < max_rounds:
        s = d.best
        added.append(s.effect)
        current = s.apply(current)
        current, err, per = _refit(current, run, added, d.comparison.channels, sample_rate, threads, max_iter)
        steps.append(HistoryStep(list(added), {e: current.effects.get(e, {}) for e in added}, err, per, current))
        remaining = [e for e in (effects or fx.EFFECT_NAMES) if e not in added]
        if not remaining:
            conclusion = "every library effect has been added"
            break
        d = diagnose(current, run, effects=remaining, channels=channels, sample_rate=sample_rate, threads=threads, max_iter=max_iter)
        diags.append(d)
        conclusion = d.conclusion
    if d.best is not None and len(added) >= max_rounds:
        conclusion = f"stopped after max_rounds = {max_rounds}; {d.best.effect} is still significant"
    return History(steps, diags, conclusion, run=str(run.source), seconds=time.perf_counter() - t_start)


def _refit(model: "Model", run: MeasuredRun, added: List[str], channels: Sequence[str], sample_rate: Optional[float], threads: int, max_iter: int) -> Tuple["Model", float, Dict[str, float]]:
    """Refit every parameter of the added effects jointly, from their current values."""
    cmp, chans, sr = _prepare(model, run, channels, sample_rate)
    prob = _Problem(model, run, chans, sr, threads)
    flat = model.effects_flat
    free = [pi for e in added for pi in _free_params(e)]
    x0 = np.array([flat[p.offset + i] for p, i in free])
    x, flat_fit, r, _ = _fit(prob, flat, free, x0, max([max_iter] + [_MIN_ITER.get(e, 0) for e in added]))
    new = model.with_effects({e: _params_dict(e, flat_fit) for e in added})
    err, per = prob.error(r)
    return new, err, per


# ---------------------------------------------------------------------------- CLI


def cli_main(argv: Sequence[str]) -> int:
    """``popup diagnose RUN [--json] [--report out.html] ...``: load the run, compare,
    rank every effect, add the significant ones in turn (refitting), print the suspects
    and the error fall (or one JSON object with ``--json``). Exit 0 on success, 2 on bad
    input (the message names what was wrong)."""
    import argparse
    import sys

    from .exceptions import PopupError
    from .io import read_run

    ap = argparse.ArgumentParser(prog="popup diagnose", description="Rank the library's effects by how much of the model-vs-measurement error each explains, then add them in turn.")
    ap.add_argument("run", help="measured-run folder (experiment.toml + measurements.csv/parquet)")
    ap.add_argument("--json", action="store_true", help="print one JSON object (run, nominal_error, error_definition, suspects, history, ...)")
    ap.add_argument("--report", metavar="HTML", help="write the self-contained HTML report here")
    ap.add_argument("--max-rounds", type=int, default=4, help="most effects to add (default 4)")
    ap.add_argument("--effects", help="comma-separated effects to try (default: the whole library)")
    ap.add_argument("--channels", help="comma-separated channels to compare (default: every comparable one)")
    ap.add_argument("--threads", type=int, default=0, help="rollout threads (0 = all cores)")
    a = ap.parse_args(list(argv))
    try:
        run = read_run(a.run)
        model = run.model()
        effects = [e.strip() for e in a.effects.split(",")] if a.effects else None
        channels = [c.strip() for c in a.channels.split(",")] if a.channels else None
        h = improve(model, run, max_rounds=a.max_rounds, effects=effects, channels=channels, threads=a.threads)
    except (PopupError, FileNotFoundError, NotADirectoryError) as e:
        print(f"popup diagnose: error: {e}", file=sys.stderr)
        return 2
    h.run = a.run
    for d in h.diagnoses:
        d.run = a.run
    if a.report:
        from .report import write_html

        write_html(h, a.report, title=f"popup diagnose {a.run}")
    if a.json:
        print(json.dumps(h.to_dict(), allow_nan=False))
        return 0
    d0 = h.diagnoses[0]
    print(f"run: {a.run}")
    print(f"nominal error: {d0.nominal_error:.4g}  ({ERROR_DEFINITION})")
    print()
    print(f"{'rank':>4}  {'effect':<22}{'sig':<5}{'score':>10}{'error after':>13}{'drop':>7}  parameters")
    for i, s in enumerate(d0.suspects, 1):
        score = f"{s.score:.1f}" if math.isfinite(s.score) else "n/a"
        params = s.params_text() or s.message
        print(f"{i:>4}  {s.effect:<22}{'yes' if s.significant else 'no':<5}{score:>10}{s.error_after:>13.4g}{100 * s.relative_drop:>6.0f}%  {params}")
    print()
    print("error history:")
    for st in h.steps:
        print(f"  {' + '.join(st.effects) or 'nominal':<40} {st.error:.4g}")
    print()
    print(h.conclusion)
    if a.report:
        print(f"report: {a.report}")
    return 0
