"""The predictable horizon of a replay (a gear rattling in its play is chaotic) and the
problem cut at it (:meth:`ReplayProblem.until`, :func:`candidate.predictable_until`)."""
from __future__ import annotations

import math

import numpy as np
import pytest

import popup
from popup import effects as fx
from popup.diagnosis.candidate import predictable_until
from popup.diagnosis.rules import PLAY_PARAMS, PREDICT_REL, PREDICT_TOL, PREDICT_WINDOW_S
from popup.problem import ReplayProblem

#: A gear whose link side rattles between soft, lightly damped flanks and a rigid-flank
#: gear (popup-lab, 10 s lab trajectory). The rigid one is chaotic as well on this run, its
#: twin parting within the first second: too early a horizon to judge a fit on.
GEARS = {
    "soft flanks": {"gap": [0.016, 0.033, 0.025], "inertia": [0.1] * 3, "contact_k": [3e3] * 3, "contact_c": [3.0] * 3},
    "rigid flanks": {"gap": [0.01, 0.02, 0.015]},
}


@pytest.fixture(scope="module")
def nominal() -> popup.Model:
    return popup.Model("popup-lab", payload_kg=1.0)


@pytest.fixture(scope="module")
def runs(nominal, tmp_path_factory):
    t, q = popup.synth.lab_trajectory(10.0, seed=3)
    out = {}
    for name, kw in GEARS.items():
        truth = nominal.with_effect("backlash", **kw)
        out[name] = (truth, popup.synth.measured_run(truth, t, q, tmp_path_factory.mktemp(name.replace(" ", "_")), seed=3))
    return out


def _twin_windows(p: ReplayProblem, flat: np.ndarray) -> np.ndarray:
    """RMS change [noise units] per :data:`PREDICT_WINDOW_S` window of the replay with the
    play :data:`PREDICT_REL` wider."""
    sl = fx.EFFECTS["backlash"].params[PLAY_PARAMS["backlash"]].slice
    twin = flat.copy()
    twin[sl] *= 1.0 + PREDICT_REL
    z = p.residuals(p.simulate(np.stack([flat, twin])))
    d = z[1] - z[0]
    k = np.floor((p.time - p.time[0]) / PREDICT_WINDOW_S).astype(int)
    out = []
    for w in range(int(k.max()) + 1):
        x = d[(k == w) & p.used]
        x = x[np.isfinite(x)]
        out.append(math.sqrt(float(np.mean(x * x))) if x.size else 0.0)
    return np.array(out)


def test_until_keeps_the_split_and_the_replay_before_the_cut(nominal, runs):
    _, run = runs["rigid flanks"]
    p = ReplayProblem(nominal, run)
    k = p.until(4.0)
    keep = p.time < 4.0
    assert k.horizon == 4.0 and p.horizon is None
    assert np.array_equal(k.time, p.time[keep]) and np.array_equal(k.measured, p.measured[keep])
    # the held-out split stays where it lies (with_horizon makes every sample a training one)
    assert np.array_equal(k.train, p.train[keep]) and np.array_equal(k.validation, p.validation[keep])
    assert k.validation.any() and k.train.any()
    # the replay is causal: away from the cut (where the encoder's derivative needs the
    # readings after it) it is the full run's, bit for bit
    z, zk = p.residuals(p.nominal_simulation()), k.residuals(k.nominal_simulation())
    inner = k.time < 4.0 - 0.1
    assert np.array_equal(zk[inner], z[keep][inner], equal_nan=True)
    # a derived problem keeps the horizon
    assert k.with_model(nominal.with_effect("payload_mass", delta_kg=0.1)).horizon == 4.0
    assert p.until(1e3) is p and p.until(float(p.time[0]) + 1e-3) is p


def test_no_play_means_no_horizon(nominal, runs):
    _, run = runs["soft flanks"]
    m = nominal.with_effect("payload_mass", delta_kg=0.3)
    p = ReplayProblem(m, run)
    assert predictable_until(p, "payload_mass", np.array(m.effects_flat)) is None
    assert predictable_until(p, "backlash", np.array(nominal.effects_flat)) is None  # no gap


@pytest.mark.parametrize("gear", sorted(GEARS))
def test_the_horizon_is_where_a_play_0_1_percent_wider_is_told_apart(runs, gear):
    truth, run = runs[gear]
    p = ReplayProblem(truth, run)
    flat = np.array(truth.effects_flat, dtype=float)
    hz = predictable_until(p, "backlash", flat)
    w = _twin_windows(p, flat)
    t0, t1 = float(p.time[0]), float(p.time[-1])
    if hz is None:
        # predicted to the end, or told apart already in the first fifth of the run
        first = int(np.argmax(w > PREDICT_TOL)) if (w > PREDICT_TOL).any() else None
        assert first is None or t0 + first * PREDICT_WINDOW_S < t0 + 0.2 * (t1 - t0), (gear, w)
    else:
        k = int(round((hz - t0) / PREDICT_WINDOW_S))
        assert 0.2 * (t1 - t0) <= hz - t0 < t1 - t0
        assert np.all(w[:k] <= PREDICT_TOL) and w[k] > PREDICT_TOL, (gear, hz, w)
    if gear == "soft flanks":
        # a link side rattling between soft flanks is chaotic: the twin parts from it
        # within the run, by far more than the floor test can tell
        assert hz is not None and float(w.max()) > 3 * PREDICT_TOL, w


