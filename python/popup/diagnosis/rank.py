"""One round: every effect of the library fitted, validated and ranked (:func:`diagnose`)."""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING, Any, Dict, List, Mapping, Optional, Sequence, Tuple

from .. import effects as fx
from .. import estimate as est
from ..compare import compare
from ..exceptions import InputError
from ..io import MeasuredRun
from ..problem import ReplayProblem
from ..unseen import fit_unseen_motion
from .rules import FLOOR_MULTIPLE, JOINT_TOP, Progress, model_at_floor
from .results import Diagnosis, Suspect
from .evidence import evidence_for
from .candidate import left_out, rank_key, refit_jointly, screen_fit, try_effect
from .conclusion import round_conclusion

if TYPE_CHECKING:  # pragma: no cover
    from ..model import Model


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
    also = [pi for e, ps in (refit or {}).items() for pi in est.free_params(e, list(ps) or None) if not left_out(flat0, *pi)]
    todo = [n for n in names if n not in have]
    suspects: List[Suspect] = []
    evs: Dict[str, Dict[str, Any]] = {}
    floor = model_at_floor(prob, e0, per0)
    if floor and not rank_at_floor:
        why = (f"not tried: the model is at its floor (systematic error {prob.floor_error(per0):.3g} above the noise and the "
               f"encoder's replay error, every channel within {FLOOR_MULTIPLE:g}× of it): nothing is left for an effect to "
               "explain (rank_at_floor=True, or --rank-at-floor, fits them anyway)")
        todo = []
        for name in names:
            if name not in have:
                suspects.append(Suspect(name, False, -math.inf, {}, {}, e0, math.nan, {}, evidence_for(name, cmp, prob), tested=False, message=why))
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
            evs[name] = evidence_for(name, cmp, prob)
            quick[name] = screen_fit(prob, name, evs[name], max_iter, starts[name])
        order = sorted(quick.values(), key=rank_key)
        full = {q.effect for q in order[:screen]} | {q.effect for q in order if q.significant} | {n for n in todo if n not in quick}
        todo = [n for n in todo if n in full] + [n for n in todo if n not in full]
        done0 = len(with_start)
    else:
        full, done0 = set(todo), 0
    total = done0 + len(full) + n_joint
    for i, name in enumerate(n for n in todo if n in full):
        if progress is not None:
            progress({"effect": name, "done": done0 + i, "total": total})
        evs.setdefault(name, evidence_for(name, cmp, prob))
        suspects.append(try_effect(prob, name, evs[name], max_iter, also if joint and also else None, (starts or {}).get(name)))
    for name in todo:
        if name not in full:
            q = quick[name]
            q.message = "; ".join(x for x in (q.message, f"screened from its fit of the round before only (not among the {screen} best of the screen)") if x)
            suspects.append(q)
    suspects.sort(key=rank_key)
    if also:
        for i, s in enumerate(suspects[:n_joint]):
            if progress is not None:
                progress({"effect": f"{s.effect} (joint refit)", "done": done0 + len(full) + i, "total": total})
            if s.tested and math.isfinite(s.score):
                suspects[i] = refit_jointly(prob, s, evs[s.effect], max_iter, also, (starts or {}).get(s.effect))
        suspects.sort(key=rank_key)
    if floor and todo:
        why = (f"not significant: the model is at its floor (systematic error {prob.floor_error(per0):.3g} above the noise "
               f"and the encoder's replay error, every channel within {FLOOR_MULTIPLE:g}× of it)")
        for s in suspects:
            if s.significant:
                s.significant = False
                s.message = why + ("; " + s.message if s.message else "")
        suspects.sort(key=rank_key)
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
    d.conclusion = round_conclusion(d)
    d.seconds = time.perf_counter() - t_start
    return d
