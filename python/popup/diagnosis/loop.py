"""The loop (:func:`improve`): add the best significant effect, refit, diagnose again; the
backward, swap and base-law steps; the floors re-estimated after each step."""

from __future__ import annotations

import itertools
import math
import time
from typing import TYPE_CHECKING, Any, Dict, List, Mapping, Optional, Sequence, Set, Tuple

import numpy as np

from .. import effects as fx
from .. import estimate as est
from ..exceptions import InputError, StepTooLargeError
from ..io import MeasuredRun
from ..problem import ReplayProblem
from ..unseen import fit_unseen_motion
from ..results import UNITS
from .rules import (AT_FLOOR, ENCODER_NOTE, FIRST_PAIRS, JOINT_TOP, MIN_EXPLAINED, MIN_ITER, NOISE_RECHECK, OFFSET_SHARE, OFFSET_Z, PAIR_HINTS, PLAY_PARAMS, PREDICT_REL, PREDICT_TOL, Progress, SCORE_THRESHOLD,
                    STEP_HALVINGS, VARIANTS, model_at_floor)
from .results import Diagnosis, History, HistoryStep, Suspect, final_problem, step_at_floor
from .candidate import left_out, limit_passed, unresolved_play
from .conclusion import conclude
from .rank import diagnose

if TYPE_CHECKING:  # pragma: no cover
    from ..model import Model


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
    stop_on_interrupt: bool = False,
    offsets: Optional[bool] = None,
) -> History:
    """The loop: diagnose, add the top significant effect, refit every added effect
    jointly, diagnose again; until no effect is significant or ``max_rounds``.

    Nothing is lost: a failure in round k returns rounds 1..k−1 with ``History.error``
    set. Errors in the set-up (a run the model cannot replay at all) are raised.
    ``rank_at_floor``: as :func:`diagnose`, for a model at its floor from the start.
    ``stop_on_interrupt``: a ``KeyboardInterrupt`` after the set-up (Ctrl-C; ``popup
    diagnose`` also raises one on SIGTERM and at its ``--time-limit``) ends the loop like a
    failed round, returning the rounds finished, instead of propagating.
    ``offsets``: fit a constant offset per channel with every model, a sensor bias or a
    calibration offset the run still has (:class:`ReplayProblem`; True), or not (False).
    Default (None): not, unless what the loop leaves is mostly constant offsets
    (:func:`offsets_left`): no library effect is a constant on one channel, so the run is
    then diagnosed again with them fitted and that history returned (its conclusion says
    so; if that pass does not complete, the first is returned with a note and ``error``)."""
    kw: Dict[str, Any] = dict(max_rounds=max_rounds, effects=effects, channels=channels, sample_rate=sample_rate, threads=threads,
                              max_iter=max_iter, progress=progress, rank_at_floor=rank_at_floor, stop_on_interrupt=stop_on_interrupt)
    h = _improve(model, run, offsets=bool(offsets), **kw)
    if offsets is not None or not h.complete:
        return h
    why = offsets_left(h)
    if not why:
        return h
    first = (f"the pass with constant offsets in the error {'added ' + ', '.join(h.effects) if h.effects else 'added nothing'} and left "
             f"{h.steps[-1].error:.3g} noise units, mostly constant offsets ({why})")
    if progress is not None:
        outer = progress
        kw["progress"] = lambda info: outer(dict(info, effect=f"offsets fitted: {info.get('effect', '')}"))
    try:
        h2 = _improve(model, run, offsets=True, **kw)
        err = h2.error
    except Exception as e:  # noqa: BLE001 - the first pass is complete: it is returned
        err = f"{type(e).__name__}: {e}"
    if err or not h2.complete:
        # the first pass is a whole answer, but not the one asked for: incomplete (exit code 1)
        h.notes.append(f"{first}; the pass with a constant offset fitted per channel did not complete ({err}): this is the first")
        h.error = f"the pass with the offsets fitted: {err}"
        h.conclusion = h.conclusion[:-1] + f"; incomplete: {first}, and the pass with them fitted did not complete ({err})."
        return h
    h2.notes.insert(0, f"{first}: diagnosed again with a constant offset fitted per channel (offsets=True, --offsets)")
    h2.conclusion = h2.conclusion[:-1] + f"; fitted because {first}."
    h2.seconds += h.seconds
    return h2


def offsets_left(h: History) -> str:
    """Why the last model of ``h`` leaves mostly constant offsets (empty if it does not): its
    residual's constant parts (:meth:`ReplayProblem.offsets`) make at least
    :data:`OFFSET_SHARE` of the excess over every channel, at least one of them significant
    (:data:`OFFSET_Z` standard errors), and the model is above its floor."""
    last = h.steps[-1]
    prob = h.problem
    if prob is None or prob.fit_offsets or last.error <= AT_FLOOR or step_at_floor(last, prob):
        return ""
    const, excess, big = 0.0, 0.0, []
    for c, v in final_problem(prob, last).offsets().items():
        m, n = v["z_mean"], v["n"]
        const += n * m * m
        excess += max(v["excess"], 0.0)
        if abs(m) * math.sqrt(n) >= OFFSET_Z:
            big.append((c, v["offset"], n * m * m))
    if not big or excess <= 0 or const < OFFSET_SHARE * excess:
        return ""
    big.sort(key=lambda b: -b[2])
    return (f"{100 * min(const / excess, 1.0):.0f} % of its excess; " + ", ".join(f"{c} {v:+.3g} {UNITS.get(c, '')}" for c, v, _ in big[:4])
            + (f" and {len(big) - 4} more" if len(big) > 4 else ""))


