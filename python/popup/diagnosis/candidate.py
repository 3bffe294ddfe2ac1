"""One candidate effect fitted to a run: its starts, step and horizons, its richer variants
and combinations, its joint refit with the effects already added, and the test that makes
it significant (the package docs)."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING, Any, Callable, Dict, List, Mapping, Optional, Sequence, Set, Tuple

import numpy as np

from .. import effects as fx
from .. import estimate as est
from ..problem import ReplayProblem
from ..unseen import fit_unseen_motion
from .rules import (AT_FLOOR, COORDINATE_SEEDS, COORDINATE_STEP, LIMIT_BEYOND_MIN, LIMIT_BEYOND_SHARE, LIMIT_MARGIN, LIMIT_PARAMS, MIN_EXPLAINED, MIN_ITER, PINNED_READINGS, PLAY_PARAMS, PREDICT_REL, PREDICT_TOL, PREDICT_WINDOW_S, PLAY_READINGS, RIGID_WHERE_ZERO, SCORE_THRESHOLD, SHORT_FIRST, SHORT_HORIZON_S,
                    STABILITY_MARGIN, STIFFEST, STRUCTURE, UNSEEN_ALTERNATIONS, VARIANTS)
from .results import Suspect, fmt_list

if TYPE_CHECKING:  # pragma: no cover
    from ..model import Model


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


def left_out(flat: np.ndarray, p: fx.EffectParam, i: int) -> bool:
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


def predictable_until(prob: ReplayProblem, name: str, flat: np.ndarray) -> Optional[float]:
    """The time [s] past which the replay of ``prob``'s model with ``flat`` is not predicted
    by its parameters: where the same model with ``name``'s play :data:`PREDICT_REL` wider
    moves the channels by more than :data:`PREDICT_TOL` noise units (RMS over a
    :data:`PREDICT_WINDOW_S` window). A link side rattling between compliant flanks is
    chaotic: its impacts' timing, and every channel after, depend on the play below any
    resolution, so past that time no model (the truth's own law included) can be judged by
    its free-run error there. ``None`` for an effect without play, or a replay predicted to
    the end (or not for its first fifth: too short to judge on)."""
    key = PLAY_PARAMS.get(name)
    if key is None:
        return None
    sl = fx.EFFECTS[name].params[key].slice
    twin = np.array(flat, dtype=float)
    if not np.any(twin[sl] > 0):
        return None
    twin[sl] = twin[sl] * (1.0 + PREDICT_REL)
    z = prob.residuals(prob.simulate(np.stack([np.asarray(flat, dtype=float), twin])))
    d = np.asarray(z[1] - z[0], dtype=float)
    t = np.asarray(prob.time, dtype=float)
    t0, t1 = float(t[0]), float(t[-1])
    k = np.floor((t - t0) / PREDICT_WINDOW_S).astype(int)
    for w in range(int(k.max()) + 1):
        sel = (k == w) & prob.used
        if not sel.any():
            continue
        x = d[sel]
        x = x[np.isfinite(x)]
        if x.size and math.sqrt(float(np.mean(x * x))) > PREDICT_TOL:
            tp = t0 + w * PREDICT_WINDOW_S
            if tp - t0 < 0.2 * (t1 - t0):
                return None
            return tp
    return None


def unresolved_play(prob: ReplayProblem, name: str, flat: np.ndarray) -> str:
    """Why effect ``name`` fitted to ``flat`` is below the encoder's resolution ("" if not)."""
    key = PLAY_PARAMS.get(name)
    if key is None:
        return ""
    w = prob.encoder_width
    gap = np.asarray(flat[fx.EFFECTS[name].params[key].slice], dtype=float)
    if not (np.any(w > 0) and np.all(gap < PLAY_READINGS * w)):
        return ""
    return (f"not significant: its {key} ({fmt_list(gap.tolist())} rad) is narrower than {PLAY_READINGS:g} encoder readings "
            f"({fmt_list(w.tolist())} rad each): a joint moving unseen inside its reading looks the same")


def unpinned_play(prob: ReplayProblem, name: str, flat: np.ndarray, half: Mapping[str, Sequence[float]]) -> str:
    """Why the play of effect ``name`` fitted to ``flat`` is not pinned down by the run ("" if
    it is): on no joint does it clear :data:`PINNED_READINGS` encoder readings by its 95 %
    half-width ``half[key][j]`` (``inf``: not identifiable; ``nan``: not fitted, that joint
    judged by its width alone, :data:`PLAY_READINGS`). A play whose interval holds zero is
    no finding, however much the likelihood gains: on a MuJoCo nominal run (200 Hz
    trapezoids, 12-bit encoders, noise × 0.32) a backlash with gaps of 0.15/0.52/0.28
    readings ± 0.13/5.1/11 readings and a free link-side inertia scored 1 099 and was added
    (0.70 → 0.54 noise units): tiny free spells at every reversal of the gear's torque
    stood in for what the replay misses there (benchmarks/README.md, session 59)."""
    key = PLAY_PARAMS.get(name)
    if key is None or key not in half:
        return ""
    w = prob.encoder_width
    gap = np.asarray(flat[fx.EFFECTS[name].params[key].slice], dtype=float)
    h = np.asarray(half[key], dtype=float)
    if not np.any(w > 0) or h.shape != gap.shape:
        return ""
    with np.errstate(invalid="ignore"):
        pinned = np.where(np.isnan(h), gap >= PLAY_READINGS * w, gap - h >= PINNED_READINGS * w)
    if pinned.any():
        return ""
    return (f"not significant: its {key} ({fmt_list(gap.tolist())} rad ± {fmt_list(h.tolist())}) is not pinned down by this run: on no joint "
            f"does it clear {PINNED_READINGS:g} encoder reading{'s' if PINNED_READINGS != 1 else ''} ({fmt_list(w.tolist())} rad each) by its 95 % interval, "
            f"what an encoder dithering between two readings can stand in for")


def limit_passed(prob: ReplayProblem, name: str, flat: np.ndarray) -> str:
    """Why effect ``name``'s limits fitted to ``flat`` are passed by the measured torques ("" if
    they are not, or ``name`` has none): on some joint, more than :data:`LIMIT_BEYOND_SHARE`
    of the measured samples at or above its limit (and at least :data:`LIMIT_BEYOND_MIN`) pass
    it by more than :data:`LIMIT_MARGIN` noise deviations. A torque limit leaves the
    measured torque level at it; a limit the measurement passes trims a model's peaks it
    does not explain."""
    key = LIMIT_PARAMS.get(name)
    if key is None:
        return ""
    lim = np.asarray(flat[fx.EFFECTS[name].params[key].slice], dtype=float)
    out = []
    for i, v in enumerate(lim):
        c = f"tau{i + 1}"
        if not math.isfinite(v) or c not in prob.channels:
            continue
        y = np.abs(prob.measured[prob.used, prob.channels.index(c)])
        y = y[np.isfinite(y)]
        sd = float(prob.noise.get(c, 0.0))
        beyond = int(np.sum(y > v + LIMIT_MARGIN * sd))
        near = int(np.sum(y >= v - LIMIT_MARGIN * sd))
        if beyond >= LIMIT_BEYOND_MIN and beyond > LIMIT_BEYOND_SHARE * near:
            out.append(f"{c} passes its {key} of {v:.4g} N·m by more than {LIMIT_MARGIN:g} noise deviations on {beyond} of the {near} samples "
                       f"at or above it (up to {float(np.max(y)):.4g} N·m)")
    if not out:
        return ""
    return "not significant: " + "; ".join(out) + ": a torque limit leaves the measured torque level at it, and this one only trims the model's peaks"


def silent_on(mask: np.ndarray, z0: np.ndarray, z1: np.ndarray) -> bool:
    """Whether residual ``z1`` equals ``z0`` on the samples of ``mask`` (an effect that does
    not act there, e.g. a torque limit reached only in the training blocks): the held-out
    samples can then neither confirm nor refute it."""
    a, b = np.asarray(z0)[mask], np.asarray(z1)[mask]
    if a.size == 0 or not np.array_equal(np.isnan(a), np.isnan(b)):
        return False
    ok = ~np.isnan(a)
    return bool(ok.any() and np.max(np.abs(a[ok] - b[ok])) <= 1e-9)


def share_where_it_acts(prob: ReplayProblem, name: str, free: List[Tuple[fx.EffectParam, int]], z0: np.ndarray, z1: np.ndarray,
                        explained: float) -> Tuple[float, Optional[List[str]], str]:
    """The share of the systematic error a candidate explains, for the share rule
    (:data:`MIN_EXPLAINED`), the channels it was measured on, and a note when isolated
    spikes were set aside.

    For a candidate whose own fitted parameters all act on some sensor rows only in encoder
    replay (:func:`popup.effects.acts_only_on`: friction and its clamp on the motor torques,
    a sensor group's delay) the share is taken on those channels ``A`` (it cannot explain an
    error of the others, whatever causes it), net of any error the fit adds on the others:
    ``1 − (E_A,after + max(E_rest,after − E_rest,before, 0)) / E_A,before`` with ``E`` the
    summed excess ``Σ_c (r_c² − 1)``. The others change only when earlier effects are
    refitted jointly with it (they move the arm); a refit that buys the torques with the
    IMUs is not credited for it. The share is also taken with the isolated spikes it leaves
    untouched on ``A`` set aside (samples that are :meth:`ReplayProblem.spike_mask` spikes
    of both residuals: impacts or glitches sharper than a sample, which no smooth law
    reproduces and the conclusion names on their own), provided the error left on ``A``
    without them is above :data:`AT_FLOOR`: a rattling gear's impact spikes on a motor
    torque, left by a fitted backlash, hid the friction beside it (benchmarks/README.md,
    session 43). The largest of these and ``explained`` (the share of the whole error) is
    returned with ``A``. For any other candidate: ``explained`` and ``None``; one that moves
    the arm acts on every channel, and a looser share for those lets stand-ins in
    (docs/effects.md, step 5)."""
    own = sorted({p.name for p, _ in free if p.effect == name})
    acts = None if prob.closed or not own else fx.acts_only_on(name, own, prob.channels)
    if not acts or len(acts) == len(prob.channels):
        return explained, None, ""
    idx = [prob.channels.index(c) for c in acts]
    rest = [j for j in range(len(prob.channels)) if j not in idx]

    def share(za: np.ndarray, zb: np.ndarray) -> Tuple[float, float]:
        ms0, _, _ = prob.channel_stats(za)
        ms1, _, _ = prob.channel_stats(zb)
        e0 = max(float(np.sum(ms0[idx])) - len(idx), 0.0)
        e1 = max(float(np.sum(ms1[idx])) - len(idx), 0.0) + max(float(np.sum(ms1[rest]) - np.sum(ms0[rest])), 0.0)
        return (1.0 - e1 / e0 if e0 > 0 and math.isfinite(e1) else 0.0), e0 / len(idx)

    on_acts = max(share(z0, z1)[0], explained)
    spiky = np.zeros(np.shape(z0), dtype=bool)
    spiky[:, idx] = prob.spike_mask(z0)[:, idx] & prob.spike_mask(z1)[:, idx]
    if not spiky.any():
        return on_acts, acts, ""
    a0, a1 = np.array(z0, dtype=float), np.array(z1, dtype=float)
    a0[spiky] = np.nan
    a1[spiky] = np.nan
    smooth, s0 = share(a0, a1)
    if not (smooth > on_acts and s0 > AT_FLOOR ** 2):
        return on_acts, acts, ""
    if not on_acts < MIN_EXPLAINED <= smooth:
        return smooth, acts, ""
    where = ", ".join(f"{prob.channels[j]} {int(spiky[:, j].sum())}" for j in idx if spiky[:, j].any())
    return smooth, acts, (f"it explains {100 * smooth:.0f} % of the systematic error on {', '.join(acts)}, the only channels it acts on "
                          f"in replay, with the isolated spikes it leaves set aside ({where} sample(s); {100 * on_acts:.0f} % with them, "
                          f"{100 * explained:.0f} % of the whole error): the share rule is applied there")


def rank_key(s: Suspect) -> Tuple[int, int, float]:
    return (0 if s.significant else 1, 0 if s.tested else 1, -s.score if math.isfinite(s.score) else math.inf)


class _Fitted:
    """A fitted candidate on its own problem (possibly another structure and step).

    ``z_null``: where earlier effects were refitted jointly with it, the residual of the
    model without it and those effects at their joint values (its null point). The joint
    fit's gain over the nominal (``z_base``) holds the refit's gain too: an earlier fit that
    sat off (a local optimum) is moved by any joint fit, and a candidate left at its neutral
    value took the credit (MuJoCo pair 661-010: air drag at cd ≈ 2e-12 scored 290 with a
    payload refitted beside it, benchmarks/README.md session 56). Both points are in the
    null model; where the null point is the better one, the candidate must pass every test
    against it as well, and its score is the lower of the two."""

    def __init__(self, name: str, variant: str, prob: ReplayProblem, z_base: np.ndarray, free: List[Tuple[fx.EffectParam, int]], out: est.FitOutcome,
                 k: Optional[int] = None, z_null: Optional[np.ndarray] = None) -> None:
        self.name, self.variant, self.prob, self.z_base, self.free, self.out = name, variant, prob, z_base, free, out
        self.k = len(free) if k is None else int(k)  # the candidate's own parameters (refitted earlier effects excluded)
        self.unpredictable_after: Optional[float] = None  # where its continuation's replay became unpredictable [s] (_continued)
        self.e1, self.per1 = prob.error(out.z)
        self.v1, _ = prob.error(out.z, prob.validation)
        t = self._against(z_base)
        self.score, self.neff, self.lr_val, self.e0, self.v0 = t["score"], t["neff"], t["lr_val"], t["e0"], t["v0"]
        self.explained, self.share, self.acts, self.spike_note, self.silent = t["explained"], t["share"], t["acts"], t["spike_note"], t["silent"]
        self.unresolved = unresolved_play(prob, name, out.flat) or limit_passed(prob, name, out.flat)
        passes = t["passes"]
        self.null_note = ""
        if z_null is not None and np.shape(z_null) == np.shape(out.z):
            gain, _ = est.log_ratio(prob, z_base, z_null, prob.train)
            if math.isfinite(gain) and gain > 0:
                u = self._against(z_null)
                refitted = ", ".join(sorted({p.effect for p, _ in free if p.effect != name}))
                self.null_note = (f"against {refitted} refitted alone (at this fit's values, {name} neutral: a log-likelihood gain of "
                                  f"{gain:.1f} without it) it scores {u['score']:.1f} and explains {100 * u['share']:.0f} % of what is left"
                                  + ("" if u["passes"] or not passes else ": not significant, the gain is the refit's"))
                self.score = min(self.score, u["score"])
                self.share = min(self.share, u["share"])
                passes = passes and u["passes"]
        # the play's interval is only worked out where it can decide (it costs a jackknife)
        self._uncertainty: Optional[Tuple[np.ndarray, Dict[str, Any]]] = None
        self.unpinned = ""
        if passes and not self.unresolved and name in PLAY_PARAMS:
            self.unpinned = unpinned_play(prob, name, out.flat, self._half())
        self.significant = bool(passes and not self.unresolved and not self.unpinned)

    def _names(self) -> List[str]:
        return [f"{p.name}[{i}]" if p.effect == self.name else f"{p.effect}.{p.name}[{i}]" for p, i in self.free]

    def _uncertain(self) -> Tuple[np.ndarray, Dict[str, Any]]:
        """:func:`estimate.uncertainty` of this fit (95 % half-widths and the identifiability report), worked out once."""
        if self._uncertainty is None:
            self._uncertainty = est.uncertainty(self.out, self.free, self._names(), self.neff)
        return self._uncertainty

    def _half(self) -> Dict[str, List[float]]:
        """95 % half-widths of this effect's own parameters, by name (``nan`` where not fitted)."""
        half, _ = self._uncertain()
        ci: Dict[str, List[float]] = {}
        for (p, i), h in zip(self.free, half):
            if p.effect == self.name:
                ci.setdefault(p.name, [math.nan] * p.length)[i] = float(h)
        return ci

    def _against(self, z0: np.ndarray) -> Dict[str, Any]:
        """The significance tests of this fit against the null residual ``z0``: the score
        (log-likelihood ratio less ln n_eff per own parameter), the held-out ratio and
        errors, the share explained (:func:`share_where_it_acts`), and whether the score,
        share and held-out rules all pass."""
        prob, z1 = self.prob, self.out.z
        lr, neff = est.log_ratio(prob, z0, z1, prob.train)
        score = lr - self.k * math.log(neff)
        lr_val, _ = est.log_ratio(prob, z0, z1, prob.validation)
        e0, _ = prob.error(z0)
        v0, _ = prob.error(z0, prob.validation)
        explained = 1.0 - (self.e1 / e0) ** 2 if e0 > 0 and math.isfinite(self.e1) else 0.0
        share, acts, spike_note = share_where_it_acts(prob, self.name, self.free, z0, z1, explained)
        silent = silent_on(prob.validation & prob.used, z0, z1)
        passes = bool(score > SCORE_THRESHOLD and share >= MIN_EXPLAINED and ((lr_val > 0 and self.v1 < v0) or silent))
        return dict(score=score, neff=neff, lr_val=lr_val, e0=e0, v0=v0, explained=explained, share=share, acts=acts, spike_note=spike_note,
                    silent=silent, passes=passes)

    def _share_note(self) -> str:
        if self.spike_note:
            return self.spike_note
        if self.acts is None or self.explained >= MIN_EXPLAINED or self.share < MIN_EXPLAINED:
            return ""
        return (f"it explains {100 * self.share:.0f} % of the systematic error on {', '.join(self.acts)}, the only channels it acts on "
                f"in replay ({100 * self.explained:.0f} % of the whole): the share rule is applied there")

    def suspect(self, ev: Dict[str, Any], nfev: int, message: str = "") -> Suspect:
        _, ident = self._uncertain()
        ci = self._half()
        return Suspect(
            self.name, self.significant, float(self.score), est.params_dict(self.name, self.out.flat), ci, self.e0, self.e1, self.per1, ev,
            n_eff=self.neff, n_rollouts=nfev, tested=True, explained=self.explained,
            message="; ".join(m for m in (self.unresolved, self.unpinned, "not checked on the held-out samples: it does not act there" if self.silent else "", self._share_note(),
                                          self.null_note, message) if m),
            validation_before=self.v0, validation_after=self.v1, validation_lr=self.lr_val, variant=self.variant, horizon=self.prob.horizon, unpredictable_after=self.unpredictable_after,
            identifiability=ident, dt=float(self.prob.model.dt), fitted=sorted({p.name for p, _ in self.free if p.effect == self.name}),
            refitted={e: est.params_dict(e, self.out.flat) for e in sorted({p.effect for p, _ in self.free if p.effect != self.name})},
        )


def _fit_candidate(prob: ReplayProblem, name: str, structure: Optional[Dict[str, Any]], only: Optional[Sequence[str]], start: Optional[Dict[str, List[float]]],
                   extra_seeds: Optional[List[Dict[str, Any]]], max_iter: int, variant: str = "",
                   also: Optional[List[Tuple[fx.EffectParam, int]]] = None, stiffest: Optional[Dict[str, Any]] = None,
                   dt: Optional[float] = None, seeds: bool = True, base: Optional[ReplayProblem] = None, k_extra: int = 0,
                   shared: Optional[Sequence[str]] = None) -> Tuple[_Fitted, str]:
    """Fit one candidate (``structure``, the names ``only`` or every fitted one) from
    ``start`` and the effect's seeds (``seeds=False``: from ``start`` alone), with the
    entries of ``also`` refitted jointly; ``dt``: the step to use (default: from the
    structure's stability limit at ``stiffest``); ``base``: the problem (same run and
    model, another unseen motion) whose nominal replay the fit is scored against (default
    ``prob``), with ``k_extra`` more parameters counted than those fitted here; ``shared``:
    parameters also fitted as one value on every entry, for one more start (the variant's
    ``shared``)."""
    model = prob.model
    m = model
    note = ""
    ref = prob if base is None else base
    pb, z_base = prob, ref.residuals(ref.nominal_simulation())
    nb = ref  # the nominal's problem, at the candidate's step
    if structure is not None:
        m = model.with_effect(name, **structure)
        if dt is None:
            check = m.with_effect(name, **(stiffest if stiffest is not None else STIFFEST.get(name, {})))
            dt = _step_for(prob, m, check)
        if dt < model.dt * (1 - 1e-12):
            m = m.with_dt(dt)
            pb = prob.with_model(model.with_dt(dt))
            nb = ref.with_model(model.with_dt(dt))
            z_base = nb.residuals(nb.nominal_simulation())
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
    rigid = RIGID_WHERE_ZERO.get(name)
    if rigid is not None:  # a joint whose law is the rigid one there fits none of the others
        zero = {i for i, v in enumerate(flat[fx.EFFECTS[name].params[rigid[0]].slice]) if v == 0.0}
        free = [(q, i) for q, i in free if not (q.name in rigid[1] and i in zero)]
    x0 = np.array([flat[q.offset + i] for q, i in free]) if start else _x0(p, free, flat)
    cands = _candidates(name, p, free, flat, x0, extra_seeds) if seeds else [x0]
    # the effects added in earlier rounds are refitted with the candidate (forward
    # selection with refit: an earlier fit biased by this effect's absence is corrected)
    others = [pi for pi in (also or []) if pi[0].effect != name]
    cur = np.array([flat[q.offset + i] for q, i in others])
    cands = [np.concatenate([c, cur]) for c in cands]
    free_all = free + others
    iters = max(max_iter, MIN_ITER.get(name, 0))
    unpredictable: Optional[float] = None  # where a fit of the continuation replays unpredictably [s]
    if name in SHORT_FIRST and seeds:
        # a lightly damped response (or a link side crossing its gap) drifts out of phase
        # over a long run, which makes the full-run objective a needle around the truth:
        # fit on a short horizon first (a wide basin), then on horizons doubled in turn,
        # each from the last optimum (continuation), and offer the result as one more start
        tie = _shared_groups(free_all, name, shared)
        starts = list(cands)
        xh, unpredictable = _continued(p, name, free_all, flat, starts, iters, check=not others)
        if xh is not None:
            cands.append(xh)
            if tie:
                # the same with the ``shared`` parameters one value on every entry (half the
                # unknowns): per entry, gaps and flanks trade off and the fit ends in a basin
                # of its own; the shared optimum is one more start for the per-entry fit
                xt, ut = _continued(p, name, free_all, flat, starts, iters, tie, check=not others)
                if xt is not None:
                    cands.append(xt)
                    if ut is not None:
                        unpredictable = ut if unpredictable is None else min(unpredictable, ut)
    xs, _ = est.best_start(p, free_all, flat, cands)
    out = est.fit(p, flat, free_all, xs, iters)
    z_null = None
    if others:
        nf = np.array(nb.model.effects_flat, dtype=float)
        ix = [q.offset + i for q, i in others]
        nf[ix] = out.flat[ix]
        if not np.array_equal(nf, nb.model.effects_flat):
            z_null = nb.residuals(nb.simulate(nf))[0]
    fitted = _Fitted(name, variant, p, z_base, free_all, out, k=len(free) + k_extra, z_null=z_null)
    fitted.unpredictable_after = unpredictable
    return fitted, note


def _shared_groups(free: List[Tuple[fx.EffectParam, int]], name: str, shared: Optional[Sequence[str]]) -> List[List[int]]:
    """Positions in ``free`` of each parameter of ``name`` in ``shared`` (one group per
    parameter fitted on two or more entries), for :func:`estimate.fit`'s ``tie``."""
    out = [[j for j, (q, _) in enumerate(free) if q.effect == name and q.name == n] for n in (shared or [])]
    return [g for g in out if len(g) > 1]


def _continued(p: ReplayProblem, name: str, free_all: List[Tuple[fx.EffectParam, int]], flat: np.ndarray, cands: List[np.ndarray],
               iters: int, tie: Optional[List[List[int]]] = None, check: bool = True) -> Tuple[Optional[np.ndarray], Optional[float]]:
    """The best of ``cands`` on a short horizon, fitted there and on horizons doubled in
    turn, each from the last optimum (``tie``: with those groups fitted as one value); and
    the first time [s] past which a fit of the continuation replays unpredictably
    (:func:`predictable_until`, checked before each doubling, kept where the next horizon
    reaches it; ``None``: none did, or ``check`` is false: only a candidate fitted with no
    effect beside it is checked, the horizon step reads round 1 only). ``(None, None)`` where
    the run is no longer than the short horizon. The check changes no fit."""
    t0, t1 = float(p.time[0]), float(p.time[-1])
    h = max(SHORT_HORIZON_S, 0.2 * (t1 - t0))
    ph = p.with_horizon(t0 + h)
    if ph is p:
        return None, None
    if tie:
        cands = [est.tied(free_all, c, tie) for c in cands]
    xh, _ = est.best_start(ph, free_all, flat, cands)
    unresolved: Optional[List[int]] = None
    if name in COORDINATE_SEEDS:
        xh, unresolved = _coordinate_seeds(ph, name, free_all, flat, xh, _untied(free_all, name, tie))
    xh = est.fit(ph, flat, free_all, xh, iters, tie=tie).x
    unpredictable: Optional[float] = None
    while True:
        if unpredictable is None and check:
            hz = _horizon_of(p, name, free_all, flat, xh)
            if hz is not None and hz < min(t0 + 2.0 * h, t1):
                unpredictable = hz
        if not 2.0 * h < t1 - t0:
            break
        h *= 2.0
        ph = p.with_horizon(t0 + h)
        if unresolved:
            # a joint whose gap the shorter horizon could not tell (it had not
            # crossed it yet) is swept again where it does: the local fit alone
            # cannot leave the needle it was left in
            xh, unresolved = _coordinate_seeds(ph, name, free_all, flat, xh, unresolved)
        xh = est.fit(ph, flat, free_all, xh, iters, mask=p.train[p.time <= t0 + h], tie=tie).x
    if unresolved:
        xh, _ = _coordinate_seeds(p, name, free_all, flat, xh, unresolved)
    return xh, unpredictable


def _horizon_of(p: ReplayProblem, name: str, free: List[Tuple[fx.EffectParam, int]], flat: np.ndarray, x: np.ndarray) -> Optional[float]:
    """:func:`predictable_until` of ``p``'s model with ``free`` set to ``x`` (``None`` on a
    problem already cut at its horizon: it is judged there once)."""
    if p.horizon is not None or name not in PLAY_PARAMS:
        return None
    f = np.asarray(flat, dtype=float).copy()
    f[[q.offset + i for q, i in free]] = x
    return predictable_until(p, name, f)


def _untied(free: List[Tuple[fx.EffectParam, int]], name: str, tie: Optional[List[List[int]]]) -> Optional[List[int]]:
    """Positions of ``name``'s entries in ``free`` outside every group of ``tie`` (``None``:
    every entry, where nothing is tied): a sweep entry by entry would untie a group."""
    if not tie:
        return None
    tied = {j for g in tie for j in g}
    return [j for j, (q, _) in enumerate(free) if q.effect == name and j not in tied]


def _coordinate_seeds(prob: ReplayProblem, name: str, free: List[Tuple[fx.EffectParam, int]], flat: np.ndarray, x: np.ndarray,
                      entries: Optional[Sequence[int]] = None) -> Tuple[np.ndarray, List[int]]:
    """One sweep over the entries of ``name``'s seeded parameters (or the indices
    ``entries`` of ``free``): each entry in turn set to every value of a fine log grid over
    its seeds' range (the others at the best so far), the best kept (one batched rollout
    per entry). Seeds that move every joint together miss unequal gaps. Returns the best
    and the entries the sweep did not resolve: over their whole grid the training
    likelihood moved by less than :data:`SCORE_THRESHOLD` (a joint that has not crossed its
    gap within the horizon)."""
    seen: Dict[str, List[float]] = {}
    for seed in est.SEEDS.get(name, []):
        for k, v in seed.items():
            seen.setdefault(k, []).extend(np.atleast_1d(np.asarray(v, dtype=float)).tolist())
    # a log grid COORDINATE_STEP apart over the seeds' range: a link side floating in its
    # gap makes the objective a needle a few % wide in that gap, even on the short horizon
    grid = {k: np.exp(np.arange(math.log(min(v)), math.log(max(v)) + 1e-9, math.log(COORDINATE_STEP))).tolist() for k, v in seen.items() if min(v) > 0}
    x = np.asarray(x, dtype=float).copy()
    unresolved: List[int] = []
    for j, (q, _) in enumerate(free):
        if q.effect != name or q.name not in grid or (entries is not None and j not in entries):
            continue
        cands = [x]
        for v in grid[q.name]:
            c = x.copy()
            c[j] = min(max(v, q.lower), q.upper)
            cands.append(c)
        x, vals = est.best_start(prob, free, flat, cands)
        ok = np.asarray(vals, dtype=float)
        ok = ok[np.isfinite(ok)]
        if ok.size == 0 or float(ok.max() - ok.min()) < SCORE_THRESHOLD:
            unresolved.append(j)
    return x, unresolved


def try_effect(prob: ReplayProblem, name: str, ev: Dict[str, Any], max_iter: int, also: Optional[List[Tuple[fx.EffectParam, int]]] = None,
                prior: Optional[Mapping[str, Sequence[float]]] = None) -> Suspect:
    """Fit ``name`` from its seeds (and ``prior``, its fit of an earlier round, as one more
    start), then its variants; the best as a :class:`Suspect`."""
    n0 = prob.nfev
    try:
        fitted, note = _fit_candidate(prob, name, STRUCTURE.get(name), None, None, [dict(prior)] if prior else None, max_iter, also=also)
    except Exception as e:  # noqa: BLE001 - one effect failing must not stop the ranking
        return Suspect(name, False, -math.inf, {}, {}, math.nan, math.nan, {}, ev, tested=False,
                       message=f"not tested: {type(e).__name__}: {e}")
    best = fitted
    best_var: Optional[Dict[str, Any]] = None
    tried: List[Tuple[Dict[str, Any], _Fitted]] = []
    notes = [note] if note else []
    base_params = est.params_dict(name, fitted.out.flat)
    # a base law the likelihood favours may fail the share or the held-out test only for what
    # a refinement adds (MuJoCo seed 628's backlash: the gaps alone explained 35 % of the
    # error, popup's law with the true link-side inertia 49 %), so its variants are tried
    promising = fitted.significant or (fitted.score > SCORE_THRESHOLD and not fitted.unresolved)
    for var in VARIANTS.get(name, []):
        if not (promising or var.get("alternative") or var.get("always")) or (var.get("on_horizon") and prob.horizon is None):
            continue
        try:
            struct = dict(STRUCTURE.get(name) or {})
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
                     for k in STIFFEST.get(name, {}) if k in base_params} if var.get("structure") else None
            if var.get("structure") and stiff:
                start = {k: base_params[k] for k in stiff}
            if var.get("stiffest"):
                stiff = dict(var["stiffest"])
            vf, _ = _fit_candidate(prob, name, struct or None, only, start, var.get("seeds"), max_iter, variant=str(var["name"]), also=also, stiffest=stiff,
                                   shared=var.get("shared"))
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
                         + "".join(f"; {m}" for m in (vf.unresolved, vf.unpinned) if m) + ")")
    if best_var is not None:
        best = _try_combined(prob, name, best, best_var, tried, max_iter, also, notes)
        best = _rigid_where_no_play(prob, name, best, max_iter, also, notes)
    hints = [f.unpredictable_after for f in [fitted] + [vf for _, vf in tried] if f.unpredictable_after is not None]
    s = best.suspect(ev, prob.nfev - n0, "; ".join(notes))
    return replace(s, unpredictable_after=min(hints)) if hints else s


