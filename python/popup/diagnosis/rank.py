"""One round: every effect of the library fitted, validated and ranked (:func:`diagnose`)."""

from __future__ import annotations

import math
import os
import threading
import time
from typing import TYPE_CHECKING, Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from .. import effects as fx
from .. import estimate as est
from ..compare import compare
from ..exceptions import InputError
from ..io import MeasuredRun
from ..problem import Cancelled, ReplayProblem
from ..unseen import fit_unseen_motion
from .rules import FLOOR_MULTIPLE, JOINT_TOP, UNSEEN_TOP, Progress, floor_words, model_at_floor
from .results import Diagnosis, Suspect
from .evidence import evidence_for
from .candidate import left_out, rank_key, refit_jointly, refit_with_own_unseen, screen_fit, screen_without_unseen, try_effect
from .conclusion import round_conclusion

if TYPE_CHECKING:  # pragma: no cover
    from ..model import Model


def cores(prob: ReplayProblem) -> int:
    """The cores a ranking on ``prob`` may use: its ``threads``, or (0) every core this
    process may run on."""
    if prob.threads > 0:
        return prob.threads
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def _each(prob: ReplayProblem, work: Sequence[Tuple[str, Callable[[ReplayProblem], Suspect]]], progress: Optional[Progress], done0: int,
          total: int) -> List[Suspect]:
    """Each ``(label, fn)`` of ``work`` as ``fn(fork)``, on a fork of ``prob``
    (:meth:`ReplayProblem.fork`), up to :func:`cores` at once; the results in ``work``'s
    order. Every candidate's fit depends on ``prob`` and its own name only, so the results
    (rollout counts included) are the same bits whatever the number of threads; the
    candidates running at a time share the cores as rollout threads (the last ones running
    get them all).

    An interrupt in this thread (Ctrl-C, or a handler's ``KeyboardInterrupt``) stops the
    others at their next simulation and is raised once they have ended."""
    n = cores(prob)
    width = max(1, min(n, len(work)))
    lock = threading.Lock()
    started = [done0]

    def run(label: str, fn: Callable[[ReplayProblem], Suspect], fork: ReplayProblem) -> Suspect:
        if progress is not None:
            with lock:
                progress({"effect": label, "done": started[0], "total": total})
                started[0] += 1
        return fn(fork)

    if width == 1:
        out = []
        for label, fn in work:
            fork = prob.fork(prob.threads)
            try:
                out.append(run(label, fn, fork))
            finally:
                prob.nfev += fork.nfev
        return out
    cancel = threading.Event()
    forks = [prob.fork(max(1, n // width), cancel) for _ in work]
    results: List[Optional[Suspect]] = [None] * len(work)
    errors: List[Optional[BaseException]] = [None] * len(work)
    todo = iter(range(len(work)))
    lock_next = threading.Lock()

    running: Dict[int, ReplayProblem] = {}

    def share(i: Optional[int], fork: Optional[ReplayProblem]) -> None:
        # the cores split over the candidates running now: the last ones get them all
        with lock_next:
            if fork is not None:
                running[i] = fork  # type: ignore[index]
            else:
                running.pop(i, None)  # type: ignore[arg-type]
            k = len(running)
            for j, f in enumerate(sorted(running)):
                running[f].threads = max(1, n // k + (1 if j < n % k else 0)) if k else 1

    def worker() -> None:
        while not cancel.is_set():
            with lock_next:
                i = next(todo, None)
            if i is None:
                return
            share(i, forks[i])
            try:
                results[i] = run(work[i][0], work[i][1], forks[i])
            except BaseException as e:  # noqa: BLE001 - handed to the main thread
                errors[i] = e
                cancel.set()
            finally:
                share(i, None)

    threads: List[threading.Thread] = []
    try:
        for k in range(width):
            th = threading.Thread(target=worker, name=f"popup-candidate-{k}", daemon=True)
            threads.append(th)  # before start(): an interrupt inside start() still joins it
            th.start()
        # timed joins: a signal the kernel hands to another thread is only run by this (the
        # main) thread between bytecodes, never while it blocks on a lock
        while any(th.is_alive() for th in threads):
            for th in threads:
                th.join(0.1)
    except BaseException:
        cancel.set()
        for th in threads:
            if th.ident is not None:
                th.join()
        raise
    finally:
        prob.nfev += sum(f.nfev for f in forks)
    failed = [e for e in errors if e is not None and not isinstance(e, Cancelled)]
    if failed:
        raise failed[0]
    return [r for r in results if r is not None]


def _screen(name: str, ev: Dict[str, Any], max_iter: int, start: Mapping[str, Sequence[float]]) -> Callable[[ReplayProblem], Suspect]:
    return lambda p: screen_fit(p, name, ev, max_iter, start)


def _try(name: str, ev: Dict[str, Any], max_iter: int, also: Any, prior: Any) -> Callable[[ReplayProblem], Suspect]:
    return lambda p: try_effect(p, name, ev, max_iter, also, prior)


def _own(s: Suspect, ev: Dict[str, Any], max_iter: int) -> Callable[[ReplayProblem], Suspect]:
    return lambda p: refit_with_own_unseen(p, s, ev, max_iter)


def _bare(s: Suspect, ev: Dict[str, Any], max_iter: int) -> Callable[[ReplayProblem], Suspect]:
    return lambda p: screen_without_unseen(p, s, ev, max_iter)


def _refit(s: Suspect, ev: Dict[str, Any], max_iter: int, also: Any, prior: Any) -> Callable[[ReplayProblem], Suspect]:
    return lambda p: refit_jointly(p, s, ev, max_iter, also, prior)


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
    offsets: bool = False,
) -> Diagnosis:
    """Rank every effect of the library (or ``effects``) by how much of the model's
    systematic error on ``run`` it explains, each fitted, validated on held-out samples,
    with intervals, identifiability and its residual evidence (module docs).

    Effects that ``model`` already has are skipped. ``threads``: the cores to use (0 =
    every core): the candidates are fitted that many at once, each on its own thread with a
    share of the cores as rollout threads; the result is the same bits for any count.
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
    ``offsets``: fit a constant offset per channel with every model (a sensor bias; see
    :class:`ReplayProblem`), when no ``problem`` is given.
    """
    t_start = time.perf_counter()
    est.check_max_iter(max_iter)
    names = list(fx.EFFECT_NAMES if effects is None else effects)
    for n in names:
        fx.normalize(n, {})
    given = problem is not None
    if problem is None:
        problem = fit_unseen_motion(ReplayProblem(model, run, channels=channels, sample_rate=sample_rate, threads=threads, offsets=offsets))
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
        why = (f"not tried: the model is at its floor (systematic error {floor_words(prob, per0)}, every channel within {FLOOR_MULTIPLE:g}× of it): "
               "nothing is left for an effect to "
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
    # round one (nothing to refit jointly, not at the floor): the leading candidates are
    # refitted on their own unseen motion
    n_own = min(UNSEEN_TOP, len(todo)) if not also and not floor and not prob.closed and prob.smoothing is not None else 0
    # and where the nominal's motion holds a compliance, every candidate is first refitted
    # from its fit on the replay without it (screen_without_unseen)
    n_bare = len(todo) if n_own and np.count_nonzero(prob.compliance) else 0
    if screen > 0 and starts:
        with_start = [n for n in todo if starts.get(n)]
        for name in with_start:
            evs[name] = evidence_for(name, cmp, prob)
        screened = _each(prob, [(f"{name} (screen)", _screen(name, evs[name], max_iter, starts[name])) for name in with_start],
                         progress, 0, len(with_start) + min(screen, len(todo)) + n_joint + n_bare + n_own)
        quick = dict(zip(with_start, screened))
        order = sorted(quick.values(), key=rank_key)
        full = {q.effect for q in order[:screen]} | {q.effect for q in order if q.significant} | {n for n in todo if n not in quick}
        todo = [n for n in todo if n in full] + [n for n in todo if n not in full]
        done0 = len(with_start)
    else:
        full, done0 = set(todo), 0
    total = done0 + len(full) + n_joint + n_bare + n_own
    fitted = [n for n in todo if n in full]
    for name in fitted:
        evs.setdefault(name, evidence_for(name, cmp, prob))
    suspects += _each(prob, [(name, _try(name, evs[name], max_iter, also if joint and also else None, (starts or {}).get(name))) for name in fitted],
                      progress, done0, total)
    for name in todo:
        if name not in full:
            q = quick[name]
            q.message = "; ".join(x for x in (q.message, f"screened from its fit of the round before only (not among the {screen} best of the screen)") if x)
            suspects.append(q)
    suspects.sort(key=rank_key)
    if also:
        top = [i for i, s in enumerate(suspects[:n_joint]) if s.tested and math.isfinite(s.score)]
        refits = _each(prob, [(f"{suspects[i].effect} (joint refit)", _refit(suspects[i], evs[suspects[i].effect], max_iter, also, (starts or {}).get(suspects[i].effect)))
                              for i in top], progress, done0 + len(full), total)
        for i, r in zip(top, refits):
            suspects[i] = r
        suspects.sort(key=rank_key)
    if n_bare:
        suspects = _each(prob, [(f"{x.effect} (without unseen motion)", _bare(x, evs[x.effect], max_iter)) for x in suspects],
                         progress, total - n_own - n_bare, total)
        suspects.sort(key=rank_key)
    if n_own:
        # the unseen servo motion fitted on the nominal model takes part of a missing
        # softening: the leading candidates are refitted on the motion their own model gives
        # (an untested one comes back as it is)
        owns = _each(prob, [(f"{x.effect} (own unseen motion)", _own(x, evs[x.effect], max_iter)) for x in suspects[:n_own]],
                     progress, total - n_own, total)
        suspects[:n_own] = owns
        suspects.sort(key=rank_key)
    if floor and todo:
        why = f"not significant: the model is at its floor (systematic error {floor_words(prob, per0)}, every channel within {FLOOR_MULTIPLE:g}× of it)"
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
        floor_error_upper=prob.floor_error(per0, upper=True),
        model_at_floor=floor,
    )
    d.conclusion = round_conclusion(d)
    d.seconds = time.perf_counter() - t_start
    return d