def _improve(
    model: "Model",
    run: MeasuredRun,
    *,
    max_rounds: int,
    effects: Optional[Sequence[str]],
    channels: Optional[Sequence[str]],
    sample_rate: Optional[float],
    threads: int,
    max_iter: int,
    progress: Optional[Progress],
    rank_at_floor: bool,
    stop_on_interrupt: bool,
    offsets: bool,
) -> History:
    t_start = time.perf_counter()
    for n in effects or []:
        fx.normalize(n, {})  # bad input is refused before any work
    if int(max_rounds) < 0:
        raise InputError(f"input max_rounds: {max_rounds} must be ≥ 0")
    est.check_max_iter(max_iter)
    prob = fit_unseen_motion(ReplayProblem(model, run, channels=channels, sample_rate=sample_rate, threads=threads, offsets=offsets))
    steps = [_step(prob, [], {}, 0)]
    noise0 = prob.noise
    diags: List[Diagnosis] = []
    added: List[str] = []
    fitted_params: Dict[str, List[str]] = {}
    swap_tried: Dict[str, Set[str]] = {}
    pair_tried: Set[Tuple[str, str]] = set()  # (the effect swapped out, the hint) of each pair step
    first_pairs = False  # the first-round pair step is tried once
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
            reset, pair_out = "", ""  # the effect set back to its base law, or swapped out for a pair
            if d.best is not None:
                rnd += 1
                s = d.best
                before = (list(added), {e: list(v) for e, v in fitted_params.items()}, cprob)  # the model s is added to
                added.append(s.effect)
                fitted_params[s.effect] = list(s.fitted)
                cand = s.apply(current)
                # refitted on the unseen motion of its own model, where it was fitted on it
                cprob = (prob if s.unseen is None else prob.with_unseen_motion(*s.unseen)).with_model(cand)
                if progress is not None:
                    progress({"round": rnd, "effect": "refit " + " + ".join(added), "done": 0, "total": 1})
                current, cprob, ci = _refit_stable(cprob, added, fitted_params, max_iter)
                cprob = fit_unseen_motion(cprob)  # the torques changed with the model
                if before[0] and not step_at_floor(_step(cprob, added, ci, rnd), prob):
                    # an earlier effect's richer law may stand in for what is missing (a
                    # payload's centre-of-mass offset for a torsion), and then the candidate
                    # just added stands in beside it (a pressure leak): the earlier effect
                    # back at its base law with the best candidate for that model is a rival,
                    # kept when it beats the model with s (MuJoCo pair 661-010)
                    stage, stage_round = "base-law rival: ", rnd
                    rv = _law_rival(prob, run, before, cprob, fitted_params, s.effect, effects, diags, threads, max_iter, prog, notes)
                    stage = ""
                    if rv is not None:
                        reset, (c, current, cprob, ci, fitted_params, d_new) = rv
                        added[:] = list(before[0]) + [c]
                        diags.append(d_new)
            else:
                # nothing significant is left, but the model is not at its floor: a richer
                # law chosen for an earlier effect may be standing in for a missing effect
                # (a payload's centre-of-mass offset for a torsion); each is tried back at
                # its base law with the best candidate added. First, one effect added may
                # stand in for two of round 1's other candidates that each fit badly alone
                pr = None
                if len(added) == 1 and not first_pairs and not step_at_floor(steps[-1], prob):
                    first_pairs = True
                    stage, stage_round = f"swap {added[0]} for a pair of round 1's candidates: ", rnd + 1
                    pr = _first_round_pair(prob, run, cprob, added[0], fitted_params, diags[0], effects, threads, max_iter, prog, notes)
                    stage = ""
                lw = None
                if pr is None and added and not step_at_floor(steps[-1], prob):
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
                if pr is None and lw is None and len(added) == 1 and not step_at_floor(steps[-1], prob):
                    # one effect added and a systematic error left: it may stand in for two
                    # effects neither of which explains much alone (drag beside a payload:
                    # a backlash with link-side inertia and contact damping mimics both)
                    hints = [s for s in _hints(d) if (added[0], s.effect) not in pair_tried]
                    pair_tried.update((added[0], s.effect) for s in hints)
                    stage, stage_round = f"swap {added[0]} for a pair: ", rnd + 1
                    pr = _try_pair(prob, run, cprob, added[0], fitted_params, hints, diags, effects, threads, max_iter, prog, notes)
                    stage = ""
                hz = _unpredictable_top(d) if not added and prob.horizon is None else None
                if hz is not None and not step_at_floor(steps[-1], prob):
                    # nothing significant, and the best candidate's replay is not predictable
                    # past hz (a gear rattling in its play: a play PREDICT_REL wider parts
                    # from it there by more than the floor test tells): no free-run error past
                    # hz can judge it, the truth's own law included, so every candidate and
                    # the nominal model are judged before hz (MuJoCo 802-000, session 74),
                    # before any pair is tried (the pairs are tried on the cut, where it finds none)
                    prob, cprob = prob.until(hz), cprob.until(hz)
                    steps[:] = [_step(prob, [], {}, 0)]
                    notes.append(f"judged on t < {hz:.3g} s from round {rnd + 1} on: past it the replay of the best candidate, {d.suspects[0].effect}, "
                                 f"is not predictable (a play {100 * PREDICT_REL:g} % wider moves it by more than {PREDICT_TOL:g} noise units); "
                                 f"the nominal error there is {steps[0].error:.3g} noise units")
                    d = diagnose(current, run, effects=effects, threads=threads, max_iter=max_iter, problem=cprob, progress=prog, rank_at_floor=rank_at_floor)
                    diags.append(d)
                    continue
                if pr is None and lw is None and not added and not step_at_floor(steps[-1], prob):
                    # nothing added and a systematic error left: two effects may each replay
                    # worse alone than neither (a sensor delay beside a bending law that
                    # moves the phase of the channels it shares: MuJoCo pair, session 34)
                    stage, stage_round = "a pair: ", rnd + 1
                    pr = _pair_from_none(prob, run, cprob, _hints(d), d, diags, effects, threads, max_iter, prog, notes)
                    stage = ""
                if lw is not None:
                    c, current, cprob, ci, fitted_params, d_new = lw
                    added.append(c)
                elif pr is not None and not added:
                    _, current, cprob, ci, fitted_params, d_new = pr
                    added[:] = list(fitted_params)
                elif pr is not None:
                    _, current, cprob, ci, fitted_params, d_new = pr
                    pair_out, added[:] = added[0], list(fitted_params)
                else:
                    break
                rnd += 1
                diags.append(d_new)
            steps.append(_step(cprob, added, ci, rnd, law_reset=reset, removed=pair_out, swapped_in=" + ".join(added) if pair_out else ""))
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
                    if step_at_floor(steps[-1], prob):
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
            if not remaining or step_at_floor(steps[-1], prob):
                break
            # from the third round on, a cheap screen from each candidate's last fit picks
            # the few that get the full multi-start fit (pairs are found by round 2)
            d = diagnose(current, run, effects=remaining, threads=threads, max_iter=max_iter, problem=cprob, progress=prog, refit=fitted_params,
                         starts=_prior_fits(diags), screen=JOINT_TOP if len(added) >= 2 else 0)
            diags.append(d)
        if added and d.best is None and not step_at_floor(steps[-1], prob):
            # the rounds are done (nothing significant left) and a systematic error is left: a richer law of an effect
            # in the model, not preferred when that effect was chosen (the error of another
            # effect, not yet added, hid its gain), is tried again with every effect in
            # (Stribeck friction beside a pressure leak: 2.84 -> 0.23 noise units)
            stage, stage_round = "richer law: ", rnd
            rl = _try_richer_laws(cprob, added, fitted_params, max_iter, prog, notes)
            stage = ""
            if rl is not None:
                e, name, current, cprob, ci, fitted_params = rl
                steps.append(_step(cprob, added, ci, rnd, law_refined=f"{e}: {name}"))
    except KeyboardInterrupt as e:
        if not stop_on_interrupt:
            raise
        error = f"round {rnd + 1} interrupted: {e or 'KeyboardInterrupt'}"
    except Exception as e:  # noqa: BLE001 - nothing lost: the rounds before are returned
        error = f"round {rnd + 1} failed: {type(e).__name__}: {e}"
    h = History(steps, diags, "", run=str(run.source), seconds=0.0, error=error, noise=prob.noise, notes=notes, noise_initial=noise0,
                problem=prob)
    h.conclusion = conclude(h, max_rounds, prob)
    h.seconds = time.perf_counter() - t_start
    return h


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
        e, up = cprob.encoder_bootstrap_bounds()
        prob, cprob = prob.with_encoder_sigma(e, up), cprob.with_encoder_sigma(e, up)
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
    return sum(1 for e, ps in fitted.items() for pi in est.free_params(e, list(ps) or None) if not left_out(flat, *pi))