def _rigid_where_no_play(prob: ReplayProblem, name: str, best: _Fitted, max_iter: int, also: Optional[List[Tuple[fx.EffectParam, int]]],
                         notes: List[str]) -> _Fitted:
    """``best`` refitted from its own values with the rigid law (:data:`RIGID_WHERE_ZERO`) on
    the joints where it is not rigid but its play (:data:`PLAY_PARAMS`) vanished, below
    :data:`PLAY_READINGS` encoder readings; kept where the likelihood prefers it (BIC, with
    the parameters it no longer fits). A joint without play, given compliant flanks, is a
    spring to a link-side inertia it never had, and a fit that put it there stays (MuJoCo's
    soft gear on joint 2: joints 1 and 3 ended with gaps of 1e-10 and 2e-8 rad on flanks at
    the 1e5 N·m/rad bound, 41 noise units where the truth replays at 0.17)."""
    rigid, key = RIGID_WHERE_ZERO.get(name), PLAY_PARAMS.get(name)
    if rigid is None or key is None:
        return best
    p = est.params_dict(name, best.out.flat)
    soft = np.asarray(p[rigid[0]], dtype=float) != 0.0
    if not soft.any():
        return best
    off = soft & (np.asarray(p[key], dtype=float) < PLAY_READINGS * np.asarray(prob.encoder_width, dtype=float))
    if not off.any() or off.all():
        return best
    fitted = sorted({q.name for q, _ in best.free if q.effect == name})
    start = {n: [0.0 if n in rigid[1] and off[i] else x for i, x in enumerate(p[n])] for n in fitted}
    struct = {**dict(STRUCTURE.get(name) or {}), **dict((_variant_named(name, best.variant) or {}).get("structure") or {})}
    joints = ", ".join(str(i + 1) for i in np.flatnonzero(off))
    try:
        f, _ = _fit_candidate(prob, name, struct, fitted, start, None, max_iter, variant=best.variant, also=also, dt=float(best.prob.model.dt), seeds=False)
    except Exception as e:  # noqa: BLE001 - the fit found stands
        notes.append(f"the rigid law on joint(s) {joints} (no play there) not tested: {type(e).__name__}: {e}")
        return best
    gain = _gain(f, best)
    kept = f.significant and gain > 0.0
    notes.append(f"the rigid law on joint(s) {joints} (no play there) {'preferred' if kept else 'not preferred'} (score {f.score:.1f} vs {best.score:.1f}; BIC gain over it {gain:.1f})")
    return f if kept else best


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
    if a.get("shared") or b.get("shared"):
        out["shared"] = sorted(set(a.get("shared") or []) | set(b.get("shared") or []))
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
            struct = {**dict(STRUCTURE.get(name) or {}), **cv["structure"]}
            fitted_names = {p.name for p, _ in best.free if p.effect == name}
            only = sorted(fitted_names | set(cv["extra"]))
            # ``best``'s values of what it fitted; what the other variant adds starts from the
            # structure's value (``best``'s own is its law's neutral one: contact_k = 0, the
            # rigid flanks, is no start for a stiffness fitted as its logarithm)
            start = {k: v for k, v in params.items() if k in fitted_names}
            stiff = ({k: [min(1.5 * x, est.BOUNDS.get((name, k), (0.0, math.inf))[1]) for x in params[k]]
                      for k in STIFFEST.get(name, {}) if k in params} if cv["structure"] else None) or None
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
                                   seeds=bool(set(var.get("extra") or []) - own_extra), shared=cv.get("shared"))
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


