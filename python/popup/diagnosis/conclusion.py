"""The sentences of a diagnosis: one round's conclusion and the whole history's (what was
added, how far the error fell, what is left and where)."""

from __future__ import annotations

import math
from typing import Any, Dict, List, Mapping, Optional, Tuple

from ..problem import SPIKE_SIGMA, ReplayProblem
from ..results import UNITS
from .rules import AT_FLOOR, FLOOR_MULTIPLE, LINE_SHARE, OFFSET_SHARE, SCORE_THRESHOLD, SPIKE_SHARE, floor_words
from .results import Diagnosis, History, Suspect, final_problem, fmt_params, step_at_floor


def tied_with_best(d: Diagnosis) -> List[Suspect]:
    """The significant candidates of ``d`` other than its best whose score is within
    :data:`SCORE_THRESHOLD` of the best's: both scores are BIC gains over the same nominal
    model, so their difference is the evidence for the best over each, and below the
    threshold the run does not tell them apart."""
    b = d.best
    if b is None or not math.isfinite(b.score):
        return []
    return [s for s in d.significant if s is not b and s.effect != b.effect and math.isfinite(s.score) and b.score - s.score < SCORE_THRESHOLD]


def _tie_text(b: Suspect, ties: List[Suspect]) -> str:
    return ("this run cannot tell it from " + ", ".join(
        f"{s.effect} (score {s.score:.5g} vs {b.score:.5g}, less than the threshold {SCORE_THRESHOLD:g} apart; error after "
        f"{s.error_after:.3g} vs {b.error_after:.3g} noise units)" for s in ties)
        + ": a run that excites them differently would separate them")


def round_conclusion(d: Diagnosis) -> str:
    b = d.best
    parts = []
    if b is not None:
        parts.append(
            f"{b.effect}{f' ({b.variant})' if b.variant else ''} explains the most: adding it is predicted to take the systematic error from "
            f"{b.error_before:.3g} to {b.error_after:.3g} noise units ({100 * b.explained:.0f} % of it; held out {b.validation_before:.3g} → {b.validation_after:.3g})"
        )
        ties = tied_with_best(d)
        if ties:
            parts.append(_tie_text(b, ties))
    elif d.nominal_error <= AT_FLOOR:
        parts.append(f"at the noise floor (systematic error {d.nominal_error:.3g} noise units): no library effect is significant")
    elif d.model_at_floor:
        parts.append(f"at its floor, the noise and the encoder's resolution (systematic error {d.nominal_error:.3g} noise units, "
                     f"{d.floor_error:.3g} above the floor" + (f", {d.floor_error_upper:.3g} above its prediction bound" if d.floor_error_upper < d.floor_error - 5e-4 else "")
                     + f"; {_encoder_text(d.encoder_floor)}): no library effect is significant")
    else:
        parts.append(f"no library effect explains the systematic error of {d.nominal_error:.3g} noise units: it is not explained by the library ({_where(d)})")
    if d.untested and not d.model_at_floor:
        parts.append("the ranking is incomplete: " + "; ".join(f"{s.effect} {s.message}" for s in d.untested))
    return "; ".join(parts)


def _where(d: Diagnosis, per: Optional[Dict[str, float]] = None) -> str:
    """Where the unexplained error sits: channels, time window, frequency band, constant
    offsets and isolated spikes."""
    per = d.channel_error if per is None else per
    worst = sorted(per.items(), key=lambda kv: -kv[1])[:3]
    txt = "worst channels " + ", ".join(f"{c} {v:.2g}× noise" for c, v in worst)
    prob = d.problem
    sp: Dict[str, Dict] = {}
    off: Dict[str, Dict[str, float]] = {}
    if prob is not None:
        try:
            z = prob.residuals(prob.nominal_simulation())
            sp, off = prob.spikes(z), ({} if prob.fit_offsets else prob.offsets(z))
        except Exception:  # noqa: BLE001 - a missing view must not hide the finding
            pass
    const = sorted(((c, v) for c, v in off.items() if v["share"] >= OFFSET_SHARE and per.get(c, 0.0) > FLOOR_MULTIPLE),
                   key=lambda kv: -per.get(kv[0], 0.0))
    cmp = d.comparison
    try:
        w = cmp.windows.sort_values("rank").iloc[0]
        txt += f"; worst window t = {float(w['t_start']):.3g}–{float(w['t_end']):.3g} s ({100 * float(w['error_share']):.0f} % of the error)"
        c0 = worst[0][0]
        band = cmp.spectrum.loc[c0]
        line = float(band.get("line_fraction", math.nan))
        if c0 in dict(const):
            pass
        elif math.isfinite(line) and line >= LINE_SHARE:
            txt += (f"; {c0}'s residual is concentrated in a line at {float(band['peak_hz']):.4g} Hz ({100 * line:.0f} % of its power "
                    f"within ±{float(band['line_halfwidth_hz']):.2g} Hz)")
        elif str(band["dominant_band"]):
            txt += f"; {c0}'s residual mostly in {band['dominant_band']} (peak {float(band['peak_hz']):.4g} Hz)"
        txt += _other_lines(cmp.spectrum, per, c0, dict(const))
    except Exception:  # noqa: BLE001 - a missing view must not hide the finding
        pass
    if const:
        txt += ("; constant offsets (a sensor bias or a calibration offset, which no library effect is: --offsets fits them): " + ", ".join(
            f"{c} reads {v['offset']:+.3g} {UNITS.get(c, '')} off the model ({-v['z_mean']:+.2g} noise σ, "
            f"{100 * v['share']:.0f} % of its excess)" for c, v in const[:4]) + (f" and {len(const) - 4} more" if len(const) > 4 else ""))
    big = sorted(((c, v) for c, v in sp.items() if v["share"] >= SPIKE_SHARE and per.get(c, 0.0) > FLOOR_MULTIPLE), key=lambda kv: -kv[1]["share"])
    if big:
        txt += "; isolated spikes (sensor glitches, or an effect sharper than a sample): " + ", ".join(
            f"{c} {v['count']} sample(s) > {SPIKE_SIGMA:g}σ from their neighbours (first at t = {v['times'][0]:.4g} s), "
            f"{100 * v['share']:.0f} % of its excess" for c, v in big[:3])
    return txt