def _bic_gain(new: ReplayProblem, fitted_new: Mapping[str, Sequence[str]], cur: ReplayProblem, fitted_cur: Mapping[str, Sequence[str]]) -> float:
    """The BIC gain of the model of ``new`` over the (non-nested) model of ``cur`` on the
    same run: the likelihood ratio on the training samples less ln n_eff per extra fitted
    parameter; ``-inf`` where their output grids differ."""
    z_new = new.residuals(new.nominal_simulation())
    z_cur = cur.residuals(cur.nominal_simulation())
    if z_new.shape != z_cur.shape:
        return -math.inf
    lr, ne = est.log_ratio(cur, z_cur, z_new, cur.train)
    return lr - (_n_params(fitted_new, new.model.effects_flat) - _n_params(fitted_cur, cur.model.effects_flat)) * math.log(ne)


def _beats(new: ReplayProblem, fitted_new: Mapping[str, Sequence[str]], cur: ReplayProblem, fitted_cur: Mapping[str, Sequence[str]]) -> Tuple[bool, str]:
    """Whether the model of ``new`` beats the (non-nested) model of ``cur`` on the same run:
    its BIC gain (:func:`_bic_gain`) passes the significance threshold, and it lowers the
    held-out error too; and the numbers, as text."""
    gain = _bic_gain(new, fitted_new, cur, fitted_cur)
    if not math.isfinite(gain):
        return False, "not comparable (different output grids)"
    v_new, v_cur = new.error(mask=new.validation)[0], cur.error(mask=cur.validation)[0]
    ok = bool(gain > SCORE_THRESHOLD and v_new < v_cur)
    return ok, f"BIC gain {gain:.1f} (threshold {SCORE_THRESHOLD:g}), held-out error {v_cur:.3g} → {v_new:.3g}"