def screen_fit(prob: ReplayProblem, name: str, ev: Dict[str, Any], max_iter: int, start: Mapping[str, Sequence[float]]) -> Suspect:
    """``name`` at its base law fitted from ``start`` alone (its fit of an earlier round): the
    cheap screen of :func:`diagnose`'s ``screen``."""
    n0 = prob.nfev
    base = {p.name for p in fx.EFFECTS[name].fit_params}
    st = {k: list(v) for k, v in start.items() if k in base}
    try:
        fitted, note = _fit_candidate(prob, name, STRUCTURE.get(name), None, st or None, None, max_iter, seeds=False)
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


def refit_jointly(prob: ReplayProblem, s: Suspect, ev: Dict[str, Any], max_iter: int, also: List[Tuple[fx.EffectParam, int]],
                   prior: Optional[Mapping[str, Sequence[float]]] = None) -> Suspect:
    """The screened candidate ``s`` (fitted with the earlier effects held) refitted with
    them (``also``): its law (variant), step and fitted names, from its screened optimum,
    and also from ``prior`` (its fit of an earlier round; the better of the two is kept).
    With the earlier effects held, a candidate they absorbed screens at its neutral value
    (a payload at +0.0002 kg beside a torsion fitted without it), a point the joint fit
    does not leave; its fit from the round before is in the joint basin."""
    n0 = prob.nfev
    var = _variant_named(s.effect, s.variant)
    struct = dict(STRUCTURE.get(s.effect) or {})
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
    j = fitted.suspect(ev, s.n_rollouts + prob.nfev - n0)
    if j.score >= s.score:
        own = j.message.split("; ") if j.message else []  # the joint fit's own notes (its null point's among them), then the screen's
        j.message = "; ".join(x for x in [*own, *[m for m in s.message.split("; ") if m not in own], f"refitted with {', '.join(sorted({p.effect for p, _ in also}))} (score {s.score:.1f} → {j.score:.1f})"] if x)
        return j
    s.n_rollouts = j.n_rollouts
    s.message = "; ".join(x for x in (s.message, f"joint refit scored lower ({j.score:.1f}): the screened fit is kept") if x)
    return s


