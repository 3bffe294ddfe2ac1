"""What the diagnosis returns: :class:`Suspect` (one effect fitted), :class:`Diagnosis` (one
round: every effect ranked) and :class:`History` (the loop: effects added in turn), with
``to_dict``, ``to_pandas`` and ``plot``."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from ..compare import Comparison
from ..problem import ERROR_DEFINITION, ReplayProblem, systematic
from .rules import model_at_floor

if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd

    from ..model import Model


def _pd() -> Any:
    import pandas as pd

    return pd


def final_problem(prob: ReplayProblem, step: "HistoryStep") -> ReplayProblem:
    """``prob`` (in its noise floors) with the model of ``step``."""
    return prob if step.model is None or step.model is prob.model else prob.with_model(step.model)


def _num(x: Any) -> Optional[float]:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


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
    unseen : tuple or None
        ``(compliance, q_corr)``: the unseen servo motion (:mod:`popup.unseen`) its own
        model gives, when it was refitted with it rather than the nominal model's
        (:func:`popup.diagnosis.candidate.refit_with_own_unseen`); the loop refits it on
        that replay. ``None``: the round's replay.
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
    unseen: Optional[Tuple[np.ndarray, np.ndarray]] = field(default=None, repr=False, compare=False)
    horizon: Optional[float] = None
    """Where it was judged on the samples before this time [s] only (the loop's horizon step)."""
    unpredictable_after: Optional[float] = None
    """Where a fit of its continuation replayed a play :data:`~popup.diagnosis.rules.PREDICT_REL`
    wider by more than :data:`~popup.diagnosis.rules.PREDICT_TOL` noise units past this time
    [s], within the run (:func:`popup.diagnosis.candidate.predictable_until`)."""

    @property
    def relative_drop(self) -> float:
        """1 − error_after/error_before."""
        if not (self.tested and self.error_before > 0 and math.isfinite(self.error_after)):
            return 0.0
        return 1.0 - self.error_after / self.error_before

    def params_text(self) -> str:
        """The fitted parameters with their 95 % half-widths, e.g. ``delta_kg=0.3006±0.00039``."""
        return fmt_params({k: v for k, v in self.params.items() if k in self.ci95}, self.ci95)

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
            "horizon_s": None if self.horizon is None else _num(self.horizon),
            "unpredictable_after_s": None if self.unpredictable_after is None else _num(self.unpredictable_after),
            "unseen_compliance": None if self.unseen is None else [_num(x) for x in self.unseen[0]],
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
    floor_error_upper : float
        The same above the floor with the encoder's part at its prediction bound
        (:attr:`ReplayProblem.encoder_sigma_upper`), the one ``model_at_floor`` judges.
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
    floor_error_upper: float = math.nan

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
                    "params": fmt_params(s.params, s.ci95) if s.tested else s.message,
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
            "floor_error_upper": _num(self.floor_error_upper),
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


def fmt_params(p: Mapping[str, Sequence[float]], ci: Mapping[str, Sequence[float]]) -> str:
    out = []
    for k, v in p.items():
        c = ci.get(k)
        if c is None:
            out.append(f"{k}={fmt_list(v)}")
        else:
            out.append(f"{k}={'/'.join(f'{x:.4g}±{e:.2g}' for x, e in zip(v, c))}")
    return ", ".join(out)


def fmt_list(v: Sequence[float]) -> str:
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
    """The effect a swap step put in place of ``removed``, or the pair ("a + b", both in
    ``effects``) the pair step put there ("" otherwise)."""
    law_reset: str = ""
    """The effect this step set back to its base law (a richer variant's extra parameters
    neutral again: they had stood in for the effect this step added), "" otherwise."""
    law_refined: str = ""
    """``"effect: variant"`` where this step gave an effect already in the model a richer
    law (the variant's extra parameters fitted with every effect after the last round),
    "" otherwise."""
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
            "law_refined": self.law_refined,
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
            new = " + ".join([e for e in s.effects if i and e not in self.steps[i - 1].effects] or s.effects[-1:])
            change = (f"{s.removed} → {s.swapped_in}" if s.swapped_in else f"− {s.removed}" if s.removed else f"{s.law_refined} law" if s.law_refined
                      else (f"+ {new} ({s.law_reset} at its base law)" if s.law_reset else f"+ {new}") if s.effects and i else "")
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
        times [s], share of the excess; :meth:`ReplayProblem.spikes`; the last model's constant part:
        ``offset``, what the measured channel reads above that model in its unit (with ``offsets``
        the fitted offset), and ``offset_share`` of that model's excess before it is taken out;
        :meth:`ReplayProblem.offsets`), ``suspects`` (first round, every effect ranked),
        ``history`` (each step's effects and error), ``rounds``, ``conclusion``, ``notes``
        (what the swap and base-law steps tried, the noise floors re-estimated), ``noise_initial`` (σ per channel
        as first estimated, before the loop re-estimated any), ``complete`` and, when a round failed,
        ``error``."""
        first = self.diagnoses[0] if self.diagnoses else None
        floor = self.at_floor
        enc = self.encoder_floor
        spikes: Dict[str, Dict[str, Any]] = {}
        offsets: Dict[str, Dict[str, float]] = {}
        fp = self._floors_problem()
        if fp is not None:
            try:
                z = fp.residuals(fp.nominal_simulation())
                spikes, offsets = fp.spikes(z), final_problem(fp, self.steps[-1]).offsets()
            except Exception:  # noqa: BLE001 - the numbers still go out
                spikes, offsets = {}, {}
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
                    "offset": _num(offsets.get(c, {}).get("offset")),
                    "offset_share": _num(offsets.get(c, {}).get("share")),
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
        labels = ["nominal"] + [(f"{s.removed}→{s.swapped_in}" if s.swapped_in else f"−{s.removed}" if s.removed
                                 else f"{s.law_refined}" if s.law_refined else f"+{s.effects[-1]}")
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


def _systematic_of(per: Mapping[str, float]) -> float:
    """S (:data:`ERROR_DEFINITION`) of the noise multiples ``per`` (channel → r_c)."""
    return systematic(np.square(np.array(list(per.values()), dtype=np.float64))) if per else math.nan


def step_at_floor(st: HistoryStep, prob: ReplayProblem) -> bool:
    """:func:`~popup.diagnosis.rules.model_at_floor` of a step of the loop."""
    return model_at_floor(prob, st.error, st.channel_error)