def _try_swap(prob: ReplayProblem, run: MeasuredRun, cprob: ReplayProblem, effect: str, added: List[str], fitted: Dict[str, List[str]],
              effects: Optional[Sequence[str]], diags: Sequence[Diagnosis], threads: int, max_iter: int,
              progress: Optional[Progress], log: Optional[List[str]] = None) -> Optional[Tuple[str, "Model", ReplayProblem, Dict[str, Dict[str, List[float]]], Dict[str, List[str]]]]:
    """Whether ``effect`` (added earlier) is better replaced by another candidate: the
    model of ``cprob`` without it is diagnosed (the candidates screened with the other
    added effects held, the :data:`JOINT_TOP` best fitted from their seeds with those
    refitted: refitted without the stand-in, they sit off and the screen misranks, a drag
    run to a high cd ranking higher modes above the missing payload), its best significant
    candidate put in its place and every added effect refitted; the swap is returned (the new effect, model, problem, intervals and fitted
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
                       log=log, what=what, screen=JOINT_TOP)
    if best is None:
        return None
    c, m2, p2, ci2, nf, _ = best
    order = [c if e == effect else e for e in added]
    return c, m2, p2, ci2, {e: nf[e] for e in order}


def _best_added(prob: ReplayProblem, run: MeasuredRun, base: ReplayProblem, kept: List[str], fitted: Dict[str, List[str]], pool: List[str],
                diags: Sequence[Diagnosis], threads: int, max_iter: int,
                progress: Optional[Progress], cur: ReplayProblem,
                fitted_cur: Mapping[str, Sequence[str]], log: Optional[List[str]] = None, what: str = "",
                joint: bool = False, screen: int = 1,
                starts: Optional[Mapping[str, Mapping[str, Sequence[float]]]] = None) -> Optional[Tuple[str, "Model", ReplayProblem, Dict[str, Dict[str, List[float]]], Dict[str, List[str]], Diagnosis]]:
    """The model of ``base`` with the best significant candidate among ``pool`` added (the
    candidates diagnosed with the effects ``kept``, fitted names ``fitted``, refitted with
    each; the best added and everything refitted jointly), if it beats the current model
    ``cur`` (:func:`_beats`). Returns (its name, the model, its problem with its own unseen
    motion, intervals, fitted names, the diagnosis), or ``None``: no candidate significant,
    the current model better, or a failure (the current model stands). ``log``: a line
    saying what (``what``) was tried and why it was (not) kept is appended. ``joint``: as
    :func:`diagnose`'s (every candidate fitted jointly with ``kept`` from its seeds).
    ``screen``: the number of best-screened candidates that get the full fit
    (:func:`diagnose`'s). ``starts``: one more start per candidate (:func:`diagnose`'s),
    instead of each one's fit in ``diags``."""
    what = what or "candidates " + ", ".join(pool)
    try:
        # only the best candidate is taken: the cheap screen picks the ``screen`` that get the full fit
        d = diagnose(base.model, run, effects=pool, threads=threads, max_iter=max_iter, problem=base, progress=progress, refit=fitted,
                     starts=_prior_fits(diags) if starts is None else starts, screen=screen, joint=joint)
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


def _hints(d: Diagnosis) -> List[Suspect]:
    """The candidates of ``d`` that pass the significance threshold in likelihood but were
    not significant (they explain less than :data:`MIN_EXPLAINED` of what is left), best
    first, at most :data:`PAIR_HINTS`: beside an effect that stands in for two, what one of
    the two still explains."""
    out = [s for s in d.suspects if s.tested and not s.significant and math.isfinite(s.score) and s.score > SCORE_THRESHOLD]
    return sorted(out, key=lambda s: -s.score)[:PAIR_HINTS]