def _on_motion(prob: ReplayProblem, s: Suspect, cur: Suspect, c: np.ndarray, q: np.ndarray, seeds: bool, ev: Dict[str, Any], max_iter: int) -> Suspect:
    """``cur`` (a fit of candidate ``s``) refitted on ``prob``'s replay with the unseen servo
    motion ``(c, q)`` (:meth:`ReplayProblem.with_unseen_motion`), from its fit (``seeds``:
    and its effect's seeds), at its law, step and fitted names; scored against ``prob``'s
    nominal replay, each joint compliance nonzero beyond ``prob``'s counted as a fitted
    parameter. The result carries that motion (:attr:`Suspect.unseen`)."""
    var = _variant_named(s.effect, s.variant)
    struct = dict(STRUCTURE.get(s.effect) or {})
    struct.update((var or {}).get("structure") or {})
    n_base = int(np.count_nonzero(prob.compliance))
    pu = prob.with_unseen_motion(c, q)
    start = {k: list(cur.params[k]) for k in cur.fitted if k in cur.params}
    f, _ = _fit_candidate(pu, s.effect, struct or None, list(cur.fitted) or None, start, None, max_iter, variant=s.variant,
                          dt=cur.dt, seeds=seeds, base=prob, k_extra=max(0, int(np.count_nonzero(c)) - n_base))
    j = f.suspect(ev, 0, s.message)
    j.unseen = (np.asarray(c, dtype=float).copy(), np.asarray(q, dtype=float).copy())
    if np.any(c != 0):
        what = "refitted with the unseen servo motion of its own model (compliance " + "/".join(f"{v:.2g}" for v in c) + " rad/(N·m); "
    else:
        what = "refitted on the replay without unseen servo motion ("
    j.message = "; ".join(x for x in (s.message, f"{what}score {s.score:.1f} → {j.score:.1f})") if x)
    return j