#: Channels above their floor, worst first, searched for lines other than the worst
#: channel's, and how many such lines the conclusion names.
LINE_CHANNELS = 6
OTHER_LINES = 2


def _other_lines(spectrum: Any, per: Mapping[str, float], c0: str, const: Mapping[str, Any]) -> str:
    """The residual's lines at other frequencies than the worst channel's, each with the
    channels (of the :data:`LINE_CHANNELS` worst, those above :data:`FLOOR_MULTIPLE`) that carry it:
    a periodic force shows its own frequency on the channels it drives directly and can
    leave a mode it excites, at another, as the worst channel's line (MuJoCo disturbance
    675-003: a 1.458 Hz torque on link 2's bending joint, 3.34 Hz on imu2_az and tau1,
    1.457 Hz on imu2_ay, ee_z and tau2). "" when there is none."""
    def line_of(c: str) -> Optional[Tuple[float, float, float]]:
        if c not in spectrum.index or c in const:
            return None
        row = spectrum.loc[c]
        share, f = float(row.get("line_fraction", math.nan)), float(row.get("peak_hz", math.nan))
        return (f, share, float(row.get("line_halfwidth_hz", 0.0))) if math.isfinite(share) and share >= LINE_SHARE and math.isfinite(f) else None

    first = line_of(c0)
    named = [(first[0], first[2])] if first is not None else []
    other: List[Tuple[float, float, List[str]]] = []
    for c, v in sorted(per.items(), key=lambda kv: -kv[1])[:LINE_CHANNELS]:
        ln = line_of(c) if c != c0 and v > FLOOR_MULTIPLE else None
        if ln is None or any(abs(ln[0] - g) <= max(ln[2], wg) for g, wg in named):
            continue
        f, share, w = ln
        hit = next((x for x in other if abs(f - x[0]) <= max(w, x[1])), None)
        if hit is None:
            if len(other) >= OTHER_LINES:
                continue
            hit = (f, w, [])
            other.append(hit)
        hit[2].append(f"{c} ({100 * share:.0f} %)")
    if not other:
        return ""
    return "; other lines in the residual: " + "; ".join(f"{f:.4g} Hz on " + ", ".join(cs) for f, _, cs in other)


def _encoder_text(ef: Mapping[str, float]) -> str:
    big = sorted(((c, v) for c, v in ef.items() if v > 1.05), key=lambda kv: -kv[1])[:3]
    if not big:
        return "the encoder adds nothing above the noise"
    return "the encoder's error alone replays at " + ", ".join(f"{v:.2g}× noise on {c}" for c, v in big)


