"""The diagnosis's rules and settings: significance and floor thresholds, the richer variants
of each effect, the structures and steps its candidates are tried at, and the floor tests."""

from __future__ import annotations

import math
from typing import Any, Callable, Dict, List, Mapping, Tuple

from .. import estimate as est
from ..problem import ENCODER_LEVEL, ReplayProblem


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


UNSEEN_TOP = 3
"""In a round with no effect added yet, the number of best-ranked candidates refitted with
the unseen servo motion (:mod:`popup.unseen`) their own model gives rather than the nominal
model's, along two paths: from the nominal model's motion and from none
(:func:`popup.diagnosis.candidate.refit_with_own_unseen`). They are taken after every
candidate has been refitted from its fit on the replay without any motion
(:func:`popup.diagnosis.candidate.screen_without_unseen`)."""


UNSEEN_ALTERNATIONS = 2
"""Most alternations of that refit: the unseen motion fitted to the candidate's model, then
the candidate refitted on it, each kept while the likelihood rises."""


SPIKE_SHARE = 0.5
"""Share of a channel's excess above which the unexplained error names its isolated spikes
(:meth:`ReplayProblem.spikes`), for a channel above :data:`FLOOR_MULTIPLE` × its noise (a
replay at the floor can have one: a friction reversal a sample early is a one-sample step)."""


LINE_SHARE = 0.5
"""Share of the worst channel's residual power within a spectral line's width of its peak
(``Comparison.spectrum["line_fraction"]``: the Hann main lobe, ±2/T) above which the
unexplained error is named as a line at that frequency (given to a fraction of 1/T)
rather than as a band: a periodic force outside the library (a pump, a fan, an unbalanced
rotor) leaves one, and so does a model error at a periodic excitation's frequency."""


FIRST_PAIRS = 6
"""The loop's first-round pair step (:func:`popup.diagnosis.improve`): when one effect was
added and a systematic error is left with nothing significant, the candidates significant
in round 1 other than it (at most this many, best first) are fitted two at a time, jointly
from their round-1 fits; the pair that replays best, confirmed as the pair step confirms
one, replaces the effect where it beats it. An effect chosen first can stand in for two
that each fit badly alone, so badly that neither passes the pair step's hints (an air drag
of cd 5.5 beside a 0.2 kg payload: alone the drag went to cd 95 and the payload to
−0.16 kg, and a backlash with compliant flanks was added; the two fitted together from
those fits landed on both truths, MuJoCo pair 662-013). 6 candidates make 15 joint fits of
two effects from one start each."""


PAIR_HINTS = 2
"""The loop's pair step (:func:`popup.diagnosis.improve`): when one effect was added and a
systematic error is left with nothing significant, it is tried replaced by a pair, one of
which is among this many best candidates that pass the likelihood threshold beside it but
explain too little of what is left to be significant (each hint costs a joint fit of every
candidate significant in some round). With nothing added (nothing significant in round 1),
the same number of best candidates that pass the likelihood threshold are each tried with
each other one that does, and where no pair qualifies, with each candidate tested below the
threshold, fitted jointly from its seeds (``_pair_from_none``)."""


OFFSET_SHARE = 0.5
"""Share of a channel's excess above which the unexplained error names the residual's
constant part (:meth:`ReplayProblem.offsets`: a sensor bias or a calibration offset; no
effect of the library is a constant on one channel), for a channel above
:data:`FLOOR_MULTIPLE` × its noise."""


OFFSET_Z = 5.0
"""Standard errors (σ/√n) a channel's constant offset must reach to count as one in
:func:`~popup.diagnosis.loop.offsets_left` (white noise: two-sided 6e-7 per channel)."""


FLOOR_MULTIPLE = 1.2
"""After an effect was added, :func:`improve` stops when the systematic error is at most
:data:`AT_FLOOR` and every channel is within this multiple of its noise (a systematic part of
at most 0.66 σ in any channel). The noise floors are themselves estimated from the run
(coloured noise, jittered stamps): a popup run refitted to its truth's own law (S = 0.065)
had channels from 0.955 to 1.118 × their floors, so effects that would take such a model
from, say, 0.15 to 0.08 noise units are fitting that uncertainty, not physics."""


#: Effects that move a lightly damped resonance (or a link side rattling in its gap): fitted on
#: a short horizon first, then on doubled horizons from that optimum (an extra start).
SHORT_FIRST = {"higher_bending_modes", "torsion", "payload_mass", "wrinkling", "pressure_leak", "air_drag", "backlash"}


#: Effects whose per-joint seeded parameters are also swept joint by joint (on the short
#: horizon, and again on each longer one for a joint the shorter could not tell).
COORDINATE_SEEDS = {"backlash"}