def _no_motion(prob: ReplayProblem) -> Tuple[np.ndarray, np.ndarray]:
    return np.zeros(3), np.zeros_like(np.asarray(prob.q_corr, dtype=float))


def screen_without_unseen(prob: ReplayProblem, s: Suspect, ev: Dict[str, Any], max_iter: int) -> Suspect:
    """Candidate ``s`` (fitted on ``prob``, whose replay holds the unseen servo motion the
    nominal model gives, :mod:`popup.unseen`) refitted from its fit alone on the replay
    without any motion (the readings as smoothed), scored as in :func:`_on_motion`; that
    fit where it ranks above ``s`` (:func:`rank_key`), else ``s`` as it is. Where ``prob``
    holds no motion, or ``s`` was not tested, ``s`` as it is.

    Why: the motion fitted on the nominal model takes part of a missing softening, and a
    fit beside it can stay in its basin at any rank, not only among the leading candidates
    :func:`refit_with_own_unseen` takes. On a popup-engine run with a near-threshold
    torsion of link 1 (k_t 12 110 N·m/rad, seed 443), the nominal's compliance of 1.5e-6
    rad/(N·m) on joint 1 sent every torsion fit to its stiffness cap, worse than the
    nominal (score −888, 9th); from that fit, on the replay without the motion, one local
    fit reaches k_t 12 117 and a score of 1 711, the first."""
    if not s.tested or not math.isfinite(s.score) or not np.count_nonzero(prob.compliance):
        return s
    n0 = prob.nfev
    try:
        j = _on_motion(prob, s, s, *_no_motion(prob), False, ev, max_iter)
    except Exception as e:  # noqa: BLE001 - the fit on the round's replay stands
        return replace(s, n_rollouts=s.n_rollouts + prob.nfev - n0,
                       message="; ".join(x for x in (s.message, f"refit on the replay without unseen motion failed: {type(e).__name__}: {e}") if x))
    best = j if rank_key(j) < rank_key(s) else s
    return replace(best, n_rollouts=s.n_rollouts + prob.nfev - n0)