def conclude(h: History, max_rounds: int, prob: Optional[ReplayProblem] = None) -> str:
    """The whole history in words: what was added (value, interval, the fall of the error
    overall and on the channels it acts on), then what is left; ``prob``: the run's problem
    in the floors the steps are in (default: the first diagnosis's), and where the loop
    re-estimated them (:func:`_floors_update`) the conclusion says so."""
    parts: List[str] = []
    for i in range(1, len(h.steps)):
        prev, st = h.steps[i - 1], h.steps[i]
        if st.removed and st.swapped_in:
            new = st.swapped_in.split(" + ")
            ptxt = "; ".join((f"{e}: " if len(new) > 1 else "") + (fmt_params({k: v for k, v in st.params.get(e, {}).items() if k in st.ci95.get(e, {})},
                                                                               st.ci95.get(e, {})) or fmt_params(st.params.get(e, {}), {})) for e in new)
            parts.append(f"replaced {st.removed} by {st.swapped_in} ({ptxt}): {st.removed} stood in for {'them' if len(new) > 1 else 'it'}; the error "
                         f"{'fell' if st.error < prev.error else 'went'} from {prev.error:.3g} to {st.error:.3g} noise units")
            continue
        if st.removed:
            parts.append(f"removed {st.removed} again (with {', '.join(st.effects)} refitted it explains nothing more; error {prev.error:.3g} → {st.error:.3g})")
            continue
        if st.law_refined:
            e, var = st.law_refined.split(": ", 1)
            vals, ci = st.params.get(e, {}), st.ci95.get(e, {})
            ptxt = fmt_params({k: v for k, v in vals.items() if k in ci}, ci) or fmt_params(vals, {})
            parts.append(f"gave {e} its {var} law ({ptxt}), tried again with every effect in: the systematic error "
                         f"{'fell' if st.error < prev.error else 'went'} from {prev.error:.3g} to {st.error:.3g} noise units")
            continue
        new = [x for x in st.effects if x not in prev.effects] or st.effects[-1:]
        e = new[-1]

        def ptxt_of(x: str) -> str:
            vals, ci = st.params.get(x, {}), st.ci95.get(x, {})
            return fmt_params({k: v for k, v in vals.items() if k in ci}, ci) or fmt_params(vals, {})
        drop = 1.0 - st.error / prev.error if prev.error > 0 else 0.0
        moved = sorted(((c, prev.channel_error.get(c, math.nan), st.channel_error.get(c, math.nan)) for c in st.channel_error),
                       key=lambda x: -(x[1] - x[2]) if math.isfinite(x[1] - x[2]) else 0.0)[:3]
        ch = ", ".join(f"{c} {a:.2g}× → {b:.2g}× noise" for c, a, b in moved if a - b > 0.05 * a)
        reset = f", with {st.law_reset} back at its base law (its richer variant had stood in for {e})" if st.law_reset else ""
        fall = (f"the systematic error fell from {prev.error:.3g} to {st.error:.3g} noise units ({100 * drop:.0f} % less)" if st.error < prev.error
                else f"the systematic error went from {prev.error:.3g} to {st.error:.3g} noise units")
        if len(new) > 1:
            what = (f"added the pair {' and '.join(new)} ({'; '.join(f'{x}: {ptxt_of(x)}' for x in new)}), neither of which was "
                    "significant alone")
        else:
            what = f"added {e} ({ptxt_of(e)})"
        parts.append(f"{what}{reset}: {fall}" + (f"; on {ch}" if ch else ""))
    last = h.steps[-1]
    d_last = h.diagnoses[-1] if h.diagnoses and h.diagnoses[-1].problem is not None and h.diagnoses[-1].problem.model is last.model else None
    n_added = sum(1 for st in h.steps[1:] if not st.removed and not st.law_refined)
    prob0 = prob if prob is not None else h.diagnoses[0].problem if h.diagnoses and h.diagnoses[0].problem is not None else None
    try:
        floor = prob0 is not None and step_at_floor(last, prob0)
    except Exception:  # noqa: BLE001 - the words still go out: not shown to be at the floor
        floor = False
    if last.error <= AT_FLOOR or floor:
        if last.error <= AT_FLOOR:
            what = f"the noise floor (systematic error {last.error:.3g} noise units)"
        else:
            assert prob0 is not None
            what = (f"its floor, the noise and the encoder's resolution (systematic error {last.error:.3g} noise units, "
                    f"{floor_words(prob0, last.channel_error)}; {_encoder_text(prob0.encoder_floor)})")
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
    if h.diagnoses and len(h.steps) > 1:
        d0, first = h.diagnoses[0], h.steps[1]
        b0 = d0.best
        ties = [t for t in tied_with_best(d0) if t.effect not in last.effects]
        if b0 is not None and ties and b0.effect in first.effects and not first.removed:
            parts.append(f"{b0.effect}, added first: " + _tie_text(b0, ties))
    untested = sorted({f"{s.effect} ({s.message})" for d in h.diagnoses if not d.model_at_floor for s in d.untested})
    if untested:
        parts.append("the ranking is incomplete: " + "; ".join(untested))
    if prob0 is not None and prob0.fit_offsets:
        try:
            off = final_problem(prob0, last).offsets()
        except Exception:  # noqa: BLE001 - the words still go out
            off = {}
        big = sorted(off.items(), key=lambda kv: -abs(kv[1]["z_mean"]))[:4]
        parts.append("a constant offset was fitted per channel with every model (a sensor bias or a calibration offset; the largest: "
                     + ", ".join(f"{c} {v['offset']:+.3g} {UNITS.get(c, '')} ({-v['z_mean']:+.2g} noise σ)" for c, v in big) + ")")
    floors_moved = {c: h.noise[c] / v for c, v in h.noise_initial.items() if v > 0 and c in h.noise and h.noise[c] != v}
    if floors_moved:
        txt = ", ".join(f"{c} {r:.2g}×" for c, r in sorted(floors_moved.items(), key=lambda kv: -abs(math.log(kv[1]))))
        parts.append(f"the history's errors are in noise floors re-estimated on a refitted model, the nominal residual's misfit having "
                     f"biased them ({txt} the first estimate)")
    if h.error:
        parts.append(f"incomplete: {h.error}; the rounds before it are kept")
    text = "; ".join(parts)
    return text[0].upper() + text[1:] + "."