COORDINATE_STEP = 1.03
"""Ratio between neighbouring values of the joint-by-joint seed sweep (``COORDINATE_SEEDS``)."""


SHORT_HORIZON_S = 2.5
"""Length [s] of the short horizon (at least 20 % of the run) of the first fit of an effect
that moves a resonance; the continuation then doubles it until the run's length."""


#: Effects whose fit needs more iterations than ``max_iter`` (coupled, lightly damped modes).
MIN_ITER: Dict[str, int] = {"torsion": 40, "higher_bending_modes": 25, "wrinkling": 20}


#: Structural settings used when an effect is tried (its discrete parameters), and the
#: parameter values at which its stability limit is taken (the stiffest seed).
STRUCTURE: Dict[str, Dict[str, Any]] = {
    "higher_bending_modes": {"segments": [2.0, 2.0]},
    "torsion": {"k_t": [200.0, 200.0]},
}


STIFFEST: Dict[str, Dict[str, Any]] = {
    "higher_bending_modes": {"k_scale": [5.0, 5.0]},
    "torsion": {"k_t": [est.BOUNDS[("torsion", "k_t")][1]] * 2, "c_t": [2.0, 2.0]},
}


FLANK_CHECK_DAMPING = 50.0
"""Damping [N·m·s/rad] of the stiffest compliant flank (``contact_k`` at its upper bound)
whose stability limit sets the step of backlash's compliant-flanks variant: ζ ≈ 0.8 on the
default link-side inertia (0.01 kg·m²), near where that limit is largest. The damping's
bound (``estimate.BOUNDS``, 100) is not used: past critical the fast overdamped root c/J
grows with c, and a step for c = 100 on 0.01 kg·m² is 2.8 × smaller (3.0e-4 s against
8.4e-4 s), which cut MuJoCo pair 730-002 off at the bench's time limit (session 68). A
damping the step cannot carry (above ≈ 80 N·m·s/rad on 0.01 kg·m² at a 500 Hz run's step;
every damping in bounds on 0.03 kg·m² and heavier link sides) fails the rollout's own step
check, and the fit treats it as a failed simulation, outside its feasible region."""

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
                             # tried whether the equal split is significant or not: fitted with
                             # equal springs, a link whose root is much stiffer than its tip (a
                             # cantilever's 4:1, or more) is mimicked by no equal pair (a popup run
                             # with a 5.8:1 root fitted k_scale 1.5/5.0, at its bound, and scored
                             # below zero, so the split was never tried and a payload was added
                             # instead); its own starts pair each split with a plausible k_scale
                             # (the split keeps the static tip deflection, so the truth's k_scale
                             # is near 1 whatever the split) besides the base fit's
                             {"name": "stiffer root (cantilever split)", "extra": ["root_ratio"], "always": True,
                              "seeds": [{"root_ratio": 4.0}, {"root_ratio": 2.0}, {"root_ratio": 0.6}]
                              + [{"root_ratio": r, "k_scale": s} for r in (2.0, 4.0, 6.0) for s in (0.7, 1.0, 1.4)]}],
    "payload_mass": [{"name": "centre-of-mass offset", "extra": ["com_offset_m"]}],
    # how fast a link side crosses its gap depends on the gear's link-side inertia
    "backlash": [{"name": "fitted link-side inertia", "extra": ["inertia"], "seeds": [{"inertia": 0.003}, {"inertia": 0.03}, {"inertia": 0.1}, {"inertia": 0.3}]},
                 # a link side held by its bearing's friction, moved only by the flanks: another
                 # law, not a refinement, so it is tried even when the free gear is not significant
                 {"name": "held link side (play operator)", "structure": {"held": [1.0, 1.0, 1.0]}, "alternative": True},
                 # a compliant gear: its flanks a unilateral spring-damper (the elasto-backlash
                 # law of Modelica and Simscape), which also carries the gear's own compliance
                 # while it pushes; run at the step of its stiffest plausible flank (the
                 # check needs a gap on every joint: a joint without one has no flank, and
                 # its stiffness would not be in the linearisation at all), damped at
                 # FLANK_CHECK_DAMPING; a joint whose play vanishes in its fit is given the
                 # rigid flanks back (RIGID_WHERE_ZERO)
                 {"name": "compliant flanks", "extra": ["contact_k", "contact_c"],
                  "structure": {"contact_k": [1e4, 1e4, 1e4], "contact_c": [5.0, 5.0, 5.0]},
                  "stiffest": {"contact_k": [est.BOUNDS[("backlash", "contact_k")][1]] * 3, "contact_c": [FLANK_CHECK_DAMPING] * 3,
                               "gap": [1e-3] * 3},
                  "seeds": [{"contact_k": 3e3, "contact_c": 3.0}, {"contact_k": 3e4, "contact_c": 10.0}, {"contact_k": 1e5, "contact_c": 30.0}],
                  # one flank law (and link side) on every joint with play, fitted with the gaps
                  # for one more start: per joint, gaps and flanks trade off (MuJoCo's soft gear
                  # 760: flanks 4-7 % off the truth's gaps replay at 8.5 noise units, the truth at 1.0)
                  "shared": ["contact_k", "contact_c", "inertia"]},
                 # the same with the link side's inertia fitted too, tried only on a run cut at
                 # its predictable horizon (``on_horizon``, the loop's horizon step): a link side rattling
                 # between compliant flanks is chaotic, and how often it crosses its gap is set
                 # by that inertia (MuJoCo 802-000, benchmarks/README.md session 74: on its first
                 # 7 s this variant found the truth, 13.1 -> 0 noise units; without the inertia
                 # nothing was added)
                 {"name": "compliant flanks and link side", "extra": ["contact_k", "contact_c", "inertia"], "on_horizon": True,
                  "structure": {"contact_k": [1e4, 1e4, 1e4], "contact_c": [5.0, 5.0, 5.0]},
                  "stiffest": {"contact_k": [est.BOUNDS[("backlash", "contact_k")][1]] * 3, "contact_c": [FLANK_CHECK_DAMPING] * 3,
                               "gap": [1e-3] * 3},
                  "seeds": [{"contact_k": k, "contact_c": c, "inertia": j} for k, c in ((3e3, 3.0), (3e4, 10.0), (1e5, 30.0)) for j in (0.01, 0.1)],
                  "shared": ["contact_k", "contact_c", "inertia"]}],
    "torsion": [{"name": "link 1 only", "structure": {"k_t": [200.0, math.inf], "c_t": [0.2, 0.0]}},
                {"name": "link 2 only", "structure": {"k_t": [math.inf, 200.0], "c_t": [0.0, 0.2]}}],
}
"""Richer variants tried when an effect is significant (or its base law beats the nominal
model by :data:`SCORE_THRESHOLD`, whatever its share and held-out test): ``extra`` parameters fitted with
the base ones (from the base fit and the variant's ``seeds``), or another ``structure``; an
``alternative`` (another law for the same effect) is tried whether the base is significant
or not, and so is a refinement marked ``always`` (one whose base law cannot stand in for
it, so a base below the threshold says nothing about it); unlike an alternative, it is
combined with the other variants. ``shared``: parameters also fitted as one value on every
entry (with the others per entry) for one more start of the fit per entry. ``on_horizon``:
tried only on a problem cut at its predictable horizon (:meth:`ReplayProblem.until`, the
loop's horizon step), where a fit of more parameters is not lost in a chaotic objective."""