def _hint_base(prob: ReplayProblem, h: Suspect, log: Optional[List[str]], what: str) -> Optional[ReplayProblem]:
    """The nominal model of ``prob`` with hint ``h``'s effect at its fit (at its fit's step
    where that is smaller) and the unseen motion fitted again: the base a pair with ``h`` is
    diagnosed from; ``None`` (and a line in ``log`` on ``what``) where it cannot be set up."""
    try:
        m = prob.model.with_effect(h.effect, **h.params)  # not h.apply: that brings a refitted effect back
        return fit_unseen_motion(prob.with_model(m.with_dt(h.dt) if math.isfinite(h.dt) and h.dt < m.dt else m))
    except KeyboardInterrupt:
        raise
    except Exception as ex:  # noqa: BLE001 - the model stands
        _note(log, f"{what}: failed setting up {h.effect} ({type(ex).__name__}: {ex}); the model stands")
        return None


def _try_pair(prob: ReplayProblem, run: MeasuredRun, cprob: ReplayProblem, effect: str, fitted: Dict[str, List[str]],
              hints: Sequence[Suspect], diags: Sequence[Diagnosis], effects: Optional[Sequence[str]], threads: int, max_iter: int,
              progress: Optional[Progress],
              log: Optional[List[str]] = None) -> Optional[Tuple[str, "Model", ReplayProblem, Dict[str, Dict[str, List[float]]], Dict[str, List[str]], Diagnosis]]:
    """Whether the one added ``effect`` (model of ``cprob``) is better replaced by a pair:
    for each hint ``b`` (:func:`_hints` of the current model's diagnosis, best first), the
    nominal model of ``prob`` with ``b`` at its hint's fit is diagnosed over the candidates
    some round found significant (not ``effect``), each fitted jointly with ``b`` from its
    seeds (a pair whose members interact is found only together: a payload fitted alone
    beside the drag it hides lands in another basin), and the best added and both refitted.
    The first pair that beats the current model (:func:`_beats`: BIC gain over the
    threshold, held-out error lower) is returned as :func:`_best_added` returns it, its
    fitted names in the order (``b``, the other); else ``None``. ``log``: a line per hint
    saying what was tried and why it was (not) kept."""
    for h in hints:
        pool = [c for c in _significant_in(diags) if c not in (effect, h.effect) and (effects is None or c in effects)]
        if not pool:
            _note(log, f"swap of {effect} for {h.effect} and another: no other candidate was significant in any round")
            continue
        what = f"swap of {effect} for {h.effect} (a likelihood gain of {h.score:.3g} beside it) and one of {', '.join(pool)}, each fitted with it from its seeds"
        base = _hint_base(prob, h, log, what)
        if base is None:
            continue
        out = _best_added(prob, run, base, [h.effect], {h.effect: list(h.fitted)}, pool, [], threads, max_iter, progress, cprob,
                          {effect: fitted[effect]}, log=log, what=what, joint=True)
        if out is not None:
            return out
    return None