def test_the_loop_asks_for_the_horizon_only_of_a_leading_play():
    from types import SimpleNamespace

    from popup.diagnosis.loop import _unpredictable_top
    from popup.diagnosis.results import Suspect

    def sus(effect, tested=True, after=None):
        return Suspect(effect, False, 10.0, {}, {}, 1.0, 1.0, {}, {}, tested=tested, unpredictable_after=after)

    assert _unpredictable_top(SimpleNamespace(suspects=[sus("backlash", after=5.0), sus("payload_mass")])) == 5.0
    # an untested candidate is not ranked; another effect on top has no play to be unpredictable in
    assert _unpredictable_top(SimpleNamespace(suspects=[sus("torsion", tested=False), sus("backlash", after=5.0)])) == 5.0
    assert _unpredictable_top(SimpleNamespace(suspects=[sus("payload_mass"), sus("backlash", after=5.0)])) is None
    assert _unpredictable_top(SimpleNamespace(suspects=[sus("backlash")])) is None
    assert _unpredictable_top(SimpleNamespace(suspects=[])) is None


def test_the_horizon_step_judges_the_nominal_model_and_every_candidate_before_it(nominal, tmp_path, monkeypatch):
    """A disturbance outside the library leaves round 1 with nothing significant, above the
    floor. With its best candidate's replay declared unpredictable past 6 s (what
    ``_unpredictable_top`` reads from a rattling gear's continuation), the loop judges the
    nominal model and every candidate on the samples before 6 s, once, and says so; the
    pairs are tried only there, after the cut (not first on the whole run)."""
    from popup.diagnosis import loop
    from popup.unseen import fit_unseen_motion

    def disturbance(t):
        return {"imu2_az": 0.8 * np.sin(2 * np.pi * 1.7 * t), "ee_z": 0.004 * np.sin(2 * np.pi * 1.7 * t + 0.5)}

    t, q = popup.synth.lab_trajectory(10.0, seed=3)
    run = popup.synth.measured_run(nominal, t, q, tmp_path / "disturbed", seed=3, disturbance=disturbance)
    asked = []

    def top(d):
        asked.append(d)
        return 6.0

    pairs = []
    pair_from_none = loop._pair_from_none

    def pair(prob, *a, **kw):
        pairs.append(prob.horizon)
        return pair_from_none(prob, *a, **kw)

    monkeypatch.setattr(loop, "_unpredictable_top", top)
    monkeypatch.setattr(loop, "_pair_from_none", pair)
    h = popup.improve(nominal, run, effects=["payload_mass", "air_drag"], max_rounds=2, threads=1)
    assert len(asked) == 1 and len(h.diagnoses) == 2
    assert pairs == [6.0], pairs
    assert all(s.horizon is None for s in h.diagnoses[0].suspects)
    assert [s.horizon for s in h.diagnoses[1].suspects if s.tested] == [6.0, 6.0]
    cut = fit_unseen_motion(ReplayProblem(nominal, run)).until(6.0)
    assert h.steps[0].error == cut.error()[0] and h.steps[0].effects == []
    assert h.diagnoses[1].nominal_error == h.steps[0].error
    assert any(n.startswith("judged on t < 6 s from round 1 on") for n in h.notes), h.notes
    assert "not explained by the library" in h.conclusion


def test_only_a_candidate_fitted_alone_is_checked_for_its_horizon(nominal, runs, monkeypatch):
    """The horizon step reads round 1 only, so a candidate fitted with an earlier effect
    refitted beside it (round 2 on, the pair steps) is not checked: the check's two
    rollouts per doubling would be spent where nothing reads them."""
    from popup import estimate as est
    from popup.diagnosis import candidate

    _, run = runs["rigid flanks"]
    p = ReplayProblem(nominal, run)
    checked = []
    monkeypatch.setattr(candidate, "_horizon_of", lambda *a: checked.append(a[1]))
    assert "payload_mass" in candidate.SHORT_FIRST
    candidate._fit_candidate(p, "payload_mass", None, None, None, None, 3)
    alone = list(checked)
    checked.clear()
    candidate._fit_candidate(p, "payload_mass", None, None, None, None, 3, also=est.free_params("air_drag"))
    assert alone and set(alone) == {"payload_mass"} and checked == []