RIGID_WHERE_ZERO: Dict[str, Tuple[str, Tuple[str, ...]]] = {"backlash": ("contact_k", ("contact_k", "contact_c"))}
"""Effects whose law on an entry (joint) is its rigid one where a parameter is 0, and the
parameters then not fitted there: backlash's flanks are rigid where ``contact_k`` is 0, and
neither their stiffness (fitted as its logarithm, which 0 has none of) nor their damping is
fitted on that joint; a fit started there, and every refit of it, keeps it rigid. Where a
variant's fit leaves a joint not rigid but without play (below :data:`PLAY_READINGS`
encoder readings of :data:`PLAY_PARAMS`), it is refitted with that joint rigid and kept if
the likelihood prefers it (:func:`candidate._rigid_where_no_play`): a joint without play,
given compliant flanks, is a spring to a link-side inertia it never had (MuJoCo's soft gear
on joint 2: joints 1 and 3 ended with vanishing gaps on flanks at the 1e5 N·m/rad bound and
a link side at its 1 kg·m² bound, 41 noise units where the truth replays at 0.17;
benchmarks/README.md, session 68)."""


Progress = Callable[[Dict[str, Any]], None]


#: Effect parameters [rad per motor joint] that are play in a joint: a play narrower than
#: :data:`PLAY_READINGS` encoder readings (:attr:`ReplayProblem.encoder_width`) is not a finding.
PLAY_PARAMS = {"backlash": "gap"}
PREDICT_REL = 1e-3
"""Relative change of a play (``PLAY_PARAMS``) whose effect on the replay sets the
predictable horizon (:func:`popup.diagnosis.candidate.predictable_until`): about the 95 %
resolution of a fitted gap."""
PREDICT_TOL = 0.3
"""RMS change [noise units] over one window, across channels, past which a replay is no
longer predicted by its parameters (``AT_FLOOR``: what the floor test can tell)."""
PREDICT_WINDOW_S = 1.0
"""Window [s] over which :data:`PREDICT_TOL` is measured."""


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