def _first_round_pair(prob: ReplayProblem, run: MeasuredRun, cprob: ReplayProblem, effect: str, fitted: Dict[str, List[str]], d1: Diagnosis,
                      effects: Optional[Sequence[str]], threads: int, max_iter: int, progress: Optional[Progress],
                      log: Optional[List[str]] = None) -> Optional[Tuple[str, "Model", ReplayProblem, Dict[str, Dict[str, List[float]]], Dict[str, List[str]], Diagnosis]]:
    """Whether the one added ``effect`` (model of ``cprob``) stands in for two of the other
    candidates significant in round 1 (``d1``, on the nominal model of ``prob``), each of
    which fits badly alone (a payload fitted alone beside the drag it hides lands in another
    basin, and the drag at 17 × its truth). The :data:`FIRST_PAIRS` best of them are fitted
    two at a time, jointly, from their round-1 fits (one start each, no seeds: a screen);
    the pair of the largest BIC gain over the current model (:func:`_bic_gain`), if that
    passes the threshold, is confirmed as the pair step confirms one: the nominal model with
    the member of the larger round-1 score at its joint fit, the other diagnosed beside it,
    fitted jointly with it from its seeds and its joint fit, both refitted (:func:`_best_added`).
    The pair replaces ``effect`` where it beats the current model (:func:`_beats`) and
    explains at least :data:`MIN_EXPLAINED` of its systematic error, the share one effect
    must explain to be added. Returns what :func:`_best_added` returns (fitted names in the
    order: the first member, the other), or ``None``; ``log`` gets one line per call, all
    starting "pairs of round 1's candidates"."""
    head = f"pairs of round 1's candidates for {effect}"
    others = sorted((s for s in d1.suspects if s.significant and s.effect != effect and s.fitted and (effects is None or s.effect in effects)),
                    key=lambda s: -s.score)[:FIRST_PAIRS]
    if len(others) < 2:
        _note(log, f"{head}: fewer than two others were significant; the model stands")
        return None
    fitted_cur = {effect: fitted[effect]}
    e_cur = cprob.error()[0]
    best: Optional[Tuple[float, Suspect, Suspect, ReplayProblem]] = None
    failed: List[str] = []
    pairs = list(itertools.combinations(others, 2))
    for a, b in pairs:
        nf = {a.effect: list(a.fitted), b.effect: list(b.fitted)}
        try:
            m = prob.model.with_effect(a.effect, **a.params).with_effect(b.effect, **b.params)
            dt = min([x.dt for x in (a, b) if math.isfinite(x.dt)] + [m.dt])
            _, p2, _ = _refit_stable(prob.with_model(m.with_dt(dt) if dt < m.dt else m), [a.effect, b.effect], nf, max_iter)
            p2 = fit_unseen_motion(p2)
            g = _bic_gain(p2, nf, cprob, fitted_cur)
        except KeyboardInterrupt:
            raise
        except Exception as ex:  # noqa: BLE001 - that pair is not a rival; the others are
            failed.append(f"{a.effect} + {b.effect} ({type(ex).__name__}: {ex})")
            continue
        if math.isfinite(g) and (best is None or g > best[0]):
            best = (g, a, b, p2)
    fails = f"; failed: {', '.join(failed)}" if failed else ""
    names = f"{', '.join(s.effect for s in others)}; {len(pairs)} joint fits"
    if best is None or not best[0] > SCORE_THRESHOLD:
        top = f"the best, {best[1].effect} + {best[2].effect}, gains {best[0]:.1f} in BIC over it" if best is not None else "none could be fitted"
        _note(log, f"{head} ({names}), each two fitted jointly from their fits: {top} (threshold {SCORE_THRESHOLD:g}){fails}; the model stands")
        return None
    g, a, b, p2 = best
    what = (f"{head} ({names}), each two fitted jointly from their fits: {a.effect} + {b.effect} gains {g:.1f} in BIC over it{fails}; "
            f"{b.effect} fitted with {a.effect} from its seeds and that fit")
    pb = p2.model.effects
    try:
        base = fit_unseen_motion(prob.with_model(prob.model.with_effect(a.effect, **pb[a.effect]).with_dt(p2.model.dt)))
    except KeyboardInterrupt:
        raise
    except Exception as ex:  # noqa: BLE001 - the model stands
        _note(log, f"{what}: failed setting up {a.effect} ({type(ex).__name__}: {ex}); the model stands")
        return None
    start = {b.effect: {k: list(pb[b.effect][k]) for k in b.fitted if k in pb[b.effect]}}
    out = _best_added(prob, run, base, [a.effect], {a.effect: list(a.fitted)}, [b.effect], [], threads, max_iter, progress, cprob, fitted_cur,
                      log=log, what=what, joint=True, starts=start)
    if out is None:
        return None
    e2 = out[2].error()[0]
    share = 1 - e2 ** 2 / e_cur ** 2 if e_cur > 0 else 0.0
    if share < MIN_EXPLAINED:
        _note(log, f"{what}: the pair explains {share:.0%} of the systematic error ({e_cur:.3g} → {e2:.3g}), less than {MIN_EXPLAINED:.0%}; the model stands")
        return None
    _note(log, f"{what}: the pair explains {share:.0%} of the systematic error ({e_cur:.3g} → {e2:.3g}); {effect} swapped for it")
    return out


def _pair_from_none(prob: ReplayProblem, run: MeasuredRun, cprob: ReplayProblem, hints: Sequence[Suspect], d: Diagnosis,
                    diags: Sequence[Diagnosis], effects: Optional[Sequence[str]], threads: int, max_iter: int,
                    progress: Optional[Progress],
                    log: Optional[List[str]] = None) -> Optional[Tuple[str, "Model", ReplayProblem, Dict[str, Dict[str, List[float]]], Dict[str, List[str]], Diagnosis]]:
    """With nothing added (no candidate of the first round's ``d`` significant) and a
    systematic error left, whether a pair explains it. For each hint ``b`` (:func:`_hints`:
    a likelihood gain over the threshold that explains less than :data:`MIN_EXPLAINED` of
    the error, or that raises it on the channels it does not fit), the nominal model with
    ``b`` at its hint's fit is diagnosed over the other candidates that passed the
    likelihood threshold, screened from their fits of ``diags``, and the best added and both
    refitted; the first pair that qualifies is returned. A pair qualifies when it beats the
    nominal model of ``cprob`` as a swap must (:func:`_beats`) and explains at least
    :data:`MIN_EXPLAINED` of its systematic error, the rule one effect meets. Where none
    does, each hint is tried with the candidates tested below the likelihood threshold,
    each fitted jointly with it from its seeds: beside the effect it pairs with missing, a
    partner's fit can land in another basin and replay worse than the nominal (a soft
    torsion beside a missing payload went to its stiffness cap on one link, popup pair of
    seed 631), so neither its score nor its fit alone says anything; of the pairs that
    qualify there, the one of the largest BIC gain over the nominal is returned. Returns
    what :func:`_best_added` returns (fitted names in the order ``b``, the other), or
    ``None``; ``log`` gets a line per hint and pool."""
    e0 = cprob.error()[0]

    def tried(h: Suspect, pool: List[str], starts: Sequence[Diagnosis], how: str) -> Optional[Tuple[Any, float]]:
        what = (f"a pair with {h.effect} (a likelihood gain of {h.score:.3g} that explains {1 - h.error_after ** 2 / e0 ** 2 if e0 > 0 else 0:.0%} "
                f"of the error alone) and one of {', '.join(pool)}, {how}")
        base = _hint_base(prob, h, log, what)
        if base is None:
            return None
        out = _best_added(prob, run, base, [h.effect], {h.effect: list(h.fitted)}, pool, starts, threads, max_iter, progress, cprob, {},
                          log=log, what=what, joint=True)
        if out is None:
            return None
        e2 = out[2].error()[0]
        share = 1 - e2 ** 2 / e0 ** 2 if e0 > 0 else 0.0
        if share < MIN_EXPLAINED:
            _note(log, f"{what}: the pair {h.effect} + {out[0]} explains {share:.0%} of the systematic error ({e0:.3g} → {e2:.3g}), "
                       f"less than {MIN_EXPLAINED:.0%}; the model stands")
            return None
        gain = _bic_gain(out[2], out[4], cprob, {})
        _note(log, f"{what}: the pair {h.effect} + {out[0]} explains {share:.0%} of the systematic error ({e0:.3g} → {e2:.3g})")
        return out, gain

    def usable(s: Suspect, h: Suspect) -> bool:
        return s.effect != h.effect and s.tested and math.isfinite(s.score) and (effects is None or s.effect in effects)

    for h in hints:
        pool = [s.effect for s in d.suspects if usable(s, h) and s.score > SCORE_THRESHOLD]
        if not pool:
            _note(log, f"a pair with {h.effect}: no other candidate passed the likelihood threshold")
            continue
        got = tried(h, pool, diags, "each fitted with it from its seeds")
        if got is not None:
            return got[0]
    best, best_gain = None, -math.inf
    for h in hints:
        pool = [s.effect for s in d.suspects if usable(s, h) and not s.score > SCORE_THRESHOLD]
        if not pool:
            continue
        got = tried(h, pool, [], "below the likelihood threshold alone, each fitted jointly with it from its seeds")
        if got is not None and got[1] > best_gain:
            best, best_gain = got
    if best is not None:
        _note(log, f"the pair kept: {' + '.join(best[4])} (of the pairs with a partner below the threshold alone, the largest BIC gain "
                   f"over the nominal: {best_gain:.1f})")
    return best