def refit_with_own_unseen(prob: ReplayProblem, s: Suspect, ev: Dict[str, Any], max_iter: int) -> Suspect:
    """Candidate ``s`` (fitted on ``prob``, whose replay holds the unseen servo motion the
    nominal model gives, :mod:`popup.unseen`, or on the motion ``s.unseen`` where
    :func:`screen_without_unseen` set it) refitted on the unseen motion its own model
    gives, along two paths: from ``s`` (that motion fitted to the model with ``s``, ``s``
    refitted on it from its fit) and, where ``prob`` holds a motion, from none (``s``
    refitted on the replay of the readings as smoothed, from its fit and its effect's
    seeds, then the motion fitted to that model). Each path alternates up to
    :data:`UNSEEN_ALTERNATIONS` times while it ranks better (:func:`rank_key`). Every fit is
    scored against ``prob``'s nominal replay, each joint compliance nonzero beyond
    ``prob``'s counted as a fitted parameter, so the scores stay comparable with the other
    candidates'. The best fit that ranks above ``s`` is returned (never losing its
    significance); one refitted carries its motion (:attr:`Suspect.unseen`); ``s`` itself
    is never changed.

    Why: the unseen motion is a servo compliance in series with the links' bending, so on
    the nominal model it takes part of any missing softening. On a popup-engine run with a
    near-threshold wrinkling (rigid joints), the compliance fitted on the nominal model
    pulled the wrinkling fit to the bound of its moment (0.52 noise units, where the truth
    replays at 0.045 without any compliance) and a payload ranked first. Why the second
    path: refitted from the nominal's compliance, a fit stays in that compliance's basin.
    On popup-engine runs with a 0.4 g payload and a near-threshold wrinkling (seed 463),
    the truth replays at 0.74 and 0.089 noise units without any motion but at 3.4 and 0.73
    on the nominal's; from there the payload and the wrinkling fits each reached only about
    the other's error, and the other ranked first."""
    if not s.tested or not math.isfinite(s.score):
        return s
    n0 = prob.nfev
    notes: List[str] = []

    def alternate(cur: Suspect, c: np.ndarray, q: np.ndarray) -> Suspect:
        for _ in range(UNSEEN_ALTERNATIONS):
            try:
                own = fit_unseen_motion(prob.with_model(cur.apply(prob.model)))
                if np.array_equal(own.compliance, c) and np.array_equal(own.q_corr, q):
                    break
                c, q = np.asarray(own.compliance, dtype=float), np.asarray(own.q_corr, dtype=float)
                j = _on_motion(prob, s, cur, c, q, False, ev, max_iter)
            except Exception as e:  # noqa: BLE001 - the path's last fit stands
                notes.append(f"refit with its own unseen motion failed: {type(e).__name__}: {e}")
                break
            if not rank_key(j) < rank_key(cur):
                break
            cur = j
        return cur

    best = s
    c0, q0 = s.unseen if s.unseen is not None else (np.asarray(prob.compliance, dtype=float), np.asarray(prob.q_corr, dtype=float))
    starts: List[Callable[[], Suspect]] = [lambda: alternate(s, c0, q0)]
    if np.count_nonzero(prob.compliance):
        zc, zq = _no_motion(prob)
        starts.append(lambda: alternate(_on_motion(prob, s, s, zc, zq, True, ev, max_iter), zc, zq))
    for run in starts:
        try:
            j = run()
        except Exception as e:  # noqa: BLE001 - the fit on the round's replay stands
            notes.append(f"refit on the replay without unseen motion failed: {type(e).__name__}: {e}")
            continue
        if rank_key(j) < rank_key(best):
            best = j
    return replace(best, n_rollouts=s.n_rollouts + prob.nfev - n0, message="; ".join(x for x in (best.message, *notes) if x))