PINNED_READINGS = 1.0
"""Readings a fitted play must clear by its 95 % interval (gap − half-width, on at least one
joint) to be a finding: one reading, what an encoder dithering between two readings can stand
in for. A held play one reading wide keeps the replayed link still while the encoder steps
forth and back, and on MuJoCo nominal 685-009 (500 Hz, 12-bit, noise × 1.57) joint 1's
1.01 ± 0.03 readings were added (0.78 → 0.15 noise units; its record undoes a one-reading
step 42 times). Each of the 40 significant backlash fits of archived runs with a hidden
backlash clears at least 1.24 readings on some joint (benchmarks/README.md, session 60)."""


#: Effects with a limit per motor joint [N·m] that the joint's measured torque channel
#: (``tau1``...) cannot exceed: a fitted limit the measurement passes is not a finding.
LIMIT_PARAMS = {"actuator_saturation": "tau_max"}


LIMIT_MARGIN = 4.0
"""Noise deviations of a torque channel above a fitted limit (:data:`LIMIT_PARAMS`) at which
a measured sample counts as beyond it (white noise: 3e-5 of the samples at the limit)."""


LIMIT_BEYOND_SHARE = 0.25
"""Share of a joint's measured samples at or above its fitted limit (within
:data:`LIMIT_MARGIN` below it, or higher) beyond which the samples that pass it by more than
:data:`LIMIT_MARGIN` refuse the limit (and at least :data:`LIMIT_BEYOND_MIN` of them). A real
torque limit leaves the measured torque level at it wherever the command asks for more; a
limit that only trims a model's peaks is passed by the measurement. On a MuJoCo run with
backlash and friction and no limit (pair 612, benchmarks/README.md, session 44) a third
round added a 22.9 N·m limit on joint 1 (43 % of the torques' error in a joint refit, the
rigid flanks' impact peaks trimmed) while 965 measured samples of ``tau1`` lay above it, up
to 31.0 N·m."""


LIMIT_BEYOND_MIN = 5
"""Fewest samples beyond a fitted limit that refuse it (glitches and outliers)."""


#: A channel's noise floor estimated from a refitted model's residual replaces the one the
#: loop used when it differs by more than this factor, either way (the estimator's own
#: scatter is a few %).
NOISE_RECHECK = 1.2


#: A change of a channel's encoder floor (as a multiple of its noise) by more than this
#: factor, either way, is noted when the loop bootstraps it again on a refitted model.
ENCODER_NOTE = 1.1


def model_at_floor(prob: ReplayProblem, error: float, per: Mapping[str, float]) -> bool:
    """Whether a model with systematic error ``error`` and noise multiples ``per`` is at its
    floor: at most :data:`AT_FLOOR` above the noise and the encoder's replay error
    (:meth:`ReplayProblem.floor_error`), and every channel within :data:`FLOOR_MULTIPLE` of
    that floor. Nothing is added then: what is left is below what the run resolves.

    The encoder's part is taken at its prediction bound
    (:attr:`ReplayProblem.encoder_sigma_upper`): the run's own encoder error is one draw
    of what the bootstrap draws, and they can differ by ±45 %. A popup nominal run (12-bit
    encoder, a 2 kg payload on links wrinkled up to 13 × their moment, multisine) replayed
    its true model at 1.16-1.17 × the bootstrap's mean floor on every encoder-dominated
    channel (0.44 noise units above it), well within the bound; judged against the mean it
    was "above its floor", and a 0.6 g payload that tuned the hypersensitive response to
    the smoothed encoder's own error was added (2.44 → 0.44 noise units, score 88 000;
    benchmarks/README.md, session 36)."""
    fm = [v for v in prob.floor_multiples(dict(per), upper=True).values() if math.isfinite(v)]
    if not fm:
        return False
    s = error if error <= AT_FLOOR else prob.floor_error(dict(per), upper=True)
    return bool(s <= AT_FLOOR and max(fm) <= FLOOR_MULTIPLE)


def floor_words(prob: ReplayProblem, per: Mapping[str, float]) -> str:
    """How far noise multiples ``per`` sit above the floor :func:`model_at_floor` judges, in
    words: the systematic error above the noise and the encoder's replay error, and above
    that replay error's prediction bound where it differs."""
    s, su = prob.floor_error(dict(per)), prob.floor_error(dict(per), upper=True)
    out = f"{s:.3g} above the noise and the encoder's replay error"
    if su < s - 5e-4:
        out += f", {su:.3g} above its {ENCODER_LEVEL:.0%} prediction bound"
    return out


#: Halvings of the step tried when a refitted model fails the step check.
STEP_HALVINGS = 3