def _unpredictable_top(d: Diagnosis) -> Optional[float]:
    """Where the replay of ``d``'s best-ranked tested candidate, an effect with play
    (:data:`PLAY_PARAMS`), is not predictable [s] (``None``: predictable, or another effect)."""
    top = next((s for s in d.suspects if s.tested), None)
    if top is None or top.effect not in PLAY_PARAMS:
        return None
    return top.unpredictable_after


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


def _try_richer_laws(cprob: ReplayProblem, added: List[str], fitted: Dict[str, List[str]], max_iter: int,
                     progress: Optional[Progress], log: Optional[List[str]] = None
                     ) -> Optional[Tuple[str, str, "Model", ReplayProblem, Dict[str, Dict[str, List[float]]], Dict[str, List[str]]]]:
    """The best richer law of an effect in the model of ``cprob`` (``added``, fitted names
    ``fitted``): each variant of :data:`VARIANTS` that only adds ``extra`` parameters (no
    other structure, not an alternative law) and is not in the model yet, refitted with
    every added effect from the current values (the extras at their neutral values).
    Returned (the effect, the variant's name, model, problem, intervals, fitted names) for
    the one that beats the current model (:func:`_beats`: the BIC gain passes the
    significance threshold and the held-out error falls) by the most; else ``None``."""
    best: Optional[Tuple[str, str, "Model", ReplayProblem, Dict[str, Dict[str, List[float]]], Dict[str, List[str]]]] = None
    todo = [(e, v) for e in added for v in VARIANTS.get(e, [])
            if v.get("extra") and "structure" not in v and not v.get("alternative")
            and set(v["extra"]) - set(fitted.get(e) or [p.name for p in fx.EFFECTS[e].fit_params])]
    for k, (e, var) in enumerate(todo):
        have = list(fitted.get(e) or [p.name for p in fx.EFFECTS[e].fit_params])
        nf = {x: list(v) for x, v in fitted.items()}
        nf[e] = have + [x for x in var["extra"] if x not in have]
        what = f"{e} with its {var['name']} law ({', '.join(x for x in var['extra'] if x not in have)} fitted), refitted with {' + '.join(added)}"
        if progress is not None:
            progress({"effect": f"{e} ({var['name']})", "done": k, "total": len(todo)})
        try:
            m, pb, ci = _refit_stable(cprob, added, nf, max_iter)
            pb = fit_unseen_motion(pb)
            ok, txt = _beats(pb, nf, cprob if best is None else best[3], fitted if best is None else best[5])
        except KeyboardInterrupt:
            raise
        except Exception as ex:  # noqa: BLE001 - the current model stands
            _note(log, f"{what}: failed ({type(ex).__name__}: {ex}); the model stands")
            continue
        _note(log, f"{what}: {'kept' if ok else 'not kept'} ({txt}; error {cprob.error()[0]:.3g} → {pb.error()[0]:.3g} noise units)")
        if ok:
            best = (e, str(var["name"]), m, pb, ci, nf)
    return best


