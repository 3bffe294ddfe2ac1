"""Diagnose a model against a measured run: which effect of the library is missing?

::

    run = popup.read_run("examples/data/lab_run")
    model = run.model()
    d = popup.diagnose(model, run)          # every effect fitted, validated, ranked
    d.to_pandas()                           # score, significant, error after, parameters
    better = d.best.apply(model)            # model.with_effect(...) with the fitted values
    h = popup.improve(model, run)           # the loop: add, refit, until nothing is left
    h.plot(); h.to_dict(); h.conclusion

One problem, one objective
--------------------------
The run is set up once as a :class:`popup.ReplayProblem` (channels, output rate, the
smoothed encoder, the nominal replay, each channel's noise floor σ_c, training and
held-out samples) and shared by :func:`popup.compare.compare`, :func:`diagnose`,
:func:`improve` and :func:`popup.fit_params`.

**Error** (:data:`ERROR_DEFINITION`): the systematic part of the free-run replay error in
units of the noise, ``S = sqrt(max(mean_c r_c² − 1, 0))`` with ``r_c = RMSE_c/σ_c`` each
channel's *noise multiple* (1 = at its noise floor). A channel that carries only noise
(a pressure held constant) sits at ``r_c ≈ 1`` whatever the model does and adds nothing.

**Fit.** Each effect's parameters (registry ``fit`` flags, :mod:`popup.effects`) are
fitted by Gaussian maximum likelihood with an unknown variance per channel on the
training samples, from the best of the effect's seed points (:mod:`popup.estimate`).

**Every effect is tried.** An effect that changes the chain (``higher_bending_modes``,
``torsion``) may need a smaller step than the model's: the step is chosen per candidate
from the linearised stability limit of that candidate's structure
(:meth:`Model.stable_dt`) with the margin :data:`STABILITY_MARGIN`, as a divisor of the
output period, and the nominal model is re-run at the same step so that both are compared
at the same accuracy. An effect that still cannot be tried is listed with
``tested = False`` and its reason, and the conclusion says the ranking is incomplete.

**Significance.** ``score = LR − k ln n_eff`` (BIC) with the likelihood ratio
``LR = Σ_c n_eff,c ln(mean z²_c,before / mean z²_c,after)`` on the training samples and
``n_eff,c = n_c (1 − ρ_c)/(1 + ρ_c)`` (ρ_c the lag-1 autocorrelation of the fitted
residual). An effect is *significant* when the score exceeds :data:`SCORE_THRESHOLD`, it
explains at least :data:`MIN_EXPLAINED` of the systematic error (``1 − S²_after/S²_before``)
and it is confirmed on the held-out samples (the likelihood ratio there is positive and the
held-out error falls), unless it does not act on them at all (a torque limit reached only in
training blocks: the held-out samples can neither confirm nor refute it; its message says so).

**Refinement.** A significant effect is also fitted in its richer variants
(:data:`VARIANTS`: friction with Stribeck terms, three segments for bending, a centre-of-mass
offset for the payload, compliant flanks for a gear with play, run at the step its
``stiffest`` values allow); a variant is kept when its score beats the base's by more than
:data:`SCORE_THRESHOLD` (its extra parameters must pay for themselves). The kept variant is
then fitted together with each other variant that beat the nominal model by the threshold
(significant or not: compliant flanks fitted at the default link-side inertia can lose to
the rigid flanks with a fitted inertia and still be what the run needs, with that inertia),
and the combination is kept when it passes the whole test and beats the kept variant by the
threshold. An *alternative*
law of an effect (backlash with the link side held in its gap, a play operator, beside the
gear with a free link side) is fitted whether or not the base is significant, and the one
that scores higher is kept.

**The floor.** Nothing is added to a model at its floor: a systematic error of at most
:data:`AT_FLOOR` and every channel within :data:`FLOOR_MULTIPLE` of its floor, the noise
and the replay error the encoder's own error causes
(:attr:`ReplayProblem.encoder_floor`, a parametric bootstrap). A quantised encoder limits
how well q̈, and so the replayed torques and accelerations, can be known: with a 12-bit
encoder and a quiet IMU the true model replays at up to 1.3 × the IMU's noise, and
an effect fitted there (a +0.8 g payload for 54 % of it, on a MuJoCo run) fits the
encoder, not the arm. The candidates are then not tried (each says why; the answer takes
seconds), or, with ``rank_at_floor=True`` (``--rank-at-floor``), fitted and ranked with
none significant.

**What the encoder cannot see.** A coarse encoder also hides motion: a held motor that
yields to the links' ringing by a fraction of a step (a servo's finite stiffness) never
changes its reading, and the replay holds it still. That motion is fitted into the replay
(:mod:`popup.unseen`). A backlash narrower than :data:`PLAY_READINGS` of a reading
(:attr:`ReplayProblem.encoder_width`) is below the quantisation of the replayed angle
itself, and is not significant.

**Identifiability.** Each fit's scaled Fisher matrix is checked (rank, condition,
correlations, bounds); parameters the run cannot pin down get an infinite interval and are
named (``Suspect.identifiability``).

**Evidence.** Each suspect carries the residual signature of ``effects.md`` measured on
the nominal residual (e.g. the regression of the torque residual on sign(q̇) and q̇ for
friction, the delay that best aligns the measurement for a sensor delay).

**The loop** (:func:`improve`) adds the best significant effect, refits every added
effect jointly and diagnoses again; from round 2 each candidate is screened with the added
effects held, the best :data:`JOINT_TOP` are refitted with them, and every fit also starts
from the same effect's fit of the round before. From round 3 on (two effects in the model)
the screen itself is cheap: each candidate is fitted from its fit of the round before
alone, and only the :data:`JOINT_TOP` best (and any significant) get the full multi-start
fit (``diagnose(screen=)``). A greedy first round can pick one effect for the error of two;
three steps undo it. *Backward*: an effect added earlier that the refitted model no longer
needs (by the rules that add one) is removed. *Swap*: an effect added earlier is replaced
by the best candidate for the model without it when that model beats the current one
(:func:`_beats`: BIC gain over the threshold, held-out error lower). *Base law*: when
nothing is significant but the model is not at its floor, an effect added with a variant's
extra parameters (a payload's centre-of-mass offset) is set back to its base law and the
best candidate then added, on the same test. The swap and the base law offer only
candidates some round found significant (an effect another stood in for explained much of
the same error when that one was chosen), each (effect, candidate) pair once; what they
tried and why it was or was not kept is in ``History.notes``. Each history step names its
``round``.

**Floors re-estimated.** The floors σ_c come from the nominal residual, whose misfit biases
the estimator (a rough misfit up; a coloured noise hidden, down). After each step (an effect
added, removed or swapped in) they are estimated again from the refitted model's residual; a
channel whose floor moves by more than :data:`NOISE_RECHECK` takes the new one, and the
history, the later rounds and the conclusion are in it (``History.noise``,
``History.noise_initial``).
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Callable, Dict, List, Mapping, Optional, Sequence, Set, Tuple

import numpy as np

from . import effects as fx
from . import estimate as est
from .compare import Comparison, compare
from .exceptions import InputError, StepTooLargeError
from .io import MeasuredRun
from .problem import ERROR_DEFINITION, SPIKE_SIGMA, ReplayProblem, systematic
from .unseen import fit_unseen_motion

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
    "MIN_EXPLAINED",
    "STABILITY_MARGIN",
    "AT_FLOOR",
    "VARIANTS",
    "JOINT_TOP",
    "FLOOR_MULTIPLE",
    "NOISE_RECHECK",
    "SPIKE_SHARE",
    "PLAY_READINGS",
]

SCORE_THRESHOLD = est.SCORE_THRESHOLD
"""BIC improvement (with the effective sample count) above which an effect is significant
(:data:`popup.estimate.SCORE_THRESHOLD`)."""
MIN_EXPLAINED = 0.4
"""Smallest share of the systematic error (``1 − S²_after/S²_before``) a significant effect
explains. On data no model reproduces exactly the likelihood ratio overstates significance
(the residual left is systematic, not noise), and an effect can take a small bite of a
misfit it does not explain: on a MuJoCo nominal run at 2 kHz with 3 × quieter sensors
(a fixed 0.45 σ₀ encoder/replay misfit left, benchmarks/README.md, session 13) backlash
with a 3 µrad gap scored 5353 for 24 % of a 0.71 systematic error, then a −0.2 g payload
for 20 %. Every hidden effect the families found explained at least 79 % (a near torsion
at the fit's cap, 1.90 → 0.868 noise units)."""
STABILITY_MARGIN = 0.5
"""A candidate runs with a step at most this fraction of its linearised stability limit."""
AT_FLOOR = 0.3
"""Systematic error [noise units] below which a model is said to be at the noise floor
(the total error within 5 % of the noise: sqrt(1 + 0.3²) = 1.044)."""

JOINT_TOP = 3
"""In a round with effects already added, the number of best-screened candidates refitted
jointly with them (the others keep their screened fit, earlier effects held)."""

SPIKE_SHARE = 0.5
"""Share of a channel's excess above which the unexplained error names its isolated spikes
(:meth:`ReplayProblem.spikes`), for a channel above :data:`FLOOR_MULTIPLE` × its noise (a
replay at the floor can have one: a friction reversal a sample early is a one-sample step)."""

FLOOR_MULTIPLE = 1.2
"""After an effect was added, :func:`improve` stops when the systematic error is at most
:data:`AT_FLOOR` and every channel is within this multiple of its noise (a systematic part of
at most 0.66 σ in any channel). The noise floors are themselves estimated from the run
(coloured noise, jittered stamps): a popup run refitted to its truth's own law (S = 0.065)
had channels from 0.955 to 1.118 × their floors, so effects that would take such a model
from, say, 0.15 to 0.08 noise units are fitting that uncertainty, not physics."""

#: Effects that move a lightly damped resonance (or a link side rattling in its gap): fitted on
#: a short horizon first, then on doubled horizons from that optimum (an extra start).
_SHORT_FIRST = {"higher_bending_modes", "torsion", "payload_mass", "wrinkling", "pressure_leak", "air_drag", "backlash"}
#: Effects whose per-joint seeded parameters are also swept joint by joint (on the short horizon).
_COORDINATE_SEEDS = {"backlash"}
COORDINATE_STEP = 1.03
"""Ratio between neighbouring values of the joint-by-joint seed sweep (``_COORDINATE_SEEDS``)."""
SHORT_HORIZON_S = 2.5
"""Length [s] of the short horizon (at least 20 % of the run) of the first fit of an effect
that moves a resonance; the continuation then doubles it until the run's length."""

#: Effects whose fit needs more iterations than ``max_iter`` (coupled, lightly damped modes).
_MIN_ITER: Dict[str, int] = {"torsion": 40, "higher_bending_modes": 25, "wrinkling": 20}

#: Structural settings used when an effect is tried (its discrete parameters), and the
#: parameter values at which its stability limit is taken (the stiffest seed).
_STRUCTURE: Dict[str, Dict[str, Any]] = {
    "higher_bending_modes": {"segments": [2.0, 2.0]},
    "torsion": {"k_t": [200.0, 200.0]},
}
_STIFFEST: Dict[str, Dict[str, Any]] = {
    "higher_bending_modes": {"k_scale": [5.0, 5.0]},
    "torsion": {"k_t": [est.BOUNDS[("torsion", "k_t")][1]] * 2, "c_t": [2.0, 2.0]},
}

VARIANTS: Dict[str, List[Dict[str, Any]]] = {
    "joint_friction": [{"name": "Stribeck", "extra": ["tau_s", "v_s"], "seeds": [{"tau_s": 0.5, "v_s": 0.05}, {"tau_s": 1.5, "v_s": 0.1}, {"tau_s": 1.0, "v_s": 0.02}]},
                       # how sharply the friction reverses (a gear's presliding width): a law with a
                       # sharper sign than the default is otherwise mimicked by a Stribeck bump at
                       # v_s ≈ v_eps (MuJoCo friction with a 3 mrad/s sign: τ_s 6.6 N·m for a true 1.07)
                       {"name": "sign width", "extra": ["v_eps"], "seeds": [{"v_eps": 0.003}, {"v_eps": 0.001}, {"v_eps": 0.03}]},
                       {"name": "Stribeck and sign width", "extra": ["tau_s", "v_s", "v_eps"],
                        "seeds": [{"tau_s": 0.3, "v_s": 0.05, "v_eps": 0.003}, {"tau_s": 0.3, "v_s": 0.05, "v_eps": 0.001},
                                  {"tau_s": 1.0, "v_s": 0.1, "v_eps": 0.003}, {"tau_s": 0.5, "v_s": 0.05, "v_eps": 0.03}]}],
    # the springs along a link: equal (the default split) or a stiffer root, as in a
    # continuous cantilever (4:1 for 2 segments gives its tip rotation as well as its deflection)
    "higher_bending_modes": [{"name": "3 segments", "structure": {"segments": [3.0, 3.0]}},
                             {"name": "stiffer root (cantilever split)", "extra": ["root_ratio"],
                              "seeds": [{"root_ratio": 4.0}, {"root_ratio": 2.0}, {"root_ratio": 0.6}]}],
    "payload_mass": [{"name": "centre-of-mass offset", "extra": ["com_offset_m"]}],
    # how fast a link side crosses its gap depends on the gear's link-side inertia
    "backlash": [{"name": "fitted link-side inertia", "extra": ["inertia"], "seeds": [{"inertia": 0.003}, {"inertia": 0.03}, {"inertia": 0.1}, {"inertia": 0.3}]},
                 # a link side held by its bearing's friction, moved only by the flanks: another
                 # law, not a refinement, so it is tried even when the free gear is not significant
                 {"name": "held link side (play operator)", "structure": {"held": [1.0, 1.0, 1.0]}, "alternative": True},
                 # a compliant gear: its flanks a unilateral spring-damper (the elasto-backlash
                 # law of Modelica and Simscape), which also carries the gear's own compliance
                 # while it pushes; run at the step of its stiffest plausible flank
                 {"name": "compliant flanks", "extra": ["contact_k", "contact_c"],
                  "structure": {"contact_k": [1e4, 1e4, 1e4], "contact_c": [5.0, 5.0, 5.0]},
                  "stiffest": {"contact_k": [est.BOUNDS[("backlash", "contact_k")][1]] * 3, "contact_c": [est.BOUNDS[("backlash", "contact_c")][1]] * 3},
                  "seeds": [{"contact_k": 3e3, "contact_c": 3.0}, {"contact_k": 3e4, "contact_c": 10.0}, {"contact_k": 1e5, "contact_c": 30.0}]}],
    "torsion": [{"name": "link 1 only", "structure": {"k_t": [200.0, math.inf], "c_t": [0.2, 0.0]}},
                {"name": "link 2 only", "structure": {"k_t": [math.inf, 200.0], "c_t": [0.0, 0.2]}}],
}
"""Richer variants tried when an effect is significant: ``extra`` parameters fitted with
the base ones (from the base fit), or another ``structure``; an ``alternative`` (another
law for the same effect) is tried whether the base is significant or not."""

Progress = Callable[[Dict[str, Any]], None]


def _pd() -> Any:
    import pandas as pd

    return pd


def _num(x: Any) -> Optional[float]:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


# ---------------------------------------------------------------------------- results


@dataclass
class Suspect:
    """One effect of the library tried on the run.

    Attributes
    ----------
    effect : str
        Effect name (``effects.md``).
    significant : bool
        Passes the significance test and the held-out confirmation (module docs).
    score : float
        BIC improvement with the effective sample count on the training samples (higher =
        more explained beyond the complexity penalty); ``-inf`` when not tested.
    params : dict
        Fitted parameters ``{name: [values]}`` (structural ones included), units in
        ``popup.effects.EFFECTS[effect].params``.
    ci95 : dict
        95 % half-widths of the fitted parameters (``inf``: not identifiable from this run).
    error_before, error_after : float
        Systematic error (``ERROR_DEFINITION``) without and with the fitted effect, on the
        whole run, at this candidate's step.
    channel_error_after : dict
        Noise multiple ``r_c`` of each channel with the effect.
    evidence : dict
        The residual signature: ``signature``, ``statistic``, ``value``, ``text``.
    tested : bool
        False when the effect could not be tried (``message`` says why).
    message : str
        Why it could not be tried, or notes (the step it ran at).
    explained : float
        Share of the systematic error it explains, ``1 − S²_after/S²_before``.
    validation_before, validation_after : float
        Systematic error on the held-out samples without and with the effect.
    validation_lr : float
        Likelihood ratio on the held-out samples (> 0: the effect helps there too).
    variant : str
        The richer variant kept ("" = the base effect).
    identifiability : dict
        ``rank``, ``condition``, ``correlated``, ``at_bound``, ``unidentifiable``, ``text``.
    dt : float
        The step [s] the candidate ran at.
    refitted : dict
        The effects already in the model that were refitted jointly with it (round 2 on):
        ``{effect: {name: [values]}}`` at this fit; :meth:`apply` sets them too, so the
        model it gives is the one ``error_after`` is of.
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
    tested: bool = True
    explained: float = 0.0
    validation_before: float = math.nan
    validation_after: float = math.nan
    validation_lr: float = math.nan
    variant: str = ""
    identifiability: Dict[str, Any] = field(default_factory=dict)
    dt: float = math.nan
    fitted: List[str] = field(default_factory=list)
    refitted: Dict[str, Dict[str, List[float]]] = field(default_factory=dict)

    @property
    def relative_drop(self) -> float:
        """1 − error_after/error_before."""
        if not (self.tested and self.error_before > 0 and math.isfinite(self.error_after)):
            return 0.0
        return 1.0 - self.error_after / self.error_before

    def params_text(self) -> str:
        """The fitted parameters with their 95 % half-widths, e.g. ``delta_kg=0.3006±0.00039``."""
        return _fmt_params({k: v for k, v in self.params.items() if k in self.ci95}, self.ci95)

    def apply(self, model: "Model") -> "Model":
        """``model`` with this effect switched on at its fitted values, the effects refitted
        jointly with it at theirs (:attr:`refitted`), and the smaller step the candidate
        needed, if it did."""
        m = model.with_effects({**self.refitted, self.effect: self.params}) if self.refitted else model.with_effect(self.effect, **self.params)
        if math.isfinite(self.dt) and self.dt < m.dt * (1 - 1e-12):
            m = m.with_dt(self.dt)
        return m

    def to_dict(self) -> Dict[str, Any]:
        """JSON-ready numbers (the ``suspects`` entries of the CLI's ``--json``)."""
        return {
            "effect": self.effect,
            "tested": bool(self.tested),
            "significant": bool(self.significant),
            "score": _num(self.score),
            "variant": self.variant,
            "params": {k: [_num(x) for x in v] for k, v in self.params.items()},
            "ci95": {k: [_num(x) for x in v] for k, v in self.ci95.items()},
            "error_before": _num(self.error_before),
            "error_after": _num(self.error_after),
            "relative_drop": _num(self.relative_drop),
            "explained_share": _num(self.explained),
            "channel_error_after": {k: _num(v) for k, v in self.channel_error_after.items()},
            "validation": {"error_before": _num(self.validation_before), "error_after": _num(self.validation_after), "lr": _num(self.validation_lr)},
            "identifiability": _jsonable(self.identifiability),
            "refitted": {e: {k: [_num(x) for x in v] for k, v in p.items()} for e, p in self.refitted.items()},
            "evidence": {k: (_num(v) if isinstance(v, float) else v) for k, v in self.evidence.items()},
            "n_eff": _num(self.n_eff),
            "dt": _num(self.dt),
            "message": self.message,
        }


def _jsonable(v: Any) -> Any:
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return _num(v)
    return v if v is None or isinstance(v, str) else str(v)


@dataclass
class Diagnosis:
    """Every effect of the library ranked by how much of the model's systematic error on
    one run it explains.

    Attributes
    ----------
    suspects : list of Suspect
        Ranked: significant ones first, then tested ones by score, untested last.
    nominal_error : float
        Systematic error of the model as given (``ERROR_DEFINITION``, noise units).
    channel_error : dict
        Noise multiple ``r_c`` of each channel for the model as given (1 = noise floor).
    comparison : Comparison
        The comparison of the model as given with the run (residual views).
    residual_white : bool
        Whether the model's residual is white on every channel (Comparison.whiteness).
    conclusion : str
        This round's finding (see :attr:`History.conclusion` for the whole loop's).
    noise : dict
        Each channel's white-noise floor σ (channel unit).
    at_floor : list of str
        Channels whose measured signal is at its noise floor (they carry no information).
    encoder_floor : dict
        Per channel, the replay error the encoder's own error causes, as a multiple of
        the noise (:attr:`ReplayProblem.encoder_floor`; 1 = nothing).
    floor_error : float
        The systematic error above the whole floor (noise and encoder).
    model_at_floor : bool
        Whether the model is at its floor (module docs): then nothing is significant.
    seconds : float
        Wall time [s].
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
    noise: Dict[str, float] = field(default_factory=dict)
    at_floor: List[str] = field(default_factory=list)
    problem: Any = field(default=None, repr=False)
    encoder_floor: Dict[str, float] = field(default_factory=dict)
    floor_error: float = math.nan
    model_at_floor: bool = False

    @property
    def significant(self) -> List[Suspect]:
        """The significant suspects, best first."""
        return [s for s in self.suspects if s.significant]

    @property
    def best(self) -> Optional[Suspect]:
        """The top significant suspect, or None."""
        sig = self.significant
        return sig[0] if sig else None

    @property
    def untested(self) -> List[Suspect]:
        """Effects that could not be tried (their ``message`` says why)."""
        return [s for s in self.suspects if not s.tested]

    def __getitem__(self, effect: str) -> Suspect:
        for s in self.suspects:
            if s.effect == effect:
                return s
        raise KeyError(effect)

    def __repr__(self) -> str:
        top = ", ".join(f"{s.effect}{'*' if s.significant else ''} ({s.error_after:.3g})" for s in self.suspects[:3])
        return f"Diagnosis(nominal_error={self.nominal_error:.4g}, top=[{top}], conclusion={self.conclusion!r})"

    def to_pandas(self) -> "pd.DataFrame":
        """One row per effect (ranked): tested, significant, score, error after, share of
        the systematic error explained, held-out error, parameters, identifiability, evidence."""
        pd = _pd()
        rows = []
        for rank, s in enumerate(self.suspects, 1):
            rows.append(
                {
                    "rank": rank,
                    "effect": s.effect + (f" ({s.variant})" if s.variant else ""),
                    "tested": s.tested,
                    "significant": s.significant,
                    "score": s.score,
                    "error_after": s.error_after,
                    "explained": s.explained,
                    "validation_after": s.validation_after,
                    "params": _fmt_params(s.params, s.ci95) if s.tested else s.message,
                    "identifiability": s.identifiability.get("text", ""),
                    "evidence": s.evidence.get("text", ""),
                }
            )
        return pd.DataFrame(rows).set_index("rank")

    def to_dict(self) -> Dict[str, Any]:
        """JSON-ready: ``nominal_error``, ``error_definition``, ``noise``, ``suspects``, ``conclusion``."""
        return {
            "run": self.run,
            "nominal_error": _num(self.nominal_error),
            "error_definition": ERROR_DEFINITION,
            "channel_error": {k: _num(v) for k, v in self.channel_error.items()},
            "noise": {k: _num(v) for k, v in self.noise.items()},
            "at_noise_floor": list(self.at_floor),
            "encoder_floor": {k: _num(v) for k, v in self.encoder_floor.items()},
            "floor_error": _num(self.floor_error),
            "model_at_floor": bool(self.model_at_floor),
            "unseen_compliance": [_num(x) for x in (self.problem.compliance if self.problem is not None else np.zeros(3))],
            "residual_white": bool(self.residual_white),
            "suspects": [s.to_dict() for s in self.suspects],
            "conclusion": self.conclusion,
            "seconds": self.seconds,
            "n_rollouts": self.n_rollouts,
        }

    def plot(self, ax: Any = None) -> Any:
        """Bar chart: systematic error with each effect fitted (significant ones coloured)."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(7, 3.5))
        tested = [s for s in self.suspects if s.tested]
        names = [s.effect for s in tested]
        vals = [s.error_after for s in tested]
        colors = ["tab:red" if s.significant else "tab:gray" for s in tested]
        ax.barh(names[::-1], vals[::-1], color=colors[::-1])
        ax.axvline(self.nominal_error, color="k", ls="--", label=f"nominal {self.nominal_error:.3g}")
        ax.set_xlabel("systematic error with the effect fitted [noise units]")
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
    validation_error: float = math.nan
    ci95: Dict[str, Dict[str, List[float]]] = field(default_factory=dict)
    removed: str = ""
    """The effect this step removed (backward or swap step), "" when it only added one."""
    swapped_in: str = ""
    """The effect a swap step put in place of ``removed`` ("" otherwise)."""
    law_reset: str = ""
    """The effect this step set back to its base law (a richer variant's extra parameters
    neutral again: they had stood in for the effect this step added), "" otherwise."""
    round: int = 0
    """The round of the loop this step belongs to (0: the model as given; round k's
    addition and its backward and swap steps all carry k)."""
    unseen_compliance: List[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    """Per motor joint, the compliance [rad/(N·m)] of the motion inside an encoder reading
    that its replay includes (:mod:`popup.unseen`; zeros: none)."""
    validation_channel_error: Dict[str, float] = field(default_factory=dict)
    """Each channel's noise multiple on the held-out samples alone."""

    def to_dict(self) -> Dict[str, Any]:
        return {
            "effects": list(self.effects),
            "round": int(self.round),
            "removed": self.removed,
            "swapped_in": self.swapped_in,
            "law_reset": self.law_reset,
            "unseen_compliance": [_num(x) for x in self.unseen_compliance],
            "error": _num(self.error),
            "validation_error": _num(self.validation_error),
            "params": {e: {k: [_num(x) for x in v] for k, v in p.items()} for e, p in self.params.items()},
            "ci95": {e: {k: [_num(x) for x in v] for k, v in p.items()} for e, p in self.ci95.items()},
            "channel_error": {k: _num(v) for k, v in self.channel_error.items()},
            "validation_channel_error": {k: _num(v) for k, v in self.validation_channel_error.items()},
        }

    def in_floors(self, ratio: Mapping[str, float]) -> "HistoryStep":
        """The same step in other noise floors: channel c's floor ``ratio[c]`` × the one
        its multiples are in (channels not named keep theirs)."""
        per = {c: v / ratio.get(c, 1.0) for c, v in self.channel_error.items()}
        val = {c: v / ratio.get(c, 1.0) for c, v in self.validation_channel_error.items()}
        moved = any(r != 1.0 for r in ratio.values())
        return replace(self, channel_error=per, error=_systematic_of(per), validation_channel_error=val,
                       validation_error=_systematic_of(val) if val else (math.nan if moved else self.validation_error))


@dataclass
class History:
    """The loop nominal → +effect → +effect …: each step's error per channel and overall,
    and the diagnosis of every round.

    Attributes
    ----------
    steps : list of HistoryStep
        ``steps[0]`` is the model as given; each later step adds one effect (all added
        effects refitted jointly), removes one (backward step), swaps one for another
        (swap step) or adds one with an earlier effect back at its base law; each names
        its ``round``.
    diagnoses : list of Diagnosis
        The diagnosis of each round: the first of the model as given, each later one of the
        model the round before left (for a base-law step, of the model with that law set
        back); ``Diagnosis.problem.model`` is the model it diagnosed.
    conclusion : str
        Built from the whole history: what was added (value, interval, how far the error
        fell overall and on the channels it acts on), then what is left.
    error : str
        Empty when complete; else what stopped the loop (the rounds before are kept).
    notes : list of str
        What the swap and base-law steps tried (the effect, the candidates), and why each
        was kept or not (its BIC gain and held-out error, no candidate significant, or the
        failure that left the model as it was); and where a refitted model's residual gave
        some channel's noise floor anew (:data:`NOISE_RECHECK`) or its encoder floor
        (:data:`ENCODER_NOTE`).
    noise : dict
        The noise floor σ per channel (channel unit) every step's error is in: first
        estimated from the residual of the model as given, then re-estimated from each
        refitted model's where it differs by more than :data:`NOISE_RECHECK`.
    """

    steps: List[HistoryStep]
    diagnoses: List[Diagnosis]
    conclusion: str
    run: str = ""
    seconds: float = 0.0
    error: str = ""
    noise: Dict[str, float] = field(default_factory=dict)
    notes: List[str] = field(default_factory=list)
    noise_initial: Dict[str, float] = field(default_factory=dict)
    """The floors σ per channel first estimated, from the residual of the model as given
    (``noise`` holds those every step is in: re-estimated as the model improved)."""
    problem: Any = field(default=None, repr=False)
    """The run's :class:`ReplayProblem` of the model as given, in the floors of ``noise``
    (``None``: the first diagnosis's is used)."""

    @property
    def complete(self) -> bool:
        """Whether every round finished (no ``error``)."""
        return not self.error

    def _floors_problem(self) -> Optional[ReplayProblem]:
        if self.problem is not None:
            return self.problem
        return self.diagnoses[0].problem if self.diagnoses else None

    @property
    def encoder_floor(self) -> Dict[str, float]:
        """Per channel, the replay error the encoder's own error causes with the last
        model of the loop (bootstrapped again on each refitted model), as a multiple of the
        floor in ``noise`` (:attr:`ReplayProblem.encoder_floor`; 1 = nothing)."""
        p = self._floors_problem()
        try:
            return dict(p.encoder_floor) if p is not None else {}
        except Exception:  # noqa: BLE001 - a failed run's history still goes out
            return {}

    @property
    def at_floor(self) -> List[str]:
        """Channels whose measured signal is at its noise floor in ``noise`` (std < 1.5 σ)."""
        p = self._floors_problem()
        return list(p.at_floor) if p is not None else []

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
        return f"History(effects={self.effects}, error {fall}{', incomplete' if self.error else ''})"

    def to_pandas(self) -> "pd.DataFrame":
        """One row per step: its round, what it changed (+ added, − removed, a → b swapped),
        effects, systematic error (whole run, held out) and each channel's noise multiple."""
        pd = _pd()
        rows = []
        for i, s in enumerate(self.steps):
            change = (f"{s.removed} → {s.swapped_in}" if s.swapped_in else f"− {s.removed}" if s.removed
                      else (f"+ {s.effects[-1]} ({s.law_reset} at its base law)" if s.law_reset else f"+ {s.effects[-1]}") if s.effects and i else "")
            row: Dict[str, Any] = {"step": i, "round": s.round, "change": change, "effects": " + ".join(s.effects) or "nominal", "error": s.error,
                                   "validation_error": s.validation_error}
            row.update({f"noise× {c}": v for c, v in s.channel_error.items()})
            rows.append(row)
        return pd.DataFrame(rows).set_index("step")

    def to_dict(self) -> Dict[str, Any]:
        """The CLI's ``--json`` contract: ``run``, ``nominal_error``, ``error_definition``,
        ``noise`` (σ per channel), ``channels`` (per channel: noise, noise multiple before
        and after, at the noise floor, the encoder floor (the replay error the encoder's own
        error causes, a multiple of the noise), the nominal residual's isolated spikes: count, first
        times [s], share of the excess; :meth:`ReplayProblem.spikes`), ``suspects`` (first round, every effect ranked),
        ``history`` (each step's effects and error), ``rounds``, ``conclusion``, ``notes``
        (what the swap and base-law steps tried, the noise floors re-estimated), ``noise_initial`` (σ per channel
        as first estimated, before the loop re-estimated any), ``complete`` and, when a round failed,
        ``error``."""
        first = self.diagnoses[0] if self.diagnoses else None
        floor = self.at_floor
        enc = self.encoder_floor
        spikes: Dict[str, Dict[str, Any]] = {}
        fp = self._floors_problem()
        if fp is not None:
            try:
                spikes = fp.spikes()
            except Exception:  # noqa: BLE001 - the numbers still go out
                spikes = {}
        out: Dict[str, Any] = {
            "run": self.run,
            "nominal_error": _num(self.steps[0].error),
            "error_definition": ERROR_DEFINITION,
            "noise": {k: _num(v) for k, v in self.noise.items()},
            "noise_initial": {k: _num(v) for k, v in (self.noise_initial or self.noise).items()},
            "channels": {
                c: {
                    "noise_std": _num(self.noise.get(c)),
                    "noise_multiple_nominal": _num(self.steps[0].channel_error.get(c)),
                    "noise_multiple_final": _num(self.steps[-1].channel_error.get(c)),
                    "at_noise_floor": c in floor,
                    "encoder_floor": _num(enc.get(c, 1.0)),
                    "spikes": spikes.get(c, {}).get("count", 0),
                    "spike_times": spikes.get(c, {}).get("times", []),
                    "spike_share": _num(spikes.get(c, {}).get("share", 0.0)),
                }
                for c in self.steps[0].channel_error
            },
            "suspects": [s.to_dict() for s in first.suspects] if first else [],
            "history": [s.to_dict() for s in self.steps],
            "rounds": [d.to_dict() for d in self.diagnoses],
            "residual_white": bool(self.diagnoses[-1].residual_white) if self.diagnoses else False,
            "conclusion": self.conclusion,
            "notes": list(self.notes),
            "complete": self.complete,
            "seconds": self.seconds,
        }
        if self.error:
            out["error"] = self.error
        return out

    def to_json(self, **kw: Any) -> str:
        return json.dumps(self.to_dict(), **kw)

    def plot(self, ax: Any = None) -> Any:
        """The fall of the error: overall (bold) and each channel's noise multiple."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(7, 4))
        x = np.arange(len(self.steps))
        labels = ["nominal"] + [(f"{s.removed}→{s.swapped_in}" if s.swapped_in else f"−{s.removed}" if s.removed else f"+{s.effects[-1]}")
                                for s in self.steps[1:]]
        chans = list(self.steps[0].channel_error)
        for c in chans:
            ax.plot(x, [s.channel_error.get(c, np.nan) for s in self.steps], color="0.7", lw=1)
        ax.plot(x, [max(s.error, 1e-3) for s in self.steps], "o-", color="tab:red", lw=2.5, label="systematic error S")
        ax.axhline(1.0, color="k", ls=":", lw=1, label="noise floor (channels)")
        ax.set_xticks(x)
        ax.set_xticklabels(labels, rotation=15)
        ax.set_yscale("log")
        ax.set_ylabel("noise units")
        ax.set_title("error history (grey: channels' noise multiples)")
        ax.legend()
        return ax


# ---------------------------------------------------------------------------- fitting one candidate


def _x0(prob: ReplayProblem, free: List[Tuple[fx.EffectParam, int]], base_flat: np.ndarray) -> np.ndarray:
    x0 = []
    for p, i in free:
        v = base_flat[p.offset + i]
        if p.effect == "actuator_saturation":
            c = f"tau{i + 1}"
            if c in prob.channels:
                # the plateau of the measured |torque|: the median of the samples within
                # 4 noise deviations of the peak (the peak itself is biased up by the noise)
                y = np.abs(prob.measured[:, prob.channels.index(c)])
                y = y[np.isfinite(y)]
                sd = prob.noise[c]
                top = y[y >= float(np.max(y)) - 4.0 * sd]
                v = float(np.median(top))
            else:
                v = 1e3
        x0.append(v)
    return np.array(x0, dtype=float)


def _candidates(effect: str, prob: ReplayProblem, free: List[Tuple[fx.EffectParam, int]], flat: np.ndarray, x0: np.ndarray, extra: Optional[List[Dict[str, float]]] = None) -> List[np.ndarray]:
    cands = est.seed_points(effect, free, x0, extra)
    if effect == "actuator_saturation":
        # x0 puts every limit at its joint's measured peak; a joint that never saturated is
        # better left unlimited (its peak is only clipped by noise), so also try each joint
        # limited alone (the objective is flat above a peak: the fit cannot find this itself)
        for k in range(len(free)):
            x = np.full_like(x0, 1e3)
            x[k] = x0[k]
            cands.append(x)
    return cands


def _left_out(flat: np.ndarray, p: fx.EffectParam, i: int) -> bool:
    """Whether entry ``i`` of ``p`` is one its effect's structure leaves out in ``flat``:
    an infinite value in that entry of any of the effect's parameters of the same length
    (torsion's ``k_t = inf``: that link rigid, its damping idle). Refitting it would move
    a parameter the run cannot see (an interval of ±inf that spoils the others')."""
    return any(q.length == p.length and math.isinf(flat[q.offset + i]) for q in fx.EFFECTS[p.effect].params.values())


def _absent_entries(structure: Optional[Dict[str, Any]]) -> Set[int]:
    """Joint/link entries a structure leaves out (an infinite stiffness: that link rigid)."""
    out: Set[int] = set()
    for v in (structure or {}).values():
        if isinstance(v, (list, tuple)):
            out.update(i for i, x in enumerate(v) if isinstance(x, float) and math.isinf(x))
    return out


def _step_for(prob: ReplayProblem, m: "Model", check: "Model") -> float:
    """The step [s] candidate ``m`` runs at: its own if stable with the margin, else the
    largest divisor of the output period within ``STABILITY_MARGIN`` of the stability
    limit of ``check`` (the candidate at its stiffest seed)."""
    q = check.rest_state(list(prob.q_enc[0] if not prob.closed else prob.q0))
    # stable_dt returns the model's own dt when that is stable: ask with a huge step to get the limit
    sdt = check.with_dt(1.0).stable_dt([float(x) for x in q], replay=not prob.closed)
    if STABILITY_MARGIN * sdt >= m.dt * (1 - 1e-12):
        return m.dt
    period = 1.0 / prob.sample_rate
    k = max(1, int(math.ceil(period / (STABILITY_MARGIN * sdt) - 1e-9)))
    return period / k


#: Effect parameters [rad per motor joint] that are play in a joint: a play narrower than
#: :data:`PLAY_READINGS` encoder readings (:attr:`ReplayProblem.encoder_width`) is not a finding.
_PLAY = {"backlash": "gap"}
PLAY_READINGS = 0.5
"""Readings a play must span (on at least one joint) to be a finding: half a reading, the
quantisation of the replayed angle itself. It was 2 before the servo's unseen motion was
part of the replay (:mod:`popup.unseen`): a play of a quarter to one reading then stood in
for that motion on MuJoCo nominal runs with coarse encoders and quiet sensors. With the
motion in the replay, twelve such runs (12- and 14-bit, trapezoid, lab and multisine, 200
and 500 Hz, noise × 0.35) fitted with the rule off gave a play of 0 on 35 of 36 joints
(0.11 reading on one, score below zero; six popup-engine runs likewise, none significant), while a MuJoCo run with a true play of 1.1-1.8
readings (12-bit, 200 Hz trapezoid) was refused by the old rule although the play took
the error from 2.05 to 0.30 noise units, every channel to within 1.2 × its noise
(benchmarks/README.md, session 23)."""


def _unresolved_play(prob: ReplayProblem, name: str, flat: np.ndarray) -> str:
    """Why effect ``name`` fitted to ``flat`` is below the encoder's resolution ("" if not)."""
    key = _PLAY.get(name)
    if key is None:
        return ""
    w = prob.encoder_width
    gap = np.asarray(flat[fx.EFFECTS[name].params[key].slice], dtype=float)
    if not (np.any(w > 0) and np.all(gap < PLAY_READINGS * w)):
        return ""
    return (f"not significant: its {key} ({_fmt_list(gap.tolist())} rad) is narrower than {PLAY_READINGS:g} encoder readings "
            f"({_fmt_list(w.tolist())} rad each): a joint moving unseen inside its reading looks the same")


def _silent_on(mask: np.ndarray, z0: np.ndarray, z1: np.ndarray) -> bool:
    """Whether residual ``z1`` equals ``z0`` on the samples of ``mask`` (an effect that does
    not act there, e.g. a torque limit reached only in the training blocks): the held-out
    samples can then neither confirm nor refute it."""
    a, b = np.asarray(z0)[mask], np.asarray(z1)[mask]
    if a.size == 0 or not np.array_equal(np.isnan(a), np.isnan(b)):
        return False
    ok = ~np.isnan(a)
    return bool(ok.any() and np.max(np.abs(a[ok] - b[ok])) <= 1e-9)


def _rank_key(s: Suspect) -> Tuple[int, int, float]:
    return (0 if s.significant else 1, 0 if s.tested else 1, -s.score if math.isfinite(s.score) else math.inf)


class _Fitted:
    """A fitted candidate on its own problem (possibly another structure and step)."""

    def __init__(self, name: str, variant: str, prob: ReplayProblem, z_base: np.ndarray, free: List[Tuple[fx.EffectParam, int]], out: est.FitOutcome,
                 k: Optional[int] = None) -> None:
        self.name, self.variant, self.prob, self.z_base, self.free, self.out = name, variant, prob, z_base, free, out
        lr, self.neff = est.log_ratio(prob, z_base, out.z, prob.train)
        self.k = len(free) if k is None else int(k)  # the candidate's own parameters (refitted earlier effects excluded)
        self.score = lr - self.k * math.log(self.neff)
        self.lr_val, _ = est.log_ratio(prob, z_base, out.z, prob.validation)
        self.e0, _ = prob.error(z_base)
        self.e1, self.per1 = prob.error(out.z)
        self.v0, _ = prob.error(z_base, prob.validation)
        self.v1, _ = prob.error(out.z, prob.validation)
        self.explained = 1.0 - (self.e1 / self.e0) ** 2 if self.e0 > 0 and math.isfinite(self.e1) else 0.0
        self.unresolved = _unresolved_play(prob, name, out.flat)
        self.silent = _silent_on(prob.validation & prob.used, z_base, out.z)
        self.significant = bool(
            self.score > SCORE_THRESHOLD and self.explained >= MIN_EXPLAINED
            and ((self.lr_val > 0 and self.v1 < self.v0) or self.silent) and not self.unresolved
        )

    def suspect(self, ev: Dict[str, Any], nfev: int, message: str = "") -> Suspect:
        names = [f"{p.name}[{i}]" if p.effect == self.name else f"{p.effect}.{p.name}[{i}]" for p, i in self.free]
        half, ident = est.uncertainty(self.out, self.free, names, self.neff)
        ci: Dict[str, List[float]] = {}
        for (p, i), h in zip(self.free, half):
            if p.effect == self.name:
                ci.setdefault(p.name, [math.nan] * p.length)[i] = float(h)
        return Suspect(
            self.name, self.significant, float(self.score), est.params_dict(self.name, self.out.flat), ci, self.e0, self.e1, self.per1, ev,
            n_eff=self.neff, n_rollouts=nfev, tested=True, explained=self.explained,
            message="; ".join(m for m in (self.unresolved, "not checked on the held-out samples: it does not act there" if self.silent else "", message) if m),
            validation_before=self.v0, validation_after=self.v1, validation_lr=self.lr_val, variant=self.variant,
            identifiability=ident, dt=float(self.prob.model.dt), fitted=sorted({p.name for p, _ in self.free if p.effect == self.name}),
            refitted={e: est.params_dict(e, self.out.flat) for e in sorted({p.effect for p, _ in self.free if p.effect != self.name})},
        )


def _fit_candidate(prob: ReplayProblem, name: str, structure: Optional[Dict[str, Any]], only: Optional[Sequence[str]], start: Optional[Dict[str, List[float]]],
                   extra_seeds: Optional[List[Dict[str, Any]]], max_iter: int, variant: str = "",
                   also: Optional[List[Tuple[fx.EffectParam, int]]] = None, stiffest: Optional[Dict[str, Any]] = None,
                   dt: Optional[float] = None, seeds: bool = True) -> Tuple[_Fitted, str]:
    """Fit one candidate (``structure``, the names ``only`` or every fitted one) from
    ``start`` and the effect's seeds (``seeds=False``: from ``start`` alone), with the
    entries of ``also`` refitted jointly; ``dt``: the step to use (default: from the
    structure's stability limit at ``stiffest``)."""
    model = prob.model
    m = model
    note = ""
    pb, z_base = prob, prob.residuals(prob.nominal_simulation())
    if structure is not None:
        m = model.with_effect(name, **structure)
        if dt is None:
            check = m.with_effect(name, **(stiffest if stiffest is not None else _STIFFEST.get(name, {})))
            dt = _step_for(prob, m, check)
        if dt < model.dt * (1 - 1e-12):
            m = m.with_dt(dt)
            pb = prob.with_model(model.with_dt(dt))
            z_base = pb.residuals(pb.nominal_simulation())
            note = f"run at dt = {dt:.3g} s (its structure's stability limit; the nominal model re-run at the same step)"
    p = pb.with_model(m) if m is not pb.model else pb
    free = est.free_params(name, only)
    absent = _absent_entries(structure)
    free = [(q, i) for q, i in free if i not in absent]
    flat = m.effects_flat.copy()
    if start:
        for k, v in start.items():
            sl = fx.EFFECTS[name].params[k].slice
            keep = flat[sl].copy()
            flat[sl] = v
            for i in absent:  # an entry the structure leaves out keeps the structure's value
                if i < len(keep):
                    flat[sl.start + i] = keep[i]
    x0 = np.array([flat[q.offset + i] for q, i in free]) if start else _x0(p, free, flat)
    cands = _candidates(name, p, free, flat, x0, extra_seeds) if seeds else [x0]
    # the effects added in earlier rounds are refitted with the candidate (forward
    # selection with refit: an earlier fit biased by this effect's absence is corrected)
    others = [pi for pi in (also or []) if pi[0].effect != name]
    cur = np.array([flat[q.offset + i] for q, i in others])
    cands = [np.concatenate([c, cur]) for c in cands]
    free_all = free + others
    iters = max(max_iter, _MIN_ITER.get(name, 0))
    if name in _SHORT_FIRST and seeds:
        # a lightly damped response (or a link side crossing its gap) drifts out of phase
        # over a long run, which makes the full-run objective a needle around the truth:
        # fit on a short horizon first (a wide basin), then on horizons doubled in turn,
        # each from the last optimum (continuation), and offer the result as one more start
        t0, t1 = float(p.time[0]), float(p.time[-1])
        h = max(SHORT_HORIZON_S, 0.2 * (t1 - t0))
        ph = p.with_horizon(t0 + h)
        if ph is not p:
            xh, _ = est.best_start(ph, free_all, flat, cands)
            if name in _COORDINATE_SEEDS:
                xh = _coordinate_seeds(ph, name, free_all, flat, xh)
            xh = est.fit(ph, flat, free_all, xh, iters).x
            while 2.0 * h < t1 - t0:
                h *= 2.0
                ph = p.with_horizon(t0 + h)
                xh = est.fit(ph, flat, free_all, xh, iters, mask=p.train[p.time <= t0 + h]).x
            cands.append(xh)
    xs, _ = est.best_start(p, free_all, flat, cands)
    out = est.fit(p, flat, free_all, xs, iters)
    return _Fitted(name, variant, p, z_base, free_all, out, k=len(free)), note


def _coordinate_seeds(prob: ReplayProblem, name: str, free: List[Tuple[fx.EffectParam, int]], flat: np.ndarray, x: np.ndarray) -> np.ndarray:
    """One sweep over the entries of ``name``'s seeded parameters: each entry in turn set to
    every value of a fine log grid over its seeds' range (the others at the best so far), the
    best kept (one batched rollout per entry). Seeds that move every joint together miss
    unequal gaps."""
    seen: Dict[str, List[float]] = {}
    for seed in est.SEEDS.get(name, []):
        for k, v in seed.items():
            seen.setdefault(k, []).extend(np.atleast_1d(np.asarray(v, dtype=float)).tolist())
    # a log grid COORDINATE_STEP apart over the seeds' range: a link side floating in its
    # gap makes the objective a needle a few % wide in that gap, even on the short horizon
    grid = {k: np.exp(np.arange(math.log(min(v)), math.log(max(v)) + 1e-9, math.log(COORDINATE_STEP))).tolist() for k, v in seen.items() if min(v) > 0}
    x = np.asarray(x, dtype=float).copy()
    for j, (q, _) in enumerate(free):
        if q.effect != name or q.name not in grid:
            continue
        cands = [x]
        for v in grid[q.name]:
            c = x.copy()
            c[j] = min(max(v, q.lower), q.upper)
            cands.append(c)
        x, _ = est.best_start(prob, free, flat, cands)
    return x


def _try_effect(prob: ReplayProblem, name: str, ev: Dict[str, Any], max_iter: int, also: Optional[List[Tuple[fx.EffectParam, int]]] = None,
                prior: Optional[Mapping[str, Sequence[float]]] = None) -> Suspect:
    """Fit ``name`` from its seeds (and ``prior``, its fit of an earlier round, as one more
    start), then its variants; the best as a :class:`Suspect`."""
    n0 = prob.nfev
    try:
        fitted, note = _fit_candidate(prob, name, _STRUCTURE.get(name), None, None, [dict(prior)] if prior else None, max_iter, also=also)
    except Exception as e:  # noqa: BLE001 - one effect failing must not stop the ranking
        return Suspect(name, False, -math.inf, {}, {}, math.nan, math.nan, {}, ev, tested=False,
                       message=f"not tested: {type(e).__name__}: {e}")
    best = fitted
    best_var: Optional[Dict[str, Any]] = None
    tried: List[Tuple[Dict[str, Any], _Fitted]] = []
    notes = [note] if note else []
    base_params = est.params_dict(name, fitted.out.flat)
    for var in VARIANTS.get(name, []):
        if not (fitted.significant or var.get("alternative")):
            continue
        try:
            struct = dict(_STRUCTURE.get(name) or {})
            struct.update(var.get("structure") or {})
            only = None
            start = None
            if var.get("extra"):
                only = sorted({p.name for p, _ in fitted.free} | set(var["extra"]))
                start = {k: v for k, v in base_params.items() if k in only and k not in var["extra"]}
            # a structural variant starts from the base fit: its step is set for 1.5 × the
            # base's stiffness, not the whole plausible range (3 segments at k_scale 5 would
            # need a 14 × smaller step)
            stiff = {k: [min(1.5 * x, est.BOUNDS.get((name, k), (0.0, math.inf))[1]) for x in base_params[k]]
                     for k in _STIFFEST.get(name, {}) if k in base_params} if var.get("structure") else None
            if var.get("structure") and stiff:
                start = {k: base_params[k] for k in stiff}
            if var.get("stiffest"):
                stiff = dict(var["stiffest"])
            vf, _ = _fit_candidate(prob, name, struct or None, only, start, var.get("seeds"), max_iter, variant=str(var["name"]), also=also, stiffest=stiff)
        except Exception as e:  # noqa: BLE001
            notes.append(f"variant {var['name']} not tested: {type(e).__name__}: {e}")
            continue
        tried.append((var, vf))
        gain = _gain(vf, best)
        if vf.significant and gain > (SCORE_THRESHOLD if best.significant else 0.0):
            notes.append(f"variant {var['name']} preferred (score {vf.score:.1f} vs {best.score:.1f}; BIC gain over it {gain:.1f})")
            best, best_var = vf, var
        else:
            notes.append(f"variant {var['name']} not preferred (score {vf.score:.1f} vs {best.score:.1f}; BIC gain over it {gain:.1f}"
                         + (f"; {vf.unresolved}" if vf.unresolved else "") + ")")
    if best_var is not None:
        best = _try_combined(prob, name, best, best_var, tried, max_iter, also, notes)
    return best.suspect(ev, prob.nfev - n0, "; ".join(notes))


def _combined(a: Mapping[str, Any], b: Mapping[str, Any]) -> Optional[Dict[str, Any]]:
    """Variants ``a`` and ``b`` of one effect together (structures merged, extras joined;
    named "a + b"), or ``None`` where they cannot be (another law; structures on the same
    parameter)."""
    if a.get("alternative") or b.get("alternative"):
        return None
    sa, sb = dict(a.get("structure") or {}), dict(b.get("structure") or {})
    if set(sa) & set(sb):
        return None
    extra = sorted(set(a.get("extra") or []) | set(b.get("extra") or []))
    out: Dict[str, Any] = {"name": f"{a['name']} + {b['name']}", "structure": {**sa, **sb}, "extra": extra}
    if a.get("stiffest") or b.get("stiffest"):
        out["stiffest"] = {**dict(a.get("stiffest") or {}), **dict(b.get("stiffest") or {})}
    return out


def _variant_named(effect: str, name: str) -> Optional[Dict[str, Any]]:
    """The variant of ``effect`` called ``name`` (:data:`VARIANTS`, or a combination of
    them "a + b" as :func:`_try_combined` names it); ``None`` for the base law."""
    if not name:
        return None
    out: Optional[Dict[str, Any]] = None
    for part in name.split(" + "):
        v = next((x for x in VARIANTS.get(effect, []) if x["name"] == part), None)
        if v is None:
            return None
        out = dict(v) if out is None else _combined(out, v)
        if out is None:
            return None
    return out


def _variant_key(v: Mapping[str, Any]) -> Tuple[Tuple[str, ...], str]:
    return tuple(sorted(v.get("extra") or [])), repr(sorted((v.get("structure") or {}).items()))


def _try_combined(prob: ReplayProblem, name: str, best: _Fitted, best_var: Mapping[str, Any], tried: Sequence[Tuple[Mapping[str, Any], _Fitted]],
                  max_iter: int, also: Optional[List[Tuple[fx.EffectParam, int]]], notes: List[str]) -> _Fitted:
    """The preferred variant ``best_var`` (fit ``best``) with each other variant of ``tried``
    that beats the nominal model by the threshold added to it, fitted from ``best``'s values
    (and from that variant's own fit): kept where the likelihood
    prefers it by the significance threshold in BIC. A 3-segment link whose root is stiffer
    is neither "3 segments" nor "stiffer root" (a popup-engine run left 0.83 noise units
    with the second alone, 0.37 with both, on the truth's values)."""
    own = {_variant_key(v) for v in VARIANTS.get(name, [])}
    params = est.params_dict(name, best.out.flat)
    for var, vf in tried:
        # a variant that beats the nominal model by the threshold on its own but not on the
        # held-out part may miss only what ``best`` adds (compliant flanks at the default
        # link-side inertia: score 280 where the fitted inertia had 3990), so it is tried
        # with it; the combination must pass the whole test itself
        if var is best_var or not (vf.significant or (vf.score > SCORE_THRESHOLD and not vf.unresolved)):
            continue
        cv = _combined(best_var, var)
        if cv is None:
            continue
        if _variant_key(cv) in own or _variant_key(cv) == _variant_key(best_var):  # nothing new
            continue
        try:
            struct = {**dict(_STRUCTURE.get(name) or {}), **cv["structure"]}
            fitted_names = {p.name for p, _ in best.free if p.effect == name}
            only = sorted(fitted_names | set(cv["extra"]))
            # ``best``'s values of what it fitted; what the other variant adds starts from the
            # structure's value (``best``'s own is its law's neutral one: contact_k = 0, the
            # rigid flanks, is no start for a stiffness fitted as its logarithm)
            start = {k: v for k, v in params.items() if k in fitted_names}
            stiff = ({k: [min(1.5 * x, est.BOUNDS.get((name, k), (0.0, math.inf))[1]) for x in params[k]]
                      for k in _STIFFEST.get(name, {}) if k in params} if cv["structure"] else None) or None
            if cv.get("stiffest"):
                stiff = dict(cv["stiffest"])
            # two more starts: the other variant's own fit, with ``best``'s extras and as it
            # is (on MuJoCo's soft gear, from the flanks' seeds alone the combination ended 640
            # BIC below the fitted inertia alone; from the flanks' own fit, 615 above it)
            own_extra = set(best_var.get("extra") or [])
            vp = {k: v for k, v in est.params_dict(name, vf.out.flat).items() if k in only}
            from_var = [{k: v for k, v in vp.items() if k not in own_extra}, vp]  # with best's extras, and as fitted
            cf, _ = _fit_candidate(prob, name, struct, only, start, from_var + list(var.get("seeds") or []), max_iter,
                                   variant=cv["name"], also=also, stiffest=stiff,
                                   seeds=bool(set(var.get("extra") or []) - own_extra))
        except Exception as e:  # noqa: BLE001
            notes.append(f"variant {cv['name']} not tested: {type(e).__name__}: {e}")
            continue
        gain = _gain(cf, best)
        if cf.significant and gain > SCORE_THRESHOLD:
            notes.append(f"variant {cv['name']} preferred (score {cf.score:.1f} vs {best.score:.1f}; BIC gain over it {gain:.1f})")
            best, best_var = cf, cv
        else:
            notes.append(f"variant {cv['name']} not preferred (score {cf.score:.1f} vs {best.score:.1f}; BIC gain over it {gain:.1f})")
    return best


def _screen_fit(prob: ReplayProblem, name: str, ev: Dict[str, Any], max_iter: int, start: Mapping[str, Sequence[float]]) -> Suspect:
    """``name`` at its base law fitted from ``start`` alone (its fit of an earlier round): the
    cheap screen of :func:`diagnose`'s ``screen``."""
    n0 = prob.nfev
    base = {p.name for p in fx.EFFECTS[name].fit_params}
    st = {k: list(v) for k, v in start.items() if k in base}
    try:
        fitted, note = _fit_candidate(prob, name, _STRUCTURE.get(name), None, st or None, None, max_iter, seeds=False)
    except Exception as e:  # noqa: BLE001 - one effect failing must not stop the ranking
        return Suspect(name, False, -math.inf, {}, {}, math.nan, math.nan, {}, ev, tested=False,
                       message=f"not tested: {type(e).__name__}: {e}")
    return fitted.suspect(ev, prob.nfev - n0, note)


def _gain(a: _Fitted, b: _Fitted) -> float:
    """BIC gain of fit ``a`` over fit ``b`` of the same run: their likelihood ratio taken
    directly, with one effective sample count (``a``'s residual), less ln n_eff per extra
    parameter. Each fit's score against the nominal weighs its log-ratio by the n_eff of
    its own residual, so two good fits of the same law differ there by a percent of a large
    score (a friction fit whose residual was a little whiter scored 95 more with three parameters
    that landed on the default); a direct ratio does not. Fits on different output grids
    fall back to the difference of their scores."""
    if a.out.z.shape == b.out.z.shape and np.array_equal(np.asarray(a.prob.time), np.asarray(b.prob.time)):
        lr, ne = est.log_ratio(a.prob, b.out.z, a.out.z, a.prob.train)
        return lr - (a.k - b.k) * math.log(ne)
    return a.score - b.score


def _refit_jointly(prob: ReplayProblem, s: Suspect, ev: Dict[str, Any], max_iter: int, also: List[Tuple[fx.EffectParam, int]],
                   prior: Optional[Mapping[str, Sequence[float]]] = None) -> Suspect:
    """The screened candidate ``s`` (fitted with the earlier effects held) refitted with
    them (``also``): its law (variant), step and fitted names, from its screened optimum,
    and also from ``prior`` (its fit of an earlier round; the better of the two is kept).
    With the earlier effects held, a candidate they absorbed screens at its neutral value
    (a payload at +0.0002 kg beside a torsion fitted without it), a point the joint fit
    does not leave; its fit from the round before is in the joint basin."""
    n0 = prob.nfev
    var = _variant_named(s.effect, s.variant)
    struct = dict(_STRUCTURE.get(s.effect) or {})
    struct.update((var or {}).get("structure") or {})
    start = {k: list(s.params[k]) for k in s.fitted if k in s.params}
    starts = [start]
    if prior:
        alt = dict(start)
        alt.update({k: list(v) for k, v in prior.items() if k in start and np.shape(v) == np.shape(start[k])})
        if alt != start:
            starts.append(alt)
    try:
        fits = [_fit_candidate(prob, s.effect, struct or None, list(s.fitted) or None, st, None, max_iter, variant=s.variant,
                               also=also, dt=s.dt, seeds=False)[0] for st in starts]
        fitted = max(fits, key=lambda f: f.score if math.isfinite(f.score) else -math.inf)
    except Exception as e:  # noqa: BLE001 - the screened fit stands
        s.message = "; ".join(x for x in (s.message, f"joint refit failed: {type(e).__name__}: {e}") if x)
        return s
    j = fitted.suspect(ev, s.n_rollouts + prob.nfev - n0, s.message)
    if j.score >= s.score:
        j.message = "; ".join(x for x in (s.message, f"refitted with {', '.join(sorted({p.effect for p, _ in also}))} (score {s.score:.1f} → {j.score:.1f})") if x)
        return j
    s.n_rollouts = j.n_rollouts
    s.message = "; ".join(x for x in (s.message, f"joint refit scored lower ({j.score:.1f}): the screened fit is kept") if x)
    return s


# ---------------------------------------------------------------------------- API


def model_error(model: "Model", run: MeasuredRun, *, channels: Optional[Sequence[str]] = None, sample_rate: Optional[float] = None,
                problem: Optional[ReplayProblem] = None) -> Tuple[float, Dict[str, float]]:
    """Systematic error (:data:`ERROR_DEFINITION`) and each channel's noise multiple of
    ``model`` on ``run``; with ``problem`` (e.g. ``Diagnosis.problem``) its channels, encoder
    and noise floor are used, so the number is the one the diagnosis predicted."""
    prob = problem.with_model(model) if problem is not None else ReplayProblem(model, run, channels=channels, sample_rate=sample_rate)
    return prob.error()


def diagnose(
    model: "Model",
    run: MeasuredRun,
    *,
    effects: Optional[Sequence[str]] = None,
    channels: Optional[Sequence[str]] = None,
    sample_rate: Optional[float] = None,
    threads: int = 0,
    max_iter: int = 15,
    problem: Optional[ReplayProblem] = None,
    progress: Optional[Progress] = None,
    refit: Optional[Mapping[str, Sequence[str]]] = None,
    rank_at_floor: bool = False,
    starts: Optional[Mapping[str, Mapping[str, Sequence[float]]]] = None,
    screen: int = 0,
    joint: bool = False,
) -> Diagnosis:
    """Rank every effect of the library (or ``effects``) by how much of the model's
    systematic error on ``run`` it explains, each fitted, validated on held-out samples,
    with intervals, identifiability and its residual evidence (module docs).

    Effects that ``model`` already has are skipped. ``threads=0`` uses every core.
    ``problem``: the run already set up in ``model`` (:class:`ReplayProblem`).
    ``progress``: called with ``{"effect", "done", "total"}`` before each effect.
    ``refit``: effects of ``model`` (``{effect: [parameter names]}``, as :func:`improve`
    added them) refitted jointly with each candidate.
    ``rank_at_floor``: for a model at its floor (module docs), fit and rank the candidates
    anyway (none is significant); by default they are not tried, each saying why.
    ``starts``: ``{effect: {parameter: values}}``, one more start for that effect's fit (as
    :func:`improve` passes each candidate's fit of the round before: an effect fitted well
    alone keeps that basin once another effect is in the model).
    ``screen``: when > 0, each candidate with a start in ``starts`` is first fitted from
    that start alone (its base law: no seeds, continuation or variants), and only the
    ``screen`` best of that screen, and any significant in it, get the full multi-start
    fit, and at most ``screen`` are refitted jointly with ``refit``; the others keep their
    screened fit, saying so (as :func:`improve` does from its third round on, and with
    ``screen=1`` for the swap and base-law steps, which take only the best candidate).
    ``joint``: every candidate is fitted jointly with ``refit`` from its seeds, with no fit
    with those effects held first: for a candidate whose error an earlier effect's value
    took, which a fit with that value held does not see (:func:`improve`'s base-law step
    over the candidates never significant before).
    """
    t_start = time.perf_counter()
    est.check_max_iter(max_iter)
    names = list(fx.EFFECT_NAMES if effects is None else effects)
    for n in names:
        fx.normalize(n, {})
    given = problem is not None
    if problem is None:
        problem = fit_unseen_motion(ReplayProblem(model, run, channels=channels, sample_rate=sample_rate, threads=threads))
    elif problem.model is not model:
        raise InputError("diagnose: problem= must be a ReplayProblem of this model (ReplayProblem.with_model)")
    prob = problem
    n_start = prob.nfev if given else 0
    cmp = compare(model, run, problem=prob)
    e0, per0 = prob.error()
    have = set(fx.active(model.effects_flat))
    flat0 = model.effects_flat
    also = [pi for e, ps in (refit or {}).items() for pi in est.free_params(e, list(ps) or None) if not _left_out(flat0, *pi)]
    todo = [n for n in names if n not in have]
    suspects: List[Suspect] = []
    evs: Dict[str, Dict[str, Any]] = {}
    floor = _model_at_floor(prob, e0, per0)
    if floor and not rank_at_floor:
        why = (f"not tried: the model is at its floor (systematic error {prob.floor_error(per0):.3g} above the noise and the "
               f"encoder's replay error, every channel within {FLOOR_MULTIPLE:g}× of it): nothing is left for an effect to "
               "explain (rank_at_floor=True, or --rank-at-floor, fits them anyway)")
        todo = []
        for name in names:
            if name not in have:
                suspects.append(Suspect(name, False, -math.inf, {}, {}, e0, math.nan, {}, _evidence(name, cmp, prob), tested=False, message=why))
    # with earlier effects to refit, every candidate is first screened with them held, and
    # only the JOINT_TOP best are refitted jointly (the refit's extra Jacobian columns are
    # most of a round's cost, and the ranking's tail does not need them)
    quick: Dict[str, Suspect] = {}
    n_joint = min(JOINT_TOP, len(todo), screen or JOINT_TOP) if also and not joint else 0
    if screen > 0 and starts:
        with_start = [n for n in todo if starts.get(n)]
        for i, name in enumerate(with_start):
            if progress is not None:
                progress({"effect": f"{name} (screen)", "done": i, "total": len(with_start) + min(screen, len(todo)) + n_joint})
            evs[name] = _evidence(name, cmp, prob)
            quick[name] = _screen_fit(prob, name, evs[name], max_iter, starts[name])
        order = sorted(quick.values(), key=_rank_key)
        full = {q.effect for q in order[:screen]} | {q.effect for q in order if q.significant} | {n for n in todo if n not in quick}
        todo = [n for n in todo if n in full] + [n for n in todo if n not in full]
        done0 = len(with_start)
    else:
        full, done0 = set(todo), 0
    total = done0 + len(full) + n_joint
    for i, name in enumerate(n for n in todo if n in full):
        if progress is not None:
            progress({"effect": name, "done": done0 + i, "total": total})
        evs.setdefault(name, _evidence(name, cmp, prob))
        suspects.append(_try_effect(prob, name, evs[name], max_iter, also if joint and also else None, (starts or {}).get(name)))
    for name in todo:
        if name not in full:
            q = quick[name]
            q.message = "; ".join(x for x in (q.message, f"screened from its fit of the round before only (not among the {screen} best of the screen)") if x)
            suspects.append(q)
    suspects.sort(key=_rank_key)
    if also:
        for i, s in enumerate(suspects[:n_joint]):
            if progress is not None:
                progress({"effect": f"{s.effect} (joint refit)", "done": done0 + len(full) + i, "total": total})
            if s.tested and math.isfinite(s.score):
                suspects[i] = _refit_jointly(prob, s, evs[s.effect], max_iter, also, (starts or {}).get(s.effect))
        suspects.sort(key=_rank_key)
    if floor and todo:
        why = (f"not significant: the model is at its floor (systematic error {prob.floor_error(per0):.3g} above the noise "
               f"and the encoder's replay error, every channel within {FLOOR_MULTIPLE:g}× of it)")
        for s in suspects:
            if s.significant:
                s.significant = False
                s.message = why + ("; " + s.message if s.message else "")
        suspects.sort(key=_rank_key)
    white = bool(cmp.whiteness["is_white"].all())
    d = Diagnosis(
        suspects=suspects,
        nominal_error=e0,
        channel_error=per0,
        comparison=cmp,
        residual_white=white,
        conclusion="",
        run=str(run.source),
        seconds=0.0,
        n_rollouts=prob.nfev - n_start,
        noise=prob.noise,
        at_floor=prob.at_floor,
        problem=prob,
        encoder_floor=prob.encoder_floor,
        floor_error=prob.floor_error(per0),
        model_at_floor=floor,
    )
    d.conclusion = _round_conclusion(d)
    d.seconds = time.perf_counter() - t_start
    return d


def _round_conclusion(d: Diagnosis) -> str:
    b = d.best
    parts = []
    if b is not None:
        parts.append(
            f"{b.effect}{f' ({b.variant})' if b.variant else ''} explains the most: adding it is predicted to take the systematic error from "
            f"{b.error_before:.3g} to {b.error_after:.3g} noise units ({100 * b.explained:.0f} % of it; held out {b.validation_before:.3g} → {b.validation_after:.3g})"
        )
    elif d.nominal_error <= AT_FLOOR:
        parts.append(f"at the noise floor (systematic error {d.nominal_error:.3g} noise units): no library effect is significant")
    elif d.model_at_floor:
        parts.append(f"at its floor, the noise and the encoder's resolution (systematic error {d.nominal_error:.3g} noise units, "
                     f"{d.floor_error:.3g} above the floor; {_encoder_text(d.encoder_floor)}): no library effect is significant")
    else:
        parts.append(f"no library effect explains the systematic error of {d.nominal_error:.3g} noise units: it is not explained by the library ({_where(d)})")
    if d.untested and not d.model_at_floor:
        parts.append("the ranking is incomplete: " + "; ".join(f"{s.effect} {s.message}" for s in d.untested))
    return "; ".join(parts)


def _where(d: Diagnosis, per: Optional[Dict[str, float]] = None) -> str:
    """Where the unexplained error sits: channels, time window, frequency band."""
    per = d.channel_error if per is None else per
    worst = sorted(per.items(), key=lambda kv: -kv[1])[:3]
    txt = "worst channels " + ", ".join(f"{c} {v:.2g}× noise" for c, v in worst)
    cmp = d.comparison
    try:
        w = cmp.windows.sort_values("rank").iloc[0]
        txt += f"; worst window t = {float(w['t_start']):.3g}–{float(w['t_end']):.3g} s ({100 * float(w['error_share']):.0f} % of the error)"
        c0 = worst[0][0]
        sp = cmp.spectrum.loc[c0]
        if str(sp["dominant_band"]):
            txt += f"; {c0}'s residual mostly in {sp['dominant_band']} (peak {float(sp['peak_hz']):.3g} Hz)"
    except Exception:  # noqa: BLE001 - a missing view must not hide the finding
        pass
    prob = d.problem
    if prob is not None:
        try:
            sp = prob.spikes(prob.residuals(prob.nominal_simulation()))
        except Exception:  # noqa: BLE001
            sp = {}
        big = sorted(((c, v) for c, v in sp.items() if v["share"] >= SPIKE_SHARE and per.get(c, 0.0) > FLOOR_MULTIPLE), key=lambda kv: -kv[1]["share"])
        if big:
            txt += "; isolated spikes (sensor glitches, or an effect sharper than a sample): " + ", ".join(
                f"{c} {v['count']} sample(s) > {SPIKE_SIGMA:g}σ from their neighbours (first at t = {v['times'][0]:.4g} s), "
                f"{100 * v['share']:.0f} % of its excess" for c, v in big[:3])
    return txt


# ---------------------------------------------------------------------------- the loop


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
    progress: Optional[Progress] = None,
    rank_at_floor: bool = False,
) -> History:
    """The loop: diagnose, add the top significant effect, refit every added effect
    jointly, diagnose again; until no effect is significant or ``max_rounds``.

    Nothing is lost: a failure in round k returns rounds 1..k−1 with ``History.error``
    set. Errors in the set-up (a run the model cannot replay at all) are raised.
    ``rank_at_floor``: as :func:`diagnose`, for a model at its floor from the start."""
    t_start = time.perf_counter()
    for n in effects or []:
        fx.normalize(n, {})  # bad input is refused before any work
    if int(max_rounds) < 0:
        raise InputError(f"input max_rounds: {max_rounds} must be ≥ 0")
    est.check_max_iter(max_iter)
    prob = fit_unseen_motion(ReplayProblem(model, run, channels=channels, sample_rate=sample_rate, threads=threads))
    steps = [_step(prob, [], {}, 0)]
    noise0 = prob.noise
    diags: List[Diagnosis] = []
    added: List[str] = []
    fitted_params: Dict[str, List[str]] = {}
    swap_tried: Dict[str, Set[str]] = {}
    notes: List[str] = []  # what the swap and base-law steps tried and why, the floors re-estimated
    current, cprob = model, prob
    error = ""
    rnd = 0

    stage, stage_round = "", 0  # what a fit of a swap or base-law step is for, and its round

    def prog(info: Dict[str, Any]) -> None:
        if progress is not None:
            progress(dict(info, round=stage_round if stage else rnd + 1, effect=f"{stage}{info.get('effect', '')}"))

    try:
        d = diagnose(current, run, effects=effects, threads=threads, max_iter=max_iter, problem=cprob, progress=prog, rank_at_floor=rank_at_floor)
        diags.append(d)
        while rnd < max_rounds:
            reset = ""
            if d.best is not None:
                rnd += 1
                s = d.best
                added.append(s.effect)
                fitted_params[s.effect] = list(s.fitted)
                cand = s.apply(current)
                cprob = prob.with_model(cand)
                if progress is not None:
                    progress({"round": rnd, "effect": "refit " + " + ".join(added), "done": 0, "total": 1})
                current, cprob, ci = _refit_stable(cprob, added, fitted_params, max_iter)
                cprob = fit_unseen_motion(cprob)  # the torques changed with the model
            else:
                # nothing significant is left, but the model is not at its floor: a richer
                # law chosen for an earlier effect may be standing in for a missing effect
                # (a payload's centre-of-mass offset for a torsion); each is tried back at
                # its base law with the best candidate added
                lw = None
                if added and not _at_floor(steps[-1], prob):
                    for e in list(added):
                        # first the candidates significant in some round (screened from their
                        # fits); then the rest of the library, each fitted from its seeds: an
                        # effect whose error the extras took may show only beside the base law
                        # (a soft torsion with a payload: each alone replays worse than neither,
                        # MuJoCo pair, benchmarks/README.md session 23)
                        sig = [c for c in _significant_in(diags) if c not in added and (effects is None or c in effects)]
                        rest = [c for c in (fx.EFFECT_NAMES if effects is None else effects) if c not in added and c not in sig]
                        stage, stage_round = f"{e} at its base law: ", rnd + 1
                        lw = _try_base_law(prob, run, cprob, e, added, fitted_params, sig, diags, threads, max_iter, prog, notes, more=rest)
                        stage = ""
                        if lw is not None:
                            reset = e
                            break
                if lw is None:
                    break
                rnd += 1
                c, current, cprob, ci, fitted_params, d_law = lw
                added.append(c)
                diags.append(d_law)
            steps.append(_step(cprob, added, ci, rnd, law_reset=reset))
            prob, cprob, steps = _floors_update(prob, cprob, steps, notes, rnd)
            # backward and swap steps, around the newest effect (the one just added, or
            # just swapped in: the others are then all "earlier" than it), until no swap
            # is kept
            newest = added[-1]
            while True:
                # backward step: an effect added earlier that the refitted model no longer
                # needs (it stood in for the newest) is removed
                for e in [x for x in added if x != newest]:
                    if not _still_needed(cprob, e, fitted_params[e]):
                        added.remove(e)
                        fitted_params.pop(e)
                        current, cprob, ci = _refit_stable(cprob.with_model(current.without_effect(e)), added, fitted_params, max_iter)
                        cprob = fit_unseen_motion(cprob)
                        steps.append(_step(cprob, added, ci, rnd, removed=e))
                        prob, cprob, steps = _floors_update(prob, cprob, steps, notes, rnd)
                # swap step: an effect added earlier may have stood in for two (the greedy
                # first round picks one effect for the error of both); it is tried replaced
                # by the best candidate for the model without it, kept when the likelihood
                # prefers it. After a swap the effect added this round is "earlier" too (a
                # stand-in picked beside the old stand-in: wrinkling beside a backlash that
                # stood in for drag, a payload missing)
                swapped = False
                for e in [x for x in added if x != newest]:
                    if _at_floor(steps[-1], prob):
                        break
                    # only candidates some round found significant: one that e stood in for
                    # explained much of the same error when e was chosen; each pair once
                    pool = [c for c in _significant_in(diags) if c not in added and (effects is None or c in effects) and c not in swap_tried.get(e, set())]
                    if not pool:
                        continue
                    swap_tried.setdefault(e, set()).update(pool)
                    stage, stage_round = f"swap out {e}: ", rnd  # part of the round just done
                    sw = _try_swap(prob, run, cprob, e, added, fitted_params, pool, diags, threads, max_iter, prog, notes)
                    stage = ""
                    if sw is None:
                        continue
                    c, current, cprob, ci, fitted_params = sw
                    added[added.index(e)] = c
                    steps.append(_step(cprob, added, ci, rnd, removed=e, swapped_in=c))
                    prob, cprob, steps = _floors_update(prob, cprob, steps, notes, rnd)
                    newest, swapped = c, True
                    break
                if not swapped:
                    break
            remaining = [e for e in (effects or fx.EFFECT_NAMES) if e not in added]
            if not remaining or _at_floor(steps[-1], prob):
                break
            # from the third round on, a cheap screen from each candidate's last fit picks
            # the few that get the full multi-start fit (pairs are found by round 2)
            d = diagnose(current, run, effects=remaining, threads=threads, max_iter=max_iter, problem=cprob, progress=prog, refit=fitted_params,
                         starts=_prior_fits(diags), screen=JOINT_TOP if len(added) >= 2 else 0)
            diags.append(d)
    except KeyboardInterrupt:
        raise
    except Exception as e:  # noqa: BLE001 - nothing lost: the rounds before are returned
        error = f"round {rnd + 1} failed: {type(e).__name__}: {e}"
    h = History(steps, diags, "", run=str(run.source), seconds=0.0, error=error, noise=prob.noise, notes=notes, noise_initial=noise0,
                problem=prob)
    h.conclusion = _conclude(h, max_rounds, prob)
    h.seconds = time.perf_counter() - t_start
    return h


#: A channel's noise floor estimated from a refitted model's residual replaces the one the
#: loop used when it differs by more than this factor, either way (the estimator's own
#: scatter is a few %).
NOISE_RECHECK = 1.2


def _noise_recheck(cprob: ReplayProblem) -> Dict[str, float]:
    """The channels whose noise floor re-estimated from the residual of the model of
    ``cprob`` (:meth:`ReplayProblem.noise_from`) differs from the one used by more than
    :data:`NOISE_RECHECK` either way: channel → new/old. A large misfit biases the
    estimator (up by the residual's own rough part, or down where it hides a coloured
    noise: neighbouring samples alike under a sensor's low-pass; on MuJoCo-like runs by
    0.77-4×), so a better model's residual gives the floor back."""
    try:
        new = cprob.noise_from()
    except Exception:  # noqa: BLE001 - a check, not a result
        return {}
    old = cprob.noise
    ratio = {c: new[c] / old[c] for c in old if old[c] > 0 and math.isfinite(new.get(c, math.nan)) and new[c] > 0}
    return {c: r for c, r in ratio.items() if r > NOISE_RECHECK or r < 1.0 / NOISE_RECHECK}


def _floors_update(prob: ReplayProblem, cprob: ReplayProblem, steps: List[HistoryStep], notes: List[str],
                   rnd: int) -> Tuple[ReplayProblem, ReplayProblem, List[HistoryStep]]:
    """The loop's floors estimated again on the model of ``cprob`` (the last step's: an
    effect added, removed or swapped in): the noise floors (:func:`_noise_update`), then
    the encoder floor in them (:func:`_encoder_update`). Later rounds, the floor stop and
    the conclusion then use them."""
    prob, cprob, steps = _noise_update(prob, cprob, steps, notes, rnd)
    prob, cprob = _encoder_update(prob, cprob, steps[-1].effects, notes, rnd)
    return prob, cprob, steps


def _noise_update(prob: ReplayProblem, cprob: ReplayProblem, steps: List[HistoryStep], notes: List[str],
                  rnd: int) -> Tuple[ReplayProblem, ReplayProblem, List[HistoryStep]]:
    """The loop's noise floors re-estimated on the model of ``cprob``: where a channel's
    differs by more than :data:`NOISE_RECHECK` (:func:`_noise_recheck`), the base problem
    ``prob`` and ``cprob`` take the new floors, every step so far is put in them (one
    scale, so the fall of the error stays comparable) and a line goes to ``notes``."""
    off = _noise_recheck(cprob)
    if not off:
        return prob, cprob, steps
    last = steps[-1]
    try:
        new = {c: cprob.noise[c] * r for c, r in off.items()}
        out = prob.with_noise(new), cprob.with_noise(new), [st.in_floors(off) for st in steps]
    except Exception as ex:  # noqa: BLE001 - a check: the loop goes on in the floors it had
        notes.append(f"round {rnd}: re-estimating the noise floors failed ({type(ex).__name__}: {ex}); the floors used stand")
        return prob, cprob, steps
    txt = ", ".join(f"{c} {r:.2g}×" for c, r in sorted(off.items(), key=lambda kv: -abs(math.log(kv[1]))))
    notes.append(f"round {rnd}: the noise floors re-estimated from the residual of the model with {' + '.join(last.effects) or 'nothing'} "
                 f"differ from those used (a larger misfit biases the estimator: up, or down where it hides a coloured noise): {txt}; "
                 f"every step is now in the new floors (that model's systematic error {last.error:.3g} → {out[2][-1].error:.3g} noise units)")
    return out


#: A change of a channel's encoder floor (as a multiple of its noise) by more than this
#: factor, either way, is noted when the loop bootstraps it again on a refitted model.
ENCODER_NOTE = 1.1


def _encoder_update(prob: ReplayProblem, cprob: ReplayProblem, effects: Sequence[str], notes: List[str],
                    rnd: int) -> Tuple[ReplayProblem, ReplayProblem]:
    """The loop's encoder floor bootstrapped again on the model of ``cprob`` (the last
    step's): the replay error an encoder causes depends on the model (a gear with play
    hits its flanks when the replayed motor angle says, so a 12-bit encoder at 200 Hz that
    leaves the nominal model at 1.3 × its noise leaves the true backlash 20-60 ×; a
    friction law's sign flips with the smoothed velocity). ``prob`` and ``cprob`` take it:
    the floor stop and the conclusion judge the newest model against its own floor. A
    change above :data:`ENCODER_NOTE` goes to ``notes``; a failure keeps the floor used."""
    old = cprob.encoder_floor
    try:
        e = cprob.encoder_bootstrap()
        prob, cprob = prob.with_encoder_sigma(e), cprob.with_encoder_sigma(e)
    except Exception as ex:  # noqa: BLE001 - a check: the loop goes on in the floor it had
        notes.append(f"round {rnd}: bootstrapping the encoder floor again failed ({type(ex).__name__}: {ex}); the floor used stands")
        return prob, cprob
    new = cprob.encoder_floor
    moved = {c: new[c] / old[c] for c in new if old.get(c, 0) > 0 and not 1 / ENCODER_NOTE <= new[c] / old[c] <= ENCODER_NOTE}
    if moved:
        txt = ", ".join(f"{c} {old[c]:.3g} → {new[c]:.3g}" for c in sorted(moved, key=lambda c: -abs(math.log(moved[c])))[:4])
        notes.append(f"round {rnd}: the encoder floor bootstrapped again on the model with {' + '.join(effects) or 'nothing'} "
                     f"(the replay error the encoder's own error causes, × each channel's noise): {txt}")
    return prob, cprob


def _n_params(fitted: Mapping[str, Sequence[str]], flat: np.ndarray) -> int:
    """The number of fitted parameter entries of the effects ``fitted`` ({effect: names})
    in the model of effect vector ``flat`` (entries its structure leaves out not counted)."""
    return sum(1 for e, ps in fitted.items() for pi in est.free_params(e, list(ps) or None) if not _left_out(flat, *pi))


def _beats(new: ReplayProblem, fitted_new: Mapping[str, Sequence[str]], cur: ReplayProblem, fitted_cur: Mapping[str, Sequence[str]]) -> Tuple[bool, str]:
    """Whether the model of ``new`` beats the (non-nested) model of ``cur`` on the same run:
    its BIC gain (likelihood ratio on the training samples less ln n_eff per extra fitted
    parameter) passes the significance threshold, and it lowers the held-out error too; and
    the numbers, as text."""
    z_new = new.residuals(new.nominal_simulation())
    z_cur = cur.residuals(cur.nominal_simulation())
    if z_new.shape != z_cur.shape:
        return False, "not comparable (different output grids)"
    lr, ne = est.log_ratio(cur, z_cur, z_new, cur.train)
    gain = lr - (_n_params(fitted_new, new.model.effects_flat) - _n_params(fitted_cur, cur.model.effects_flat)) * math.log(ne)
    v_new, v_cur = new.error(mask=new.validation)[0], cur.error(mask=cur.validation)[0]
    ok = bool(gain > SCORE_THRESHOLD and v_new < v_cur)
    return ok, f"BIC gain {gain:.1f} (threshold {SCORE_THRESHOLD:g}), held-out error {v_cur:.3g} → {v_new:.3g}"


def _try_swap(prob: ReplayProblem, run: MeasuredRun, cprob: ReplayProblem, effect: str, added: List[str], fitted: Dict[str, List[str]],
              effects: Optional[Sequence[str]], diags: Sequence[Diagnosis], threads: int, max_iter: int,
              progress: Optional[Progress], log: Optional[List[str]] = None) -> Optional[Tuple[str, "Model", ReplayProblem, Dict[str, Dict[str, List[float]]], Dict[str, List[str]]]]:
    """Whether ``effect`` (added earlier) is better replaced by another candidate: the
    model of ``cprob`` without it is diagnosed (the other added effects refitted with each
    candidate), its best significant candidate put in its place and every added effect
    refitted; the swap is returned (the new effect, model, problem, intervals and fitted
    names) when it beats the current model by the significance threshold in BIC (likelihood
    ratio less ln n_eff per extra parameter, the effects being non-nested) and lowers the
    held-out error too; else ``None``. A failure keeps the current model. ``log``: a line
    saying what was tried and why it was (not) kept is appended."""
    others = [e for e in added if e != effect]
    pool = [e for e in (effects or fx.EFFECT_NAMES) if e not in added]
    if not others or not pool:
        return None
    what = f"swap of {effect} (candidates {', '.join(pool)})"
    try:
        # the others refitted without it first: fitted beside a stand-in they are biased
        # (a payload fitted beside a backlash standing in for drag was 0.69 × the truth)
        _, bprob, _ = _refit_stable(prob.with_model(cprob.model.without_effect(effect)), others, {e: fitted[e] for e in others}, max_iter)
        bprob = fit_unseen_motion(bprob)
    except KeyboardInterrupt:
        raise
    except Exception as ex:  # noqa: BLE001 - the current model stands
        _note(log, f"{what}: failed refitting {', '.join(others)} without it ({type(ex).__name__}: {ex}); the model stands")
        return None
    best = _best_added(prob, run, bprob, others, {e: list(fitted[e]) for e in others}, pool, diags, threads, max_iter, progress, cprob, fitted,
                       log=log, what=what)
    if best is None:
        return None
    c, m2, p2, ci2, nf, _ = best
    order = [c if e == effect else e for e in added]
    return c, m2, p2, ci2, {e: nf[e] for e in order}


def _best_added(prob: ReplayProblem, run: MeasuredRun, base: ReplayProblem, kept: List[str], fitted: Dict[str, List[str]], pool: List[str],
                diags: Sequence[Diagnosis], threads: int, max_iter: int,
                progress: Optional[Progress], cur: ReplayProblem,
                fitted_cur: Mapping[str, Sequence[str]], log: Optional[List[str]] = None, what: str = "",
                joint: bool = False) -> Optional[Tuple[str, "Model", ReplayProblem, Dict[str, Dict[str, List[float]]], Dict[str, List[str]], Diagnosis]]:
    """The model of ``base`` with the best significant candidate among ``pool`` added (the
    candidates diagnosed with the effects ``kept``, fitted names ``fitted``, refitted with
    each; the best added and everything refitted jointly), if it beats the current model
    ``cur`` (:func:`_beats`). Returns (its name, the model, its problem with its own unseen
    motion, intervals, fitted names, the diagnosis), or ``None``: no candidate significant,
    the current model better, or a failure (the current model stands). ``log``: a line
    saying what (``what``) was tried and why it was (not) kept is appended. ``joint``: as
    :func:`diagnose`'s (every candidate fitted jointly with ``kept`` from its seeds)."""
    what = what or "candidates " + ", ".join(pool)
    try:
        # only the best candidate is taken: the cheap screen picks the one that gets the full fit
        d = diagnose(base.model, run, effects=pool, threads=threads, max_iter=max_iter, problem=base, progress=progress, refit=fitted,
                     starts=_prior_fits(diags), screen=1, joint=joint)
        s = d.best
        if s is None:
            _note(log, f"{what}: no candidate significant; the model stands")
            return None
        nf = dict(fitted)
        nf[s.effect] = list(s.fitted)
        m2, p2, ci2 = _refit_stable(prob.with_model(s.apply(base.model)), list(kept) + [s.effect], nf, max_iter)
        p2 = fit_unseen_motion(p2)
        ok, why = _beats(p2, nf, cur, fitted_cur)
        _note(log, f"{what}: {s.effect} {'kept' if ok else 'not kept'} ({why})")
        if not ok:
            return None
    except KeyboardInterrupt:
        raise
    except Exception as ex:  # noqa: BLE001 - the current model stands
        _note(log, f"{what}: failed ({type(ex).__name__}: {ex}); the model stands")
        return None
    return s.effect, m2, p2, ci2, nf, d


def _systematic_of(per: Mapping[str, float]) -> float:
    """S (:data:`ERROR_DEFINITION`) of the noise multiples ``per`` (channel → r_c)."""
    return systematic(np.square(np.array(list(per.values()), dtype=np.float64))) if per else math.nan


def _step(cprob: ReplayProblem, added: Sequence[str], ci: Dict[str, Dict[str, List[float]]], rnd: int, **kw: Any) -> HistoryStep:
    """A step of the loop: the model of ``cprob`` with the effects ``added``, its error on
    every sample and on the held-out ones, per channel and overall."""
    err, per = cprob.error()
    verr, vper = cprob.error(mask=cprob.validation)
    m = cprob.model
    return HistoryStep(list(added), {e: m.effects.get(e, {}) for e in added}, err, per, m, validation_error=verr, ci95=ci,
                       unseen_compliance=cprob.compliance.tolist(), round=rnd, validation_channel_error=vper, **kw)


def _note(log: Optional[List[str]], line: str) -> None:
    if log is not None:
        log.append(line)


def _extras(effect: str, names: Sequence[str]) -> List[str]:
    """The names among ``names`` that are not fitted by ``effect``'s base law (a richer
    variant's extra parameters)."""
    base = {p.name for p in fx.EFFECTS[effect].fit_params}
    return [k for k in names if k not in base]


def _try_base_law(prob: ReplayProblem, run: MeasuredRun, cprob: ReplayProblem, effect: str, added: List[str], fitted: Dict[str, List[str]],
                  effects: Optional[Sequence[str]], diags: Sequence[Diagnosis], threads: int, max_iter: int,
                  progress: Optional[Progress], log: Optional[List[str]] = None,
                  more: Sequence[str] = ()) -> Optional[Tuple[str, "Model", ReplayProblem, Dict[str, Dict[str, List[float]]], Dict[str, List[str]], Diagnosis]]:
    """Whether ``effect``, added with a richer variant's extra parameters, is better back at
    its base law (the extras neutral) with another effect added: the added effects are
    refitted with ``effect`` at its base law, that model is diagnosed, and its best
    significant candidate added and refitted with them. Returned (the new effect, model,
    problem, intervals, fitted names and the diagnosis) when it beats the current model by
    the significance threshold in BIC and lowers the held-out error too; else ``None``.
    The candidates ``effects`` are screened from their fits in ``diags``; if none is kept,
    the candidates ``more`` are tried, each fitted jointly with the added effects from its
    seeds (their error was taken by the extras, and the effect's base-law value refitted
    without them is off: a torsion fitted with that payload held finds nothing)."""
    extras = _extras(effect, fitted.get(effect, []))
    pool = [e for e in (fx.EFFECT_NAMES if effects is None else effects) if e not in added]
    more = [e for e in more if e not in added and e not in pool]
    if not extras or not (pool or more):
        return None
    what = f"{effect} back at its base law ({', '.join(extras)} neutral; candidates {', '.join(pool or more)})"
    try:
        params = dict(cprob.model.effects.get(effect, {}))
        params.update({k: [fx.EFFECTS[effect].params[k].neutral] * fx.EFFECTS[effect].params[k].length for k in extras})
        nf = {e: (list(fitted[e]) if e != effect else [k for k in fitted[e] if k not in extras]) for e in added}
        _, pb, _ = _refit_stable(prob.with_model(cprob.model.with_effects({effect: params})), added, nf, max_iter)
        pb = fit_unseen_motion(pb)
        z_b, z_c = pb.residuals(pb.nominal_simulation()), cprob.residuals(cprob.nominal_simulation())
        if z_b.shape == z_c.shape and est.log_ratio(cprob, z_b, z_c, cprob.train)[0] < SCORE_THRESHOLD:
            # the extras explain nothing: the round just done already diagnosed this model
            _note(log, f"{what}: not tried, the extras explain nothing (likelihood ratio below {SCORE_THRESHOLD:g})")
            return None
    except KeyboardInterrupt:
        raise
    except Exception as ex:  # noqa: BLE001 - the current model stands
        _note(log, f"{what}: failed refitting at the base law ({type(ex).__name__}: {ex}); the model stands")
        return None
    out = _best_added(prob, run, pb, added, nf, pool, diags, threads, max_iter, progress, cprob, fitted, log=log, what=what) if pool else None
    if out is None and more:
        what = f"{effect} back at its base law ({', '.join(extras)} neutral; candidates {', '.join(more)}, each fitted with {', '.join(added)} from its seeds)"
        out = _best_added(prob, run, pb, added, nf, more, [], threads, max_iter, progress, cprob, fitted, log=log, what=what, joint=True)
    return out


def _significant_in(diags: Sequence[Diagnosis]) -> List[str]:
    """The effects significant in any of the diagnoses ``diags``, in order of first sight."""
    out: List[str] = []
    for d in diags:
        for s in d.suspects:
            if s.significant and s.effect not in out:
                out.append(s.effect)
    return out


def _prior_fits(diags: Sequence[Diagnosis]) -> Dict[str, Dict[str, List[float]]]:
    """Each effect's most recent tested fit over the rounds ``diags`` (its fitted
    parameters only), offered as one more start in the next round."""
    out: Dict[str, Dict[str, List[float]]] = {}
    for d in diags:
        for s in d.suspects:
            if s.tested and math.isfinite(s.score) and s.fitted:
                out[s.effect] = {k: list(s.params[k]) for k in s.fitted if k in s.params}
    return out


def _model_at_floor(prob: ReplayProblem, error: float, per: Mapping[str, float]) -> bool:
    """Whether a model with systematic error ``error`` and noise multiples ``per`` is at its
    floor: at most :data:`AT_FLOOR` above the noise and the encoder's replay error
    (:meth:`ReplayProblem.floor_error`), and every channel within :data:`FLOOR_MULTIPLE` of
    that floor. Nothing is added then: what is left is below what the run resolves."""
    fm = [v for v in prob.floor_multiples(dict(per)).values() if math.isfinite(v)]
    if not fm:
        return False
    s = error if error <= AT_FLOOR else prob.floor_error(dict(per))
    return bool(s <= AT_FLOOR and max(fm) <= FLOOR_MULTIPLE)


def _at_floor(st: HistoryStep, prob: ReplayProblem) -> bool:
    """:func:`_model_at_floor` of a step of the loop."""
    return _model_at_floor(prob, st.error, st.channel_error)


def _encoder_text(ef: Mapping[str, float]) -> str:
    big = sorted(((c, v) for c, v in ef.items() if v > 1.05), key=lambda kv: -kv[1])[:3]
    if not big:
        return "the encoder adds nothing above the noise"
    return "the encoder's error alone replays at " + ", ".join(f"{v:.2g}× noise on {c}" for c, v in big)


def _still_needed(prob: ReplayProblem, effect: str, params: Sequence[str]) -> bool:
    """Whether the model of ``prob`` needs ``effect``, by the rules that would have added it:
    a play narrower than the encoder resolves (:func:`_unresolved_play`) is not needed; nor
    is an effect without which the model is at its floor (:func:`_model_at_floor`, with its
    own unseen motion); otherwise the likelihood ratio of the model with it against the
    model without it (its parameters neutral, nothing refitted, so the test keeps an
    effect when in doubt) must pass the significance threshold."""
    if _unresolved_play(prob, effect, prob.model.effects_flat):
        return False
    try:
        without = fit_unseen_motion(prob.with_model(prob.model.without_effect(effect)))
        z_wo = without.residuals(without.nominal_simulation())
        e_wo, per_wo = without.error(z_wo)
    except Exception:  # noqa: BLE001 - if it cannot be removed, keep it
        return True
    if _model_at_floor(without, e_wo, per_wo):
        return False
    z = prob.residuals(prob.nominal_simulation())
    lr, neff = est.log_ratio(prob, z_wo, z, prob.train)
    k = len(est.free_params(effect, list(params) or None))
    return lr - k * math.log(neff) > SCORE_THRESHOLD


#: Halvings of the step tried when a refitted model fails the step check.
_STEP_HALVINGS = 3


def _refit_stable(prob: ReplayProblem, added: List[str], fitted: Dict[str, List[str]], max_iter: int) -> Tuple["Model", ReplayProblem, Dict[str, Dict[str, List[float]]]]:
    """:func:`_refit`, at half the step (up to :data:`_STEP_HALVINGS` times) when the
    refitted model leaves the step's stability region (a stiffness the joint refit moved
    beyond what the candidate's step was chosen for, or a pose where a mode is faster)."""
    for k in range(_STEP_HALVINGS + 1):
        try:
            out = _refit(prob, added, fitted, max_iter)
            out[1].error()  # the refitted model runs at this step
            return out
        except StepTooLargeError:
            if k == _STEP_HALVINGS:
                raise
            prob = prob.with_model(prob.model.with_dt(0.5 * prob.model.dt))
    raise AssertionError("unreachable")


def _refit(prob: ReplayProblem, added: List[str], fitted: Dict[str, List[str]], max_iter: int) -> Tuple["Model", ReplayProblem, Dict[str, Dict[str, List[float]]]]:
    """Refit every fitted parameter of the added effects jointly, from their current values."""
    model = prob.model
    flat = model.effects_flat
    free = [pi for e in added for pi in est.free_params(e, fitted.get(e) or None) if not _left_out(flat, *pi)]
    x0 = np.array([flat[p.offset + i] for p, i in free])
    out = est.fit(prob, flat, free, x0, max([max_iter] + [_MIN_ITER.get(e, 0) for e in added]))
    new = model.with_effects({e: est.params_dict(e, out.flat) for e in added})
    nprob = prob.with_model(new)
    _, ne = est.log_ratio(prob, out.z, out.z, prob.train)
    half, _ = est.uncertainty(out, free, [f"{p.effect}.{p.name}[{i}]" for p, i in free], ne)
    ci: Dict[str, Dict[str, List[float]]] = {}
    for (p, i), h in zip(free, half):
        ci.setdefault(p.effect, {}).setdefault(p.name, [math.nan] * p.length)[i] = float(h)
    return new, nprob, ci


def _conclude(h: History, max_rounds: int, prob: Optional[ReplayProblem] = None) -> str:
    """The whole history in words: what was added (value, interval, the fall of the error
    overall and on the channels it acts on), then what is left; ``prob``: the run's problem
    in the floors the steps are in (default: the first diagnosis's), and where the loop
    re-estimated them (:func:`_floors_update`) the conclusion says so."""
    parts: List[str] = []
    for i in range(1, len(h.steps)):
        prev, st = h.steps[i - 1], h.steps[i]
        if st.removed and st.swapped_in:
            e = st.swapped_in
            ptxt = _fmt_params({k: v for k, v in st.params.get(e, {}).items() if k in st.ci95.get(e, {})}, st.ci95.get(e, {})) or _fmt_params(st.params.get(e, {}), {})
            parts.append(f"replaced {st.removed} by {e} ({ptxt}): {st.removed} stood in for it; the error "
                         f"{'fell' if st.error < prev.error else 'went'} from {prev.error:.3g} to {st.error:.3g} noise units")
            continue
        if st.removed:
            parts.append(f"removed {st.removed} again (with {', '.join(st.effects)} refitted it explains nothing more; error {prev.error:.3g} → {st.error:.3g})")
            continue
        e = st.effects[-1]
        vals = st.params.get(e, {})
        ci = st.ci95.get(e, {})
        ptxt = _fmt_params({k: v for k, v in vals.items() if k in ci}, ci) or _fmt_params(vals, {})
        drop = 1.0 - st.error / prev.error if prev.error > 0 else 0.0
        moved = sorted(((c, prev.channel_error.get(c, math.nan), st.channel_error.get(c, math.nan)) for c in st.channel_error),
                       key=lambda x: -(x[1] - x[2]) if math.isfinite(x[1] - x[2]) else 0.0)[:3]
        ch = ", ".join(f"{c} {a:.2g}× → {b:.2g}× noise" for c, a, b in moved if a - b > 0.05 * a)
        reset = f", with {st.law_reset} back at its base law (its richer variant had stood in for {e})" if st.law_reset else ""
        fall = (f"the systematic error fell from {prev.error:.3g} to {st.error:.3g} noise units ({100 * drop:.0f} % less)" if st.error < prev.error
                else f"the systematic error went from {prev.error:.3g} to {st.error:.3g} noise units")
        parts.append(f"added {e} ({ptxt}){reset}: {fall}" + (f"; on {ch}" if ch else ""))
    last = h.steps[-1]
    d_last = h.diagnoses[-1] if h.diagnoses and h.diagnoses[-1].problem is not None and h.diagnoses[-1].problem.model is last.model else None
    n_added = sum(1 for st in h.steps[1:] if not st.removed)
    prob0 = prob if prob is not None else h.diagnoses[0].problem if h.diagnoses and h.diagnoses[0].problem is not None else None
    try:
        floor = prob0 is not None and _at_floor(last, prob0)
    except Exception:  # noqa: BLE001 - the words still go out: not shown to be at the floor
        floor = False
    if last.error <= AT_FLOOR or floor:
        if last.error <= AT_FLOOR:
            what = f"the noise floor (systematic error {last.error:.3g} noise units)"
        else:
            assert prob0 is not None
            what = (f"its floor, the noise and the encoder's resolution (systematic error {last.error:.3g} noise units, "
                    f"{prob0.floor_error(last.channel_error):.3g} above that floor; {_encoder_text(prob0.encoder_floor)})")
        left = f"what is left is at {what}"
        if parts and floor:
            left += f", every channel within {FLOOR_MULTIPLE:g}× its floor: nothing more was tried"
        if not parts:
            left = f"the model is at {what}: nothing significant is missing"
    else:
        where = _where(d_last, last.channel_error) if d_last is not None else ", ".join(f"{c} {v:.2g}× noise" for c, v in sorted(last.channel_error.items(), key=lambda kv: -kv[1])[:3])
        if d_last is not None and d_last.best is not None and n_added >= max_rounds:
            left = f"stopped after max_rounds = {max_rounds}; {d_last.best.effect} is still significant ({where})"
        else:
            left = f"a systematic error of {last.error:.3g} noise units is left that is not explained by the library ({where})"
    if any(c > 0 for c in last.unseen_compliance):
        left += (" (the replay includes the motor joints' motion inside one encoder reading, a servo compliance of "
                 + "/".join(f"{c:.2g}" for c in last.unseen_compliance) + " rad/(N·m) per joint: popup.unseen)")
    parts.append(left)
    untested = sorted({f"{s.effect} ({s.message})" for d in h.diagnoses if not d.model_at_floor for s in d.untested})
    if untested:
        parts.append("the ranking is incomplete: " + "; ".join(untested))
    floors_moved = {c: h.noise[c] / v for c, v in h.noise_initial.items() if v > 0 and c in h.noise and h.noise[c] != v}
    if floors_moved:
        txt = ", ".join(f"{c} {r:.2g}×" for c, r in sorted(floors_moved.items(), key=lambda kv: -abs(math.log(kv[1]))))
        parts.append(f"the history's errors are in noise floors re-estimated on a refitted model, the nominal residual's misfit having "
                     f"biased them ({txt} the first estimate)")
    if h.error:
        parts.append(f"incomplete: {h.error}; the rounds before it are kept")
    text = "; ".join(parts)
    return text[0].upper() + text[1:] + "."


# ---------------------------------------------------------------------------- progress


class TerminalProgress:
    """Progress of :func:`improve` on a terminal (stderr, one line rewritten): round,
    effect, fits done and an ETA from the mean time per fit so far."""

    def __init__(self, stream: Any = None) -> None:
        self.stream = sys.stderr if stream is None else stream
        self.t0 = time.perf_counter()
        self.fits = 0

    def __call__(self, info: Dict[str, Any]) -> None:
        self.fits += 1
        el = time.perf_counter() - self.t0
        left = max(int(info.get("total", 0)) - int(info.get("done", 0)), 0)
        eta = el / max(self.fits - 1, 1) * left if self.fits > 1 else math.nan
        eta_txt = f"ETA this round {eta:4.0f} s" if math.isfinite(eta) else "ETA …"
        line = f"popup diagnose: round {info.get('round', 1)}  {str(info.get('effect', '')):<32} {info.get('done', 0)}/{info.get('total', 0)} fits  {el:5.0f} s  {eta_txt}"
        self.stream.write("\r" + line[:118].ljust(118))
        self.stream.flush()

    def close(self) -> None:
        self.stream.write("\r" + " " * 118 + "\r")
        self.stream.flush()


# ---------------------------------------------------------------------------- CLI


def cli_main(argv: Sequence[str]) -> int:
    """``popup diagnose RUN [--json] [--report out.html] ...``: load the run, compare,
    rank every effect, add the significant ones in turn (refitting), print the suspects
    and the error fall (or one JSON object with ``--json``). Exit 0 when complete, 1 when a
    round failed (what finished is still printed and reported, with the error), 2 on bad
    input (the message names what was wrong)."""
    import argparse

    from .exceptions import PopupError
    from .io import read_run

    ap = argparse.ArgumentParser(prog="popup diagnose", description="Rank the library's effects by how much of the model's systematic error each explains, then add them in turn.")
    ap.add_argument("run", help="measured-run folder (experiment.toml + measurements.csv/parquet) or MCAP log")
    ap.add_argument("--json", action="store_true", help="print one JSON object (run, nominal_error, error_definition, noise, suspects, history, conclusion, ...)")
    ap.add_argument("--report", metavar="HTML", help="write the self-contained HTML report here")
    ap.add_argument("--max-rounds", type=int, default=4, help="most effects to add (default 4)")
    ap.add_argument("--effects", help="comma-separated effects to try (default: the whole library)")
    ap.add_argument("--channels", help="comma-separated channels to compare (default: every comparable one)")
    ap.add_argument("--threads", type=int, default=0, help="rollout threads (0 = all cores)")
    ap.add_argument("--rank-at-floor", action="store_true",
                    help="fit and rank every effect even when the model is at its floor (noise and encoder); by default they are not tried")
    ap.add_argument("--no-progress", action="store_true", help="no progress line on stderr (it is off anyway with --json or when stderr is not a terminal)")
    a = ap.parse_args(list(argv))
    show = not a.json and not a.no_progress and sys.stderr.isatty()
    bar = TerminalProgress() if show else None
    try:
        run = read_run(a.run)
        model = run.model()
        effects = [e.strip() for e in a.effects.split(",")] if a.effects else None
        channels = [c.strip() for c in a.channels.split(",")] if a.channels else None
        h = improve(model, run, max_rounds=a.max_rounds, effects=effects, channels=channels, threads=a.threads, progress=bar,
                    rank_at_floor=a.rank_at_floor)
    except (PopupError, FileNotFoundError, NotADirectoryError) as e:
        if bar is not None:
            bar.close()
        print(f"popup diagnose: error: {e}", file=sys.stderr)
        return 2
    if bar is not None:
        bar.close()
    h.run = a.run
    for d in h.diagnoses:
        d.run = a.run
    rc = 0 if h.complete else 1
    if a.report:
        from .report import write_html

        try:
            write_html(h, a.report, title=f"popup diagnose {a.run}")
        except Exception as e:  # noqa: BLE001 - the numbers still go out
            print(f"popup diagnose: error: could not write the report {a.report}: {type(e).__name__}: {e}", file=sys.stderr)
            rc = 1
    if a.json:
        print(json.dumps(h.to_dict(), allow_nan=False))
        return rc
    print(f"run: {a.run}")
    print(f"error: {ERROR_DEFINITION}")
    print(f"nominal error: {h.steps[0].error:.4g} noise units")
    floor = h.at_floor
    print("channels (noise σ, nominal → final noise multiple):")
    for c, v in h.steps[0].channel_error.items():
        print(f"  {c:<9} σ = {h.noise.get(c, math.nan):<10.3g} {v:8.3g}× → {h.steps[-1].channel_error.get(c, math.nan):.3g}×{'  (signal at the noise floor)' if c in floor else ''}")
    if h.diagnoses:
        d0 = h.diagnoses[0]
        print()
        if h.noise_initial and h.noise_initial != h.noise:
            print(f"first round (in the floors first estimated, nominal error {d0.nominal_error:.4g} in them; popup.History.noise_initial):")
        print(f"{'rank':>4}  {'effect':<22}{'sig':<5}{'score':>10}{'error after':>13}{'explained':>10}  parameters")
        for i, s in enumerate(d0.suspects, 1):
            score = f"{s.score:.1f}" if math.isfinite(s.score) else "n/a"
            params = s.params_text() if s.tested else s.message
            after = f"{s.error_after:.4g}" if s.tested else "not tested"
            print(f"{i:>4}  {s.effect:<22}{'yes' if s.significant else 'no':<5}{score:>10}{after:>13}{100 * s.explained:>9.0f}%  {params}")
    print()
    print("error history (systematic error, noise units):")
    for st in h.steps:
        print(f"  {' + '.join(st.effects) or 'nominal':<40} {st.error:.4g}")
    print()
    print(h.conclusion)
    if h.error:
        print(f"popup diagnose: incomplete: {h.error}", file=sys.stderr)
    if a.report:
        print(f"report: {a.report}")
    return rc


# ---------------------------------------------------------------------------- evidence


def _evidence(effect: str, cmp: Comparison, prob: ReplayProblem) -> Dict[str, Any]:
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
            means = {c: float(np.nanmean(res[c])) / max(float(np.nanstd(prob.measured[:, prob.channels.index(c)])), 1e-300) for c in chans}
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
                y = prob.measured[:, prob.channels.index(c)]
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


def _rate(prob: ReplayProblem, j: int, t: np.ndarray) -> np.ndarray:
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


def _first_mode_hz(prob: ReplayProblem) -> float:
    try:
        modes = [float(x) for x in np.asarray(prob.model.locked_modes(list(prob.q_enc[0])), float) if x > 0]
        return min(modes) / (2 * math.pi) if modes else math.nan
    except Exception:  # noqa: BLE001
        return math.nan


