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
explains at least :data:`MIN_EXPLAINED` of the systematic error (``1 − S²_after/S²_before``;
for an effect that acts on some sensor rows only in replay, friction and its clamp on the
motor torques, of the error on those channels: :func:`popup.effects.acts_only_on`, also
when refitted jointly with the effects added, net of what that refit adds elsewhere, and
with the isolated spikes it leaves there set aside when that share is larger: a gear's
impacts no smooth law replays; :func:`popup.diagnosis.candidate.share_where_it_acts`)
and it is confirmed on the held-out samples (the likelihood ratio there is positive and the
held-out error falls), unless it does not act on them at all (a torque limit reached only in
training blocks: the held-out samples can neither confirm nor refute it; its message says so).
Two significant candidates whose scores differ by less than :data:`SCORE_THRESHOLD` (both
are BIC gains over the same nominal model, so the difference is the evidence for one over
the other) are ones the run cannot tell apart, and the conclusions say so
(:func:`popup.diagnosis.conclusion.tied_with_best`): the best is still added.

**Refinement.** A significant effect (or one whose base law beats the nominal model by
:data:`SCORE_THRESHOLD` but fails the share or held-out test) is also fitted in its richer variants
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
that scores higher is kept. So is a refinement marked ``always``, one the base law cannot
stand in for: a link whose root spring is several times its outer one (bending's "stiffer
root" split) drives an equal-spring fit to its bound and below the threshold, so the base
says nothing about it; it starts from seeds of its own (each split with a plausible
stiffness) as well as from the base's fit, and is combined with the other variants.

**The floor.** Nothing is added to a model at its floor: a systematic error of at most
:data:`AT_FLOOR` and every channel within :data:`FLOOR_MULTIPLE` of its floor, the noise
and the replay error the encoder's own error causes
(:attr:`ReplayProblem.encoder_floor`, a parametric bootstrap; its encoder part taken at
the bootstrap's 95 % prediction bound for one draw, :attr:`ReplayProblem.encoder_sigma_upper`,
since the run's own encoder error is one such draw). A quantised encoder limits
how well q̈, and so the replayed torques and accelerations, can be known: with a 12-bit
encoder and a quiet IMU the true model replays at up to 1.3 × the IMU's noise, and
an effect fitted there (a +0.8 g payload for 54 % of it, on a MuJoCo run) fits the
encoder, not the arm. The candidates are then not tried (each says why; the answer takes
seconds), or, with ``rank_at_floor=True`` (``--rank-at-floor``), fitted and ranked with
none significant.

**What the encoder cannot see.** A coarse encoder also hides motion: a held motor that
yields to the links' ringing by a fraction of a step (a servo's finite stiffness) never
changes its reading, and the replay holds it still. That motion is fitted into the replay
(:mod:`popup.unseen`), for the nominal model and, in the first round, again for each of
the :data:`UNSEEN_TOP` leading candidates, which are refitted on it, starting both from the
nominal model's motion and from none (a compliance fitted without the missing effect takes
part of a softening, and a fit started beside it stays in its basin); before that, every
candidate is refitted from its fit on the replay without any motion, so that one held at
any rank by the nominal's compliance can still lead. A backlash narrower than :data:`PLAY_READINGS` of a reading
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
four steps undo it. *Backward*: an effect added earlier that the refitted model no longer
needs (by the rules that add one) is removed. *Swap*: an effect added earlier is replaced
by the best candidate for the model without it when that model beats the current one
(BIC gain over the threshold, held-out error lower). *Base law*: when
nothing is significant but the model is not at its floor, an effect added with a variant's
extra parameters (a payload's centre-of-mass offset) is set back to its base law and the
best candidate then added, on the same test. *Pair*: when one effect was added, nothing
is significant beside it and the error left is above the floor, it may stand in for two
effects that each explain little alone (drag and a payload, mimicked by a backlash with
link-side inertia and contact damping); for each of the :data:`PAIR_HINTS` best candidates
that pass the likelihood threshold beside it without being significant, the nominal model
with that candidate is diagnosed over the candidates significant in some round, each
fitted jointly with it from its seeds, and the best pair replaces the effect on the same
test. *Pair from none*: when nothing was significant in round 1 and the error is above the
floor, two effects may each replay worse alone than neither (a sensor delay beside a
bending law that moves the phase of the channels it shares the other way); for each of the
:data:`PAIR_HINTS` best candidates that pass the likelihood threshold, the nominal model
with it is diagnosed over the other candidates that passed it (screened from their fits
alone, the best fitted jointly with it), and the first pair that beats the nominal model on
the same test and explains at least :data:`MIN_EXPLAINED` of its systematic error, as one
effect must, is added in round 1. Where none does, each such candidate is tried with those
tested below the threshold, fitted jointly from their seeds (a partner can replay worse
alone than the nominal, its fit in another basin: a soft torsion beside a missing payload),
and of the pairs that qualify the one of the largest BIC gain over the nominal is added.
*First-round pair*: when one effect was added and nothing is significant beside it, above
the floor, it may stand in for two of round 1's other candidates that each fit so badly
alone that neither passes the likelihood threshold beside it (drag and a payload, each in
another basin alone); before the base-law and pair steps, the :data:`FIRST_PAIRS` best
candidates significant in round 1 are fitted two at a time jointly from their round-1
fits, and the pair of the largest BIC gain, confirmed as the pair step confirms one,
replaces the effect where it beats it and explains :data:`MIN_EXPLAINED` of its error.
The swap and the base law offer only
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


Layout
------
Each module imports only those before it:
:mod:`~popup.diagnosis.rules` (thresholds, variants, the floor tests),
:mod:`~popup.diagnosis.results` (:class:`Suspect`, :class:`Diagnosis`, :class:`History`),
:mod:`~popup.diagnosis.evidence` (each effect's residual signature),
:mod:`~popup.diagnosis.candidate` (one effect fitted and tested),
:mod:`~popup.diagnosis.conclusion` (the sentences),
:mod:`~popup.diagnosis.rank` (:func:`diagnose`: one round),
:mod:`~popup.diagnosis.loop` (:func:`improve`: the rounds) and
:mod:`~popup.diagnosis.cli` (``popup diagnose``).
"""

from .cli import TerminalProgress, cli_main
from .loop import improve
from .rank import diagnose, model_error
from .results import Diagnosis, History, HistoryStep, Suspect
from .rules import (
    AT_FLOOR,
    FIRST_PAIRS,
    FLOOR_MULTIPLE,
    JOINT_TOP,
    MIN_EXPLAINED,
    NOISE_RECHECK,
    OFFSET_SHARE,
    PAIR_HINTS,
    OFFSET_Z,
    PLAY_READINGS,
    SCORE_THRESHOLD,
    SPIKE_SHARE,
    STABILITY_MARGIN,
    UNSEEN_ALTERNATIONS,
    UNSEEN_TOP,
    VARIANTS,
    Progress,
)
from ..problem import ERROR_DEFINITION

__all__ = [
    "Suspect",
    "Diagnosis",
    "History",
    "HistoryStep",
    "diagnose",
    "improve",
    "model_error",
    "cli_main",
    "TerminalProgress",
    "Progress",
    "ERROR_DEFINITION",
    "SCORE_THRESHOLD",
    "MIN_EXPLAINED",
    "STABILITY_MARGIN",
    "AT_FLOOR",
    "VARIANTS",
    "JOINT_TOP",
    "FLOOR_MULTIPLE",
    "NOISE_RECHECK",
    "OFFSET_SHARE",
    "PAIR_HINTS",
    "FIRST_PAIRS",
    "OFFSET_Z",
    "SPIKE_SHARE",
    "PLAY_READINGS",
    "UNSEEN_TOP",
    "UNSEEN_ALTERNATIONS",
]