def _law_rival(prob: ReplayProblem, run: MeasuredRun, before: Tuple[List[str], Dict[str, List[str]], ReplayProblem], cur: ReplayProblem,
               fitted_cur: Dict[str, List[str]], newest: str, effects: Optional[Sequence[str]], diags: Sequence[Diagnosis], threads: int,
               max_iter: int, progress: Optional[Progress],
               log: List[str]) -> Optional[Tuple[str, Tuple[str, "Model", ReplayProblem, Dict[str, Dict[str, List[float]]], Dict[str, List[str]], Diagnosis]]]:
    """The rival of adding ``newest`` to the model ``before`` (its effects, fitted names and
    problem; ``cur`` and ``fitted_cur``: the model with ``newest`` added and refitted): each
    effect of ``before`` fitted with a richer variant's extra parameters, set back at its
    base law with the best candidate for that model (:func:`_try_base_law`, from the
    candidates significant in some round, then every other one fitted jointly from its
    seeds). The first that also beats ``cur`` (:func:`_beats`) is returned with the effect
    reset; else ``None``. A line per try goes to ``log``."""
    added, fitted, bprob = before
    for e in added:
        if not _extras(e, fitted.get(e, [])):
            continue
        sig = [c for c in _significant_in(diags) if c not in added and (effects is None or c in effects)]
        rest = [c for c in (fx.EFFECT_NAMES if effects is None else effects) if c not in added and c not in sig]
        lw = _try_base_law(prob, run, bprob, e, added, fitted, sig, diags, threads, max_iter, progress, log, more=rest)
        if lw is None:
            continue
        ok, why = _beats(lw[2], lw[4], cur, fitted_cur)
        _note(log, f"{e} back at its base law with {lw[0]} against {' + '.join(fitted_cur)}, the model with {newest} added: "
                   f"{'kept' if ok else 'not kept'} ({why})")
        if ok:
            return e, lw
    return None


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


def _still_needed(prob: ReplayProblem, effect: str, params: Sequence[str]) -> bool:
    """Whether the model of ``prob`` needs ``effect``, by the rules that would have added it:
    a play narrower than the encoder resolves (:func:`unresolved_play`) or a torque limit the
    measured torque passes (:func:`limit_passed`) is not needed; nor
    is an effect without which the model is at its floor (:func:`model_at_floor`, with its
    own unseen motion); otherwise the likelihood ratio of the model with it against the
    model without it (its parameters neutral, nothing refitted, so the test keeps an
    effect when in doubt) must pass the significance threshold."""
    if unresolved_play(prob, effect, prob.model.effects_flat) or limit_passed(prob, effect, prob.model.effects_flat):
        return False
    try:
        without = fit_unseen_motion(prob.with_model(prob.model.without_effect(effect)))
        z_wo = without.residuals(without.nominal_simulation())
        e_wo, per_wo = without.error(z_wo)
    except Exception:  # noqa: BLE001 - if it cannot be removed, keep it
        return True
    if model_at_floor(without, e_wo, per_wo):
        return False
    z = prob.residuals(prob.nominal_simulation())
    lr, neff = est.log_ratio(prob, z_wo, z, prob.train)
    k = len(est.free_params(effect, list(params) or None))
    return lr - k * math.log(neff) > SCORE_THRESHOLD


def _refit_stable(prob: ReplayProblem, added: List[str], fitted: Dict[str, List[str]], max_iter: int) -> Tuple["Model", ReplayProblem, Dict[str, Dict[str, List[float]]]]:
    """:func:`_refit`, at half the step (up to :data:`STEP_HALVINGS` times) when the
    refitted model leaves the step's stability region (a stiffness the joint refit moved
    beyond what the candidate's step was chosen for, or a pose where a mode is faster)."""
    for k in range(STEP_HALVINGS + 1):
        try:
            out = _refit(prob, added, fitted, max_iter)
            out[1].error()  # the refitted model runs at this step
            return out
        except StepTooLargeError:
            if k == STEP_HALVINGS:
                raise
            prob = prob.with_model(prob.model.with_dt(0.5 * prob.model.dt))
    raise AssertionError("unreachable")


def _refit(prob: ReplayProblem, added: List[str], fitted: Dict[str, List[str]], max_iter: int) -> Tuple["Model", ReplayProblem, Dict[str, Dict[str, List[float]]]]:
    """Refit every fitted parameter of the added effects jointly, from their current values."""
    model = prob.model
    flat = model.effects_flat
    free = [pi for e in added for pi in est.free_params(e, fitted.get(e) or None) if not left_out(flat, *pi)]
    x0 = np.array([flat[p.offset + i] for p, i in free])
    out = est.fit(prob, flat, free, x0, max([max_iter] + [MIN_ITER.get(e, 0) for e in added]))
    new = model.with_effects({e: est.params_dict(e, out.flat) for e in added})
    nprob = prob.with_model(new)
    _, ne = est.log_ratio(prob, out.z, out.z, prob.train)
    half, _ = est.uncertainty(out, free, [f"{p.effect}.{p.name}[{i}]" for p, i in free], ne)
    ci: Dict[str, Dict[str, List[float]]] = {}
    for (p, i), h in zip(free, half):
        ci.setdefault(p.effect, {}).setdefault(p.name, [math.nan] * p.length)[i] = float(h)
    return new, nprob, ci
