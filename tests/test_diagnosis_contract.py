"""The diagnosis's contract beyond ranking: channels that carry only noise do not hide a
finding, nothing is lost when a round fails, untested effects are named, progress is
reported, and the JSON says what the error means."""

from __future__ import annotations

import io
import json
import math
import re

import numpy as np
import pytest

import popup
from popup import diagnosis as dg
from popup import estimate as est
from popup.diagnosis import candidate as dgc
from popup.diagnosis import loop as dgl
from popup.diagnosis import rules as dgr
from popup.io import write_run

FRICTION = {"tau_c": [1.2, 1.8, 0.6], "b": [0.2, 0.3, 0.1], "tau_s": [0.8, 1.0, 0.4], "v_s": [0.05, 0.05, 0.05]}


@pytest.fixture(scope="module")
def nominal():
    return popup.Model("popup-lab", payload_kg=1.0)


@pytest.fixture(scope="module")
def friction_run(nominal, tmp_path_factory):
    """A Stribeck friction run that also records the pressures held at 30 kPa with ±50 Pa
    sensor noise (the channels that buried the finding before)."""
    t, q = popup.synth.lab_trajectory(8.0, seed=11)
    path = tmp_path_factory.mktemp("stribeck")
    run = popup.synth.measured_run(nominal.with_effect("joint_friction", **FRICTION), t, q, path, seed=11)
    df = run.data.copy()
    rng = np.random.default_rng(5)
    for c in ("p1", "p2"):
        df[c] = 30e3 + rng.normal(0.0, 50.0, len(df))
    exp = dict(run.experiment)
    write_run(path, exp, df, overwrite=True)
    return popup.read_run(path)


def test_noise_only_channels_do_not_hide_the_finding(nominal, friction_run):
    h = popup.improve(nominal, friction_run, effects=["joint_friction", "payload_mass", "sensor_delay"], max_rounds=2)
    d0 = h.diagnoses[0]
    assert {"p1", "p2"} <= set(d0.noise) and {"p1", "p2"} <= set(d0.at_floor)
    assert d0.noise["p1"] == pytest.approx(50.0, rel=0.1)
    # the pressures sit at their noise floor whatever the model does
    assert abs(d0.channel_error["p1"] - 1.0) < 0.05
    assert h.effects[0] == "joint_friction"
    assert h.steps[-1].error <= 0.5 * h.steps[0].error
    # the richer (Stribeck) variant is preferred for a Stribeck truth
    assert d0.best is not None and d0.best.variant == "Stribeck", d0.to_pandas()
    assert h.conclusion.startswith("Added joint_friction")


def test_a_sharper_friction_sign_is_fitted_as_its_width_not_as_a_stribeck_bump(nominal, tmp_path):
    """Friction that reverses more sharply than popup's default sign (v_eps = 3 mrad/s, as a
    gear with little presliding, or a simulator with a sharper regularisation): the default
    law could only mimic it with a Stribeck bump at v_s ≈ v_eps (MuJoCo runs: τ_s fitted 6×
    too large); the sign-width variant is preferred and every parameter lands on the truth."""
    truth = dict(FRICTION, v_eps=[0.003, 0.003, 0.003])
    t, q = popup.synth.lab_trajectory(8.0, seed=12)
    run = popup.synth.measured_run(nominal.with_effect("joint_friction", **truth), t, q, tmp_path / "sharp", seed=12)
    d = popup.diagnose(nominal, run, effects=["joint_friction"])
    s = d.best
    assert s is not None and s.effect == "joint_friction" and s.variant == "Stribeck and sign width", s.message
    for k in ("tau_c", "tau_s", "v_eps"):
        for i in range(3):
            got, ci, want = s.params[k][i], s.ci95[k][i], truth[k][i]
            assert math.isfinite(ci) and abs(got - want) <= 3 * ci + 0.03 * want, (k, i, got, ci, want)
    # with the default width (the friction_run's truth) the width is not worth its parameters:
    # test_noise_only_channels_do_not_hide_the_finding keeps the plain Stribeck variant


# minutes of fitting: with -m slow (benchmarks/slow_tests.sh)
@pytest.mark.slow
def test_a_stiffer_root_is_fitted_as_the_cantilever_split(nominal, tmp_path):
    """Links that bend like a uniform cantilever: 2 segments with the root joint 4 × as stiff
    as the mid one (the split that gives a cantilever's tip rotation as well as its tip
    deflection; MuJoCo's family arm is built so). The equal split cannot place the second
    mode; the root-ratio variant is preferred and lands on 4 (MuJoCo trapezoid run: 62.7 →
    21.9 noise units with 3 equal segments, → 3.0 with root_ratio 4.01/4.05)."""
    truth = {"segments": [2.0, 2.0], "k_scale": [1.2, 1.2], "root_ratio": [4.0, 4.0]}
    t, q = popup.synth.lab_trajectory(6.0, seed=13)
    run = popup.synth.measured_run(nominal.with_effect("higher_bending_modes", **truth), t, q, tmp_path / "root", seed=13)
    d = popup.diagnose(nominal, run, effects=["higher_bending_modes"])
    s = d.best
    assert s is not None and s.effect == "higher_bending_modes" and s.variant == "stiffer root (cantilever split)", s.message
    assert s.error_after <= 0.1 * s.error_before
    for k in ("k_scale", "root_ratio"):
        for i in range(2):
            got, ci, want = s.params[k][i], s.ci95[k][i], truth[k][i]
            assert math.isfinite(ci) and abs(got - want) <= 3 * ci + 0.03 * want, (k, i, got, ci, want)


def test_a_refit_beyond_the_step_is_rerun_at_a_smaller_step(nominal, friction_run, monkeypatch):
    """A joint refit that moves a stiffness beyond what the candidate's step was chosen for
    fails the step check: the refit is repeated at half the step, not the whole round lost."""
    orig = dgl._refit
    seen = []

    def stiff(prob, *a, **kw):
        seen.append(prob.model.dt)
        if prob.model.dt > 0.6e-3:
            raise popup.StepTooLargeError("time step dt = 1e-3 s is too large (injected)")
        return orig(prob, *a, **kw)

    monkeypatch.setattr(dgl, "_refit", stiff)
    h = dg.improve(nominal, friction_run, effects=["joint_friction"], max_rounds=1)
    assert h.complete and h.effects == ["joint_friction"], h.error
    assert seen[:2] == [pytest.approx(1e-3), pytest.approx(0.5e-3)]
    assert h.steps[-1].model.dt == pytest.approx(0.5e-3)
    assert h.steps[-1].error < 0.5 * h.steps[0].error


def test_a_failing_round_keeps_what_finished(nominal, friction_run, monkeypatch, capsys, tmp_path):
    calls = {"n": 0}
    orig = dg.diagnose

    def flaky(*a, **kw):
        calls["n"] += 1
        if calls["n"] == 2:
            raise popup.StepTooLargeError("time step dt = 1e-3 s is too large (injected)")
        return orig(*a, **kw)

    monkeypatch.setattr(dgl, "diagnose", flaky)  # the loop's rounds
    # friction alone brings this run to its noise floor, where the loop stops: switch that
    # stop off so that a second round runs (and fails)
    for mod in (dgr, dg.rank, dg.conclusion):
        monkeypatch.setattr(mod, "FLOOR_MULTIPLE", 0.0)
    h = dg.improve(nominal, friction_run, effects=["joint_friction", "payload_mass"], max_rounds=3)
    assert not h.complete and "round 2 failed: StepTooLargeError" in h.error
    assert h.effects == ["joint_friction"] and len(h.steps) == 2 and len(h.diagnoses) == 1
    d = h.to_dict()
    assert d["complete"] is False and "injected" in d["error"]
    assert "incomplete" in d["conclusion"] and d["conclusion"].startswith("Added joint_friction")
    json.dumps(d, allow_nan=False)
    # the CLI: exit 1, the JSON with what finished, the report written
    calls["n"] = 0
    report = tmp_path / "r.html"
    rc = dg.cli_main([str(friction_run.source), "--json", "--effects", "joint_friction,payload_mass", "--report", str(report)])
    out = json.loads(capsys.readouterr().out)
    assert rc == 1 and out["error"] and len(out["history"]) == 2
    assert report.exists() and "injected" in report.read_text(encoding="utf-8")


def test_an_interrupt_returns_the_rounds_finished_only_when_asked(nominal, friction_run, monkeypatch):
    """Ctrl-C in round 2: the library call propagates it; with ``stop_on_interrupt`` (the
    CLI) round 1 is returned, saying where it stopped."""
    calls = {"n": 0}
    orig = dgl.diagnose

    def interrupted(*a, **kw):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt("stopped by the test")
        return orig(*a, **kw)

    monkeypatch.setattr(dgl, "diagnose", interrupted)
    for mod in (dgr, dg.rank, dg.conclusion):
        monkeypatch.setattr(mod, "FLOOR_MULTIPLE", 0.0)  # so that a second round runs
    with pytest.raises(KeyboardInterrupt):
        dg.improve(nominal, friction_run, effects=["joint_friction", "payload_mass"], max_rounds=3)
    calls["n"] = 0
    h = dg.improve(nominal, friction_run, effects=["joint_friction", "payload_mass"], max_rounds=3, stop_on_interrupt=True)
    assert not h.complete and h.error == "round 2 interrupted: stopped by the test"
    assert h.effects == ["joint_friction"] and len(h.steps) == 2 and h.steps[-1].error < 0.5 * h.steps[0].error
    assert "incomplete" in h.conclusion and h.conclusion.startswith("Added joint_friction")


@pytest.mark.parametrize("how", ["SIGTERM", "time limit"])
def test_the_cli_prints_what_finished_on_sigterm_and_at_its_time_limit(nominal, friction_run, monkeypatch, capsys, how):
    """The signal arrives while round 2 runs (sent by the patched round itself, so the test
    does not depend on timing): the JSON of round 1 is printed, exit 1, and the handlers and
    the timer are put back."""
    import os
    import signal
    import time

    calls = {"n": 0}
    orig = dgl.diagnose
    timer = []
    real_setitimer = signal.setitimer
    monkeypatch.setattr(signal, "setitimer", lambda which, t, *a: timer.append(t) or real_setitimer(which, 0))
    sig = signal.SIGTERM if how == "SIGTERM" else signal.SIGALRM

    def round2_signalled(*a, **kw):
        calls["n"] += 1
        if calls["n"] == 2:
            os.kill(os.getpid(), sig)
            for _ in range(600):  # the handler raises within the first sleep
                time.sleep(0.05)
            raise AssertionError("the signal did not stop the round")
        return orig(*a, **kw)

    monkeypatch.setattr(dgl, "diagnose", round2_signalled)
    for mod in (dgr, dg.rank, dg.conclusion):
        monkeypatch.setattr(mod, "FLOOR_MULTIPLE", 0.0)
    before = (signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGALRM))
    extra = ["--time-limit", "1e4"] if how == "time limit" else []
    rc = dg.cli_main([str(friction_run.source), "--json", "--effects", "joint_friction,payload_mass", *extra])
    out = json.loads(capsys.readouterr().out)
    why = "SIGTERM received" if how == "SIGTERM" else "the time limit of 10000 s was reached"
    assert rc == 1 and out["complete"] is False and out["error"] == f"round 2 interrupted: {why}"
    assert [st["effects"] for st in out["history"]] == [[], ["joint_friction"]]
    assert (signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGALRM)) == before
    assert timer == ([1e4, 0] if how == "time limit" else [])


def test_a_bad_time_limit_is_refused(friction_run, capsys):
    for bad in ("0", "-3", "nan", "inf"):
        assert dg.cli_main([str(friction_run.source), "--json", "--time-limit", bad]) == 2
        assert "--time-limit" in capsys.readouterr().err


def test_an_effect_that_cannot_be_tried_is_named(nominal, friction_run, monkeypatch):
    orig = dgc._fit_candidate

    def broken(prob, name, *a, **kw):
        if name == "backlash":
            raise popup.StepTooLargeError("injected for backlash")
        return orig(prob, name, *a, **kw)

    monkeypatch.setattr(dgc, "_fit_candidate", broken)
    seen = []
    d = dg.diagnose(nominal, friction_run, effects=["backlash", "payload_mass"], progress=seen.append)
    s = d["backlash"]
    assert not s.tested and not s.significant and s.message.startswith("not tested: StepTooLargeError")
    assert d.suspects[-1].effect == "backlash"
    assert "ranking is incomplete" in d.conclusion and "backlash" in d.conclusion
    # then the leading candidates are refitted on their own unseen motion (popup.unseen; the
    # untested one comes back as it is): every event with the same total
    labels = [x["effect"] for x in seen]
    assert labels[:2] == ["backlash", "payload_mass"]
    assert sorted(labels[2:]) == ["backlash (own unseen motion)", "payload_mass (own unseen motion)"]
    assert {x["total"] for x in seen} == {4}
    assert s.to_dict()["tested"] is False


def test_terminal_progress_line():
    buf = io.StringIO()
    p = dg.TerminalProgress(buf)
    p({"round": 1, "effect": "joint_friction", "done": 0, "total": 10})
    p({"round": 1, "effect": "backlash", "done": 1, "total": 10})
    p.close()
    text = buf.getvalue()
    assert "round 1" in text and "backlash" in text and "1/10 fits" in text and "ETA" in text


def test_error_is_in_noise_units_and_zero_for_the_truth(nominal, friction_run):
    """The truth replays at the noise floor: each channel within 10 % of its noise."""
    truth = nominal.with_effect("joint_friction", **FRICTION)
    prob = popup.ReplayProblem(truth, friction_run)
    err, per = prob.error()
    assert err < dg.AT_FLOOR, per
    assert max(per.values()) < 1.1, per
    assert math.isclose(err, math.sqrt(max(np.mean(np.square(list(per.values()))) - 1.0, 0.0)))


@pytest.mark.parametrize("kept", [0.85, 0.3])
def test_a_small_bite_of_a_misfit_is_not_significant_however_large_its_likelihood_ratio(nominal, friction_run, kept):
    """On a misspecified model (a systematic misfit no effect explains) the likelihood ratio
    of a fit that removes a little of it is large; it is significant only if it explains at
    least MIN_EXPLAINED of the systematic error (docs/effects.md, step 5)."""
    prob = popup.ReplayProblem(nominal, friction_run)
    z0 = prob.residuals(prob.nominal_simulation())
    rng = np.random.default_rng(3)
    noise = rng.standard_normal(z0.shape)
    t = np.asarray(prob.time)[:, None]
    misfit = 2.0 * np.sin(2 * np.pi * 0.7 * t + np.arange(z0.shape[1])[None, :])  # 2 noise sigmas, every channel
    base, after = noise + misfit, noise + kept * misfit
    out = popup.estimate.FitOutcome(x=np.zeros(1), flat=nominal.effects_flat.copy(), z=after, J=np.zeros((1, 1)),
                                    weights=np.ones(z0.shape[1]), nfev=0, r=np.zeros(1), row_t=np.zeros(1))
    free = popup.estimate.free_params("payload_mass")
    f = dgc._Fitted("payload_mass", "", prob, base, free, out)
    assert f.score > 100 * dg.SCORE_THRESHOLD and f.lr_val > 0 and f.v1 < f.v0  # huge and confirmed on held-out samples
    assert f.explained == pytest.approx(1 - kept**2, abs=0.05)
    assert f.significant == (f.explained >= dg.MIN_EXPLAINED)
    assert f.significant == (kept < 0.5)


@pytest.mark.parametrize("kept", [0.1, 0.85])
def test_isolated_spikes_a_candidate_leaves_do_not_hide_what_it_explains(nominal, friction_run, kept):
    """A rattling gear's impacts, left by a fitted backlash, are isolated spikes on a motor
    torque (MuJoCo pair seed 612: 824 samples, 82 % of tau1's excess): friction beside them
    explained 93 % of tau2's error and was refused by the share rule over the torques. The
    rule now sets aside the spikes the candidate leaves untouched; a candidate that takes
    only a small bite of the smooth error is still refused, and one that removes the
    spikes is judged with them. Only for effects that act on some channels only in replay
    (the torques, for friction): one that moves the arm keeps the whole share (stand-ins,
    docs/effects.md step 5). Refitted jointly with an effect that moves the arm (on that
    run the joint refit then lost the torques' share), friction is still judged on the
    torques, net of what the refit adds on the other channels."""
    prob = popup.ReplayProblem(nominal, friction_run)
    n, C = prob.residuals(prob.nominal_simulation()).shape
    rng = np.random.default_rng(7)
    noise = rng.standard_normal((n, C))
    t = np.asarray(prob.time)
    j1, j2 = prob.channels.index("tau1"), prob.channels.index("tau2")
    smooth = np.zeros((n, C))
    # what friction explains: 3 noise sigmas on tau2, at a fifth of the sample rate (a
    # residual whose samples are nearly independent, so that its likelihood ratio is large)
    smooth[:, j2] = 3.0 * np.sin(2 * np.pi * t / (5 * float(np.median(np.diff(t)))))
    spikes = np.zeros((n, C))
    rows = rng.choice(np.flatnonzero(prob.used), size=n // 15, replace=False)
    spikes[rows, j1] = 60.0 * rng.choice([-1.0, 1.0], size=rows.size)  # impacts sharper than a sample
    base, after = noise + smooth + spikes, noise + kept * smooth + spikes
    free = popup.estimate.free_params("joint_friction")

    def fitted(z, name="joint_friction", params=free, z0=base, k=None):
        out = popup.estimate.FitOutcome(x=np.zeros(1), flat=nominal.effects_flat.copy(), z=z, J=np.zeros((1, 1)),
                                        weights=np.ones(C), nfev=0, r=np.zeros(1), row_t=np.zeros(1))
        return dgc._Fitted(name, "", prob, z0, params, out, k=k)

    f = fitted(after)
    assert f.acts == ["tau1", "tau2", "tau3"]
    assert f.score > 10 * dg.SCORE_THRESHOLD and f.lr_val > 0 and f.v1 < f.v0
    # with the spikes the torques' systematic error is mostly tau1's impacts: under the share
    share, acts, _ = dgc.share_where_it_acts(prob, "joint_friction", free, base, after, f.explained)
    ms0, _, _ = prob.channel_stats(base)
    ms1, _, _ = prob.channel_stats(after)
    idx = [prob.channels.index(c) for c in f.acts]
    raw = 1 - (np.mean(ms1[idx]) - 1) / (np.mean(ms0[idx]) - 1)
    assert raw < dgr.MIN_EXPLAINED
    assert acts == f.acts and share == f.share == pytest.approx(1 - kept**2, abs=0.05)  # the spike-free share
    assert f.significant == (kept < 0.5)
    if f.significant:
        assert "isolated spikes it leaves set aside" in f.spike_note and f"tau1 {rows.size}" in f.spike_note, f.spike_note
    # an effect that moves the arm acts on every channel: its share is the whole one
    p = fitted(after, "payload_mass", popup.estimate.free_params("payload_mass"))
    assert p.acts is None and p.spike_note == "" and p.share == p.explained < dgr.MIN_EXPLAINED and not p.significant
    # refitted jointly with an earlier effect that moves the arm (the loop's joint refit):
    # still judged on the torques, net of what the refit adds to the other channels
    joint = free + popup.estimate.free_params("payload_mass")
    imu = [prob.channels.index(c) for c in prob.channels if c.startswith("imu")]
    for worse, ok in ((0.02, kept < 0.5), (1.5, False)):
        z1 = after.copy()
        z1[:, imu] *= math.sqrt(1.0 + worse)  # each IMU channel's mean square up by that much
        jf = fitted(z1, params=joint, k=len(free))
        assert jf.acts == ["tau1", "tau2", "tau3"], jf.acts
        assert jf.significant == ok, (worse, jf.share, jf.score)
        assert (jf.share >= dgr.MIN_EXPLAINED) == (kept < 0.5 and worse < 1), (worse, jf.share)  # the IMUs paid for it
    # a candidate that removes the impacts too is judged with them (nothing set aside)
    g = fitted(noise + kept * smooth)
    assert g.spike_note == "" and g.significant
    # with nothing but noise left beside the spikes (the smooth error at the floor), the
    # share is the whole one: a tiny bite of a spiky residual is not made significant
    h = fitted(0.98 * noise + spikes, z0=noise + spikes)
    assert h.spike_note == "" and not h.significant and h.share < dgr.MIN_EXPLAINED


def test_isolated_spikes_are_named_where_the_error_is_left(nominal, friction_run, tmp_path):
    """Sensor glitches (a few samples far from their neighbours) are named with their share
    of the channel's excess; a clean run has none (8σ from a running median: ~1e-14 per sample)."""
    truth = nominal.with_effect("joint_friction", **FRICTION)
    clean = popup.ReplayProblem(truth, friction_run)
    _, per = clean.error()
    # a clean replay at the floor: nothing a conclusion would name (a friction reversal a
    # sample early can make one spike in a torque)
    named = {c: v for c, v in clean.spikes().items() if v["share"] >= dg.SPIKE_SHARE and per[c] > dg.FLOOR_MULTIPLE}
    assert named == {} and sum(v["count"] for v in clean.spikes().values()) <= 2, clean.spikes()
    df = friction_run.data.copy()
    sd = float(popup.ReplayProblem(truth, friction_run).noise["tau2"])
    rows = [400, 1500, 3100]
    y = df["tau2"].to_numpy().copy()
    y[rows] += 40.0 * sd * np.array([1.0, -1.0, 1.0])
    df["tau2"] = y
    write_run(tmp_path, dict(friction_run.experiment), df)
    run = popup.read_run(tmp_path)
    prob = popup.ReplayProblem(truth, run)
    sp = prob.spikes()
    assert sp["tau2"]["count"] == 3 and set(sp) - {"tau2"} == set(clean.spikes()), sp
    assert sp["tau2"]["share"] > 0.9 and sp["tau2"]["times"] == [float(prob.time[i]) for i in rows]
    d = popup.diagnose(truth, run, effects=["payload_mass"], problem=prob)
    assert d.significant == [] and "isolated spikes" in d.conclusion and "tau2 3 sample(s)" in d.conclusion, d.conclusion
    assert "isolated spikes" not in popup.diagnose(truth, friction_run, effects=["payload_mass"], problem=clean).conclusion
    # and in the JSON, per channel
    js = popup.improve(truth, run, effects=["payload_mass"], max_rounds=1).to_dict()
    assert js["channels"]["tau2"]["spikes"] == 3 and js["channels"]["tau2"]["spike_times"] == sp["tau2"]["times"], js["channels"]["tau2"]
    assert js["channels"]["tau2"]["spike_share"] > 0.9 and "isolated spikes" in js["conclusion"]
    json.dumps(js, allow_nan=False)


@pytest.mark.parametrize("seed", [3, 17])
def test_constant_sensor_offsets_are_named_with_their_values_where_the_error_is_left(nominal, tmp_path, seed):
    """A constant offset on a channel (an IMU's bias, a torque sensor's zero, a mocap frame's
    calibration) is no library effect: nothing is added, and the conclusion and the JSON
    give each offset's value. Cases drawn per seed: 4 of the 12 channels, 4-10 σ, either sign."""
    rng = np.random.default_rng(seed)
    t, q = popup.synth.lab_trajectory(6.0, seed=seed)
    group = {"tau": "tau", "ee_": "ee", "imu": "imu"}
    chans = [str(c) for c in rng.choice(list(popup.problem.DEFAULT_CHANNELS), size=4, replace=False)]
    bias = {c: float(rng.choice([-1.0, 1.0]) * rng.uniform(4.0, 10.0) * popup.synth.NOISE[group[c[:3]]]) for c in chans}
    run = popup.synth.measured_run(nominal, t, q, tmp_path, seed=seed,
                                   disturbance=lambda tt: {c: np.full(np.size(tt), b) for c, b in bias.items()})
    prob = popup.ReplayProblem(nominal, run)
    off = prob.offsets()
    n = int(prob.used.sum())
    for c in prob.channels:
        # white noise: the mean of n samples scatters by σ/√n (5 of them: 6e-7 two-sided)
        tol = 5.0 * prob.noise[c] / math.sqrt(n)
        assert off[c]["offset"] == pytest.approx(bias.get(c, 0.0), abs=tol), (c, off[c], bias)
        assert (off[c]["share"] > 0.95) if c in bias else (abs(off[c]["z_mean"]) < 5.0 / math.sqrt(n)), (c, off[c])
    d = popup.diagnose(nominal, run, effects=["payload_mass"], problem=prob)
    assert d.significant == [] and "constant offsets" in d.conclusion, d.conclusion
    for c in chans:
        assert f"{c} reads {off[c]['offset']:+.3g} {popup.results.UNITS[c]} off the model" in d.conclusion, d.conclusion
    h0 = popup.improve(nominal, run, effects=["payload_mass"], max_rounds=1, offsets=False)
    assert "constant offsets" in h0.conclusion and "fitted" not in h0.conclusion, h0.conclusion
    js = h0.to_dict()
    for c in prob.channels:
        assert js["channels"][c]["offset"] == pytest.approx(off[c]["offset"], rel=1e-6, abs=1e-12)
    json.dumps(js, allow_nan=False)
    assert dgl.offsets_left(h0).startswith("100 % of its excess")
    # the clean run names none, and its loop is not run again
    clean = popup.synth.measured_run(nominal, t, q, tmp_path / "clean", seed=seed)
    assert "constant offsets" not in popup.diagnose(nominal, clean, effects=["payload_mass"]).conclusion
    hc = popup.improve(nominal, clean, effects=["payload_mass"], max_rounds=1)
    assert dgl.offsets_left(hc) == "" and not hc.problem.fit_offsets and "offset" not in hc.conclusion, hc.conclusion
    # fitted with every model (offsets=True, --offsets; and by default, as what the loop left
    # is all offsets): the run is at its floor, the offsets given
    # profiled out of a batch, each member as alone: the same bits
    po = popup.ReplayProblem(nominal, run, offsets=True)
    flat = np.asarray(nominal.effects_flat, dtype=float)
    sims = po.simulate(np.array([flat, flat]))
    zb = po.residuals(sims)
    assert np.array_equal(zb[0], po.residuals(sims[0])) and np.array_equal(zb[1], zb[0])
    assert np.all(np.abs(np.nanmean(zb[0][po.used], axis=0)) < 1e-12)
    for how in (True, None):
        h = popup.improve(nominal, run, effects=["payload_mass"], max_rounds=1, offsets=how)
        assert h.problem.fit_offsets and h.effects == [] and h.steps[0].error <= dg.AT_FLOOR, h.conclusion
        assert "a constant offset was fitted" in h.conclusion and ("fitted because the pass" in h.conclusion) == (how is None), h.conclusion
        js = h.to_dict()
        for c in prob.channels:
            assert js["channels"][c]["offset"] == pytest.approx(bias.get(c, 0.0), abs=5.0 * prob.noise[c] / math.sqrt(n)), c


def test_the_cli_fits_offsets_when_asked_never_when_told_not_to_and_refuses_both(nominal, tmp_path, capsys):
    t, q = popup.synth.lab_trajectory(5.0, seed=8)
    run = popup.synth.measured_run(nominal, t, q, tmp_path, seed=8, disturbance=lambda tt: {"imu2_az": np.full(np.size(tt), 0.15)})
    out = {}
    for flag in ("--offsets", "--no-offsets", None):
        rc = dg.cli_main([str(run.source), "--json", "--effects", "payload_mass"] + ([flag] if flag else []))
        assert rc == 0
        out[flag] = json.loads(capsys.readouterr().out)
    assert "a constant offset was fitted" in out["--offsets"]["conclusion"] and "fitted because" not in out["--offsets"]["conclusion"]
    assert "imu2_az reads +0.15 m/s² off the model" in out["--no-offsets"]["conclusion"], out["--no-offsets"]["conclusion"]
    assert "fitted because the pass with constant offsets in the error added nothing" in out[None]["conclusion"]
    assert out[None]["channels"]["imu2_az"]["offset"] == pytest.approx(0.15, abs=0.005)
    with pytest.raises(SystemExit):
        dg.cli_main([str(run.source), "--offsets", "--no-offsets"])
    assert "not allowed with" in capsys.readouterr().err


def test_a_failed_pass_with_the_offsets_fitted_returns_the_first_with_a_note(nominal, tmp_path, monkeypatch):
    t, q = popup.synth.lab_trajectory(5.0, seed=8)
    run = popup.synth.measured_run(nominal, t, q, tmp_path, seed=8, disturbance=lambda tt: {"tau2": np.full(np.size(tt), -0.3)})
    real = dgl._improve

    def failing(*a, **kw):
        if kw["offsets"]:
            raise popup.StepTooLargeError("second pass broke")
        return real(*a, **kw)

    monkeypatch.setattr(dgl, "_improve", failing)
    h = popup.improve(nominal, run, effects=["payload_mass"], max_rounds=1)
    m = re.search(r"tau2 reads ([-+][0-9.]+) N·m off the model", h.conclusion)
    assert not h.problem.fit_offsets and m and float(m.group(1)) == pytest.approx(-0.3, abs=0.005), h.conclusion
    assert any("did not complete (StepTooLargeError: second pass broke)" in n for n in h.notes), h.notes
    # a whole answer, but not the one asked for: incomplete, said in the conclusion and the JSON
    assert not h.complete and "second pass broke" in h.error and "incomplete: " in h.conclusion
    assert h.to_dict()["error"] == h.error and h.steps[0].error > 1.0


def test_friction_under_torque_sensor_offsets_is_fitted_right_with_the_offsets_fitted(nominal, tmp_path):
    """Offsets on the torques break Coulomb friction's symmetry: fitted beside them, friction
    lands on its truth and the error falls to the noise (with the offsets in the error the
    fit is biased and leaves them: the loop runs again with them fitted)."""
    t, q = popup.synth.lab_trajectory(6.0, seed=3)
    bias = {"tau1": -0.34, "tau2": -0.25, "tau3": 0.23, "imu1_ay": 0.094}
    run = popup.synth.measured_run(nominal.with_effect("joint_friction", **FRICTION), t, q, tmp_path, seed=3,
                                   disturbance=lambda tt: {c: np.full(np.size(tt), b) for c, b in bias.items()})
    seen = []
    h = popup.improve(nominal, run, effects=["payload_mass", "joint_friction"], max_rounds=2, progress=seen.append)
    # the progress of the second pass says it is that pass
    assert any(str(i["effect"]).startswith("offsets fitted: ") for i in seen) and not str(seen[0]["effect"]).startswith("offsets"), seen
    assert h.problem.fit_offsets and "fitted because the pass with constant offsets in the error added joint_friction" in h.conclusion
    assert h.effects == ["joint_friction"] and h.steps[-1].error <= 0.1 * h.steps[0].error, h.conclusion
    fit = h.steps[-1].params["joint_friction"]
    assert np.allclose(fit["tau_c"], FRICTION["tau_c"], rtol=0.05) and np.allclose(fit["b"], FRICTION["b"], atol=0.05), fit
    js = h.to_dict()
    for c, b in bias.items():
        assert js["channels"][c]["offset"] == pytest.approx(b, abs=5.0 * h.noise[c] / math.sqrt(len(run.time))), c


def test_held_out_samples_an_effect_does_not_act_on_neither_confirm_nor_refute_it():
    """A torque limit reached only in training blocks leaves the held-out residual exactly as
    it was: that is 'silent', not a refutation; any change there, or a failed run (NaN), is not."""
    from popup.diagnosis.candidate import silent_on as _silent_on

    rng = np.random.default_rng(3)
    z0 = rng.standard_normal((200, 4))
    z0[5, 1] = np.nan  # a dropout in the measurement
    mask = np.zeros(200, dtype=bool)
    mask[60:120] = True
    z1 = z0.copy()
    z1[~mask] += 0.5  # acts on the training samples only
    assert _silent_on(mask, z0, z1)
    z1[100, 2] += 1e-6  # acts on one held-out sample
    assert not _silent_on(mask, z0, z1)
    assert not _silent_on(mask, z0, np.full_like(z0, np.nan))  # a failed run is not silent
    assert not _silent_on(np.zeros(200, dtype=bool), z0, z0)  # no held-out samples: nothing to say


# minutes of fitting: with -m slow (benchmarks/slow_tests.sh)
@pytest.mark.slow
def test_the_cheap_screen_fully_fits_only_its_best_and_still_finds_the_effect(nominal, tmp_path):
    """``diagnose(screen=1)`` (the loop's rounds from the third on): each candidate is fitted
    from its fit of an earlier round alone, and only the best of that screen gets the full
    multi-start fit. The earlier fits here are of the model *without* the payload (biased by
    its absence, as in the loop); friction is still found, on the truth and as the plain
    diagnosis fits it, and the others say they were only screened."""
    t, q = popup.synth.lab_trajectory(6.0, rate=250.0, seed=21)
    truth = nominal.with_effect("payload_mass", delta_kg=0.3).with_effect("joint_friction", tau_c=[1.0, 1.5, 0.5], b=[0.2, 0.2, 0.1])
    run = popup.synth.measured_run(truth, t, q, tmp_path, seed=21)
    cands = ["joint_friction", "air_drag", "sensor_delay"]
    d1 = dg.diagnose(nominal, run, effects=cands + ["payload_mass"])
    starts = dgl._prior_fits([d1])
    assert set(cands) <= set(starts)
    with_payload = nominal.with_effect("payload_mass", delta_kg=0.3)
    full = dg.diagnose(with_payload, run, effects=cands, starts=starts)
    quick = dg.diagnose(with_payload, run, effects=cands, starts=starts, screen=1)
    assert quick.best is not None and quick.best.effect == "joint_friction" and full.best.effect == "joint_friction"
    for k in ("tau_c", "b"):
        np.testing.assert_allclose(quick.best.params[k], truth.effects["joint_friction"][k], rtol=0.05, atol=0.02)
    others = [s for s in quick.suspects if s.effect != "joint_friction"]
    assert all("screened from its fit of the round before only" in s.message for s in others), [s.message for s in others]
    assert all(not s.significant for s in others)
    # the screened candidate's full fit is the plain diagnosis's
    for k in ("tau_c", "b"):
        np.testing.assert_allclose(quick.best.params[k], full.best.params[k], rtol=1e-3, atol=1e-4)
    assert quick.best.score == pytest.approx(full.best.score, rel=1e-3)
    # without earlier fits there is nothing to screen from: every candidate gets the full fit
    plain = dg.diagnose(with_payload, run, effects=cands, screen=1)
    assert not any("screened" in s.message for s in plain.suspects)


def test_a_fit_never_ends_worse_than_the_start_it_was_given(nominal, tmp_path):
    """A start close to a bound is moved a fifth of the entry's scale inside it before the
    solver runs (a start on a bound stalls it): a sensor delay fitted at 3 µs starts again at
    1 ms. The solver could end there, or in a worse basin, below the point it was handed
    (the loop's refit after adding a 0.1 ms torque delay to a fitted friction went from 0.404
    to 0.709 noise units); the start as given is kept when it is better."""
    from popup import estimate as est
    from popup.problem import ReplayProblem

    t, q = popup.synth.lab_trajectory(4.0, rate=250.0, seed=31)
    run = popup.synth.measured_run(nominal, t, q, tmp_path, seed=31)
    prob = ReplayProblem(nominal, run)
    free = est.free_params("sensor_delay", ["imu", "torque"])
    flat = nominal.effects_flat
    x0 = np.array([3e-6, 1e-4])  # beside the truth (no delay), both inside the nudge zone
    out = est.fit(prob, flat, free, x0, 1)  # one evaluation: the solver cannot get back
    f0 = flat.copy()
    for (p, i), v in zip(free, x0):
        f0[p.offset + i] = v
    z0 = prob.residuals(prob.simulate(f0[None]))[0]
    assert est._nll(prob, out.z, prob.train) <= est._nll(prob, z0, prob.train)
    np.testing.assert_array_equal(out.x, x0)
    # with room to converge it still lands on the truth
    out = est.fit(prob, flat, free, np.array([0.004, 0.004]), 15)
    assert np.all(out.x < 2e-4), out.x


@pytest.mark.parametrize("b", [[0.3, 0.3, 0.3], [0.1, 0.3, 0.6]])
def test_a_tied_fit_fits_one_value_for_its_group(nominal, tmp_path, b):
    """``tie``: the entries of a group are one unknown (one Jacobian column), started from
    their mean; on a run whose joints share the value it is found, and where they do not, the
    tied fit is worse than the fit per entry, which finds each."""
    from popup.problem import ReplayProblem

    t, q = popup.synth.lab_trajectory(4.0, rate=250.0, seed=41)
    truth = nominal.with_effect("joint_friction", tau_c=[0.0, 0.0, 0.0], b=b)
    run = popup.synth.measured_run(truth, t, q, tmp_path, seed=41)
    prob = ReplayProblem(nominal, run)
    free = est.free_params("joint_friction", ["b"])
    flat = nominal.effects_flat
    x0 = np.array([0.05, 0.1, 0.2])
    tied = est.fit(prob, flat, free, x0, 15, tie=[[0, 1, 2]])
    each = est.fit(prob, flat, free, x0, 15)
    assert tied.J.shape[1] == 1 and each.J.shape[1] == 3
    assert tied.x[0] == tied.x[1] == tied.x[2]
    np.testing.assert_allclose(each.x, b, rtol=0.03, atol=0.01)
    if len(set(b)) == 1:
        assert abs(tied.x[0] - b[0]) < 0.05 * b[0], tied.x
    else:
        assert est._nll(prob, tied.z, prob.train) > est._nll(prob, each.z, prob.train) + 100.0


def test_tie_groups_name_a_bad_group():
    assert est.tie_groups(4, [[1, 3]]) == [[0], [1, 3], [2]]
    assert est.tie_groups(3, None) == [[0], [1], [2]]
    for bad, what in (([[0, 3]], "out of range"), ([[0, 1], [1, 2]], "in two groups")):
        with pytest.raises(popup.PopupError, match=what) as e:
            est.tie_groups(3, bad)
        assert isinstance(e.value, ValueError)


def test_the_compliant_flanks_share_their_law_for_one_more_start():
    """The compliant flanks (alone and combined with the fitted link side) are also fitted
    with one flank law and link side on every joint (:func:`candidate._shared_groups`), the
    gaps per joint."""
    flanks = dgc._variant_named("backlash", "compliant flanks")
    both = dgc._variant_named("backlash", "fitted link-side inertia + compliant flanks")
    assert set(flanks["shared"]) == set(both["shared"]) == {"contact_k", "contact_c", "inertia"}
    free = est.free_params("backlash", ["gap", "inertia", "contact_k", "contact_c"])
    groups = dgc._shared_groups(free, "backlash", both["shared"])
    assert sorted(free[g[0]][0].name for g in groups) == ["contact_c", "contact_k", "inertia"]
    assert all(len(g) == 3 and len({free[j][0].name for j in g}) == 1 for g in groups)
    assert dgc._untied(free, "backlash", groups) == [j for j, (p, _) in enumerate(free) if p.name == "gap"]
    assert dgc._shared_groups(free[:4], "backlash", both["shared"]) == []  # one inertia entry: nothing to share


def test_a_candidate_refitted_with_the_added_effects_applies_them_as_refitted(nominal, tmp_path):
    """From round 2 a candidate is refitted jointly with the effects already added; its
    ``error_after`` is that joint fit's, so ``Suspect.apply`` sets the added effects at their
    refitted values too. Before, only the candidate's own values were set: the loop's refit
    started from the added effects at their old values and could end above the model it
    had before the addition (a MuJoCo friction run: 0.527 → 0.698 after a sensor delay whose
    joint fit had predicted 0.404, then a pressure leak added to win the difference back)."""
    t, q = popup.synth.lab_trajectory(6.0, rate=250.0, seed=21)
    truth = nominal.with_effect("payload_mass", delta_kg=0.3).with_effect("joint_friction", tau_c=[1.0, 1.5, 0.5], b=[0.2, 0.2, 0.1])
    run = popup.synth.measured_run(truth, t, q, tmp_path, seed=21)
    current = nominal.with_effect("payload_mass", delta_kg=0.2)  # an earlier round's fit, biased by the missing friction
    d = dg.diagnose(current, run, effects=["joint_friction"], refit={"payload_mass": ["delta_kg"]})
    s = d["joint_friction"]
    assert s.significant and "refitted with payload_mass" in s.message, s.message
    assert s.refitted["payload_mass"]["delta_kg"][0] == pytest.approx(0.3, abs=0.01), s.refitted
    err, _ = dg.model_error(s.apply(current), run, problem=d.problem)
    assert err == pytest.approx(s.error_after, rel=1e-6, abs=1e-9)
    # the candidate's values alone leave the payload where it was: a worse model
    alone = current.with_effect("joint_friction", **s.params)
    assert dg.model_error(alone, run, problem=d.problem)[0] > 2 * s.error_after + 0.5
    assert s.to_dict()["refitted"]["payload_mass"]["delta_kg"] == s.refitted["payload_mass"]["delta_kg"]


def test_a_candidate_is_not_credited_with_the_refit_gain_of_the_added_effects(nominal, tmp_path):
    """A candidate refitted jointly with an added effect that sat off its optimum gains the
    refit's improvement too; the test compares it with the added effect refitted alone (at
    the joint fit's values, the candidate neutral). With a payload the only truth and its
    earlier fit off (0.2 of 0.3 kg), air drag refitted beside it must not be significant:
    the gain is the payload's (MuJoCo pair 661-010, where drag at cd ≈ 2e-12 scored 290).
    Friction, which the same run with friction needs, stays significant."""
    t, q = popup.synth.lab_trajectory(6.0, rate=250.0, seed=27)
    truth = nominal.with_effect("payload_mass", delta_kg=0.3)
    run = popup.synth.measured_run(truth, t, q, tmp_path / "payload", seed=27)
    current = nominal.with_effect("payload_mass", delta_kg=0.2)  # an earlier round's fit that sits off
    d = dg.diagnose(current, run, effects=["air_drag"], refit={"payload_mass": ["delta_kg"]})
    s = d["air_drag"]
    assert s.refitted["payload_mass"]["delta_kg"][0] == pytest.approx(0.3, abs=0.02), s.refitted
    assert "refitted alone" in s.message, s.message
    assert not s.significant and s.score < dgr.SCORE_THRESHOLD, (s.score, s.message)
    assert d.best is None
    # a candidate the run does need still passes against the same null point
    truth_f = truth.with_effect("joint_friction", tau_c=[1.0, 1.5, 0.5], b=[0.2, 0.2, 0.1])
    run_f = popup.synth.measured_run(truth_f, t, q, tmp_path / "friction", seed=27)
    f = dg.diagnose(current, run_f, effects=["joint_friction"], refit={"payload_mass": ["delta_kg"]})["joint_friction"]
    assert f.significant and f.score > 10 * dgr.SCORE_THRESHOLD, (f.score, f.message)


def test_joint_fits_every_candidate_with_the_added_effects_from_its_seeds(nominal, tmp_path):
    """``diagnose(joint=True)`` (the base-law step's candidates never significant before): each
    candidate is fitted jointly with the effects of ``refit`` from its seeds, not first with
    them held and then only the best :data:`JOINT_TOP` refitted. With four candidates the
    plain diagnosis leaves one held; with ``joint`` every candidate carries the refitted
    payload, and friction is found with the payload back at the truth."""
    t, q = popup.synth.lab_trajectory(4.0, rate=250.0, seed=23)
    truth = nominal.with_effect("payload_mass", delta_kg=0.3).with_effect("joint_friction", tau_c=[1.0, 1.5, 0.5], b=[0.2, 0.2, 0.1])
    run = popup.synth.measured_run(truth, t, q, tmp_path, seed=23)
    current = nominal.with_effect("payload_mass", delta_kg=0.2)
    cands = ["joint_friction", "air_drag", "sensor_delay", "pressure_leak"]
    assert len(cands) > dg.JOINT_TOP
    held = dg.diagnose(current, run, effects=cands, refit={"payload_mass": ["delta_kg"]}, max_iter=8)
    assert sum(bool(s.refitted) for s in held.suspects if s.tested) <= dg.JOINT_TOP < len(cands)
    d = dg.diagnose(current, run, effects=cands, refit={"payload_mass": ["delta_kg"]}, max_iter=8, joint=True)
    tested = [s for s in d.suspects if s.tested]
    assert len(tested) == len(cands) and all("payload_mass" in s.refitted for s in tested), [(s.effect, s.refitted) for s in tested]
    assert not any("refitted with payload_mass (score" in s.message for s in tested)  # no held fit came first
    b = d.best
    assert b is not None and b.effect == "joint_friction", [(s.effect, s.score) for s in d.suspects]
    assert b.refitted["payload_mass"]["delta_kg"][0] == pytest.approx(0.3, abs=0.01), b.refitted


# minutes of fitting: with -m slow (benchmarks/slow_tests.sh)
@pytest.mark.slow
def test_the_swap_offers_only_candidates_some_round_found_significant(nominal, tmp_path, monkeypatch):
    """The loop's swap step (an effect added earlier replaced by another) offers only the
    candidates that some round's diagnosis found significant, each (effect, candidate)
    pair once, and says in ``History.notes`` what it tried."""
    t, q = popup.synth.lab_trajectory(6.0, rate=250.0, seed=23)
    # a sensor delay the candidates leave out keeps the model above its floor after the
    # pair is in (the swap is not tried at the floor: nothing is left to gain)
    truth = (nominal.with_effect("payload_mass", delta_kg=0.3).with_effect("joint_friction", tau_c=[1.0, 1.5, 0.5], b=[0.2, 0.2, 0.1])
             .with_effect("sensor_delay", imu=[0.001]))
    run = popup.synth.measured_run(truth, t, q, tmp_path, seed=23)
    offered = []
    real = dgl._try_swap

    def spy(prob, run_, cprob, effect, added, fitted, pool, *rest):
        offered.append((effect, list(pool), list(added)))
        return real(prob, run_, cprob, effect, added, fitted, pool, *rest)

    monkeypatch.setattr(dgl, "_try_swap", spy)
    h = dg.improve(nominal, run, effects=["payload_mass", "joint_friction", "air_drag", "wrinkling"], max_rounds=2)
    assert not h.error, h.error
    assert set(h.effects) == {"payload_mass", "joint_friction"}
    sig = dgl._significant_in(h.diagnoses)
    assert len(sig) > 2, sig  # stand-ins were significant in round 1: there is something to swap in
    assert offered, "no swap was tried"
    pairs = [(e, c) for e, pool, _ in offered for c in pool]
    assert len(pairs) == len(set(pairs))  # each pair once
    for e, pool, added in offered:
        assert pool and set(pool) <= set(sig) and not set(pool) & set(added)
    assert len(h.notes) == len(offered) and all(n.startswith("swap of ") for n in h.notes), h.notes


def _coloured_payload_run(nominal, tmp_path):
    """A payload 0.4 kg off the nominal, IMU noise through a sensor's 45 Hz 2-pole low-pass
    at 200 Hz (8 s lab plan): (run, truth model, the IMU channels, each one's true σ)."""
    from scipy.signal import butter, lfilter

    t, q = popup.synth.lab_trajectory(8.0, rate=200.0, seed=29)
    rng = np.random.default_rng(3)
    b, a = butter(2, 45.0 / 100.0)
    imu = ["imu1_ax", "imu1_ay", "imu1_az", "imu2_ax", "imu2_ay", "imu2_az"]
    true = {}

    def coloured(tt):
        out = {}
        for c in imu:
            x = 0.007 * lfilter(b, a, rng.normal(0.0, 1.0, len(tt) + 200))[200:]
            true[c] = float(np.std(x))
            out[c] = x
        return out

    truth = nominal.with_effect("payload_mass", delta_kg=0.4)
    run = popup.synth.measured_run(truth, t, q, tmp_path, seed=29, noise={"tau": 0.05, "ee": 2e-4, "imu": 0.0}, disturbance=coloured)
    return run, truth, imu, true


def test_noise_floors_a_large_misfit_biased_are_re_estimated_as_the_model_improves(nominal, tmp_path, monkeypatch):
    """The noise floors come from the nominal residual. Under a large misfit (a payload
    0.4 kg off) the estimator is biased: down by 4× on channels whose noise is coloured (a
    sensor's 45 Hz low-pass at 200 Hz: neighbouring samples alike, and the misfit's rough
    part hides the colour), up on others. A refitted model's residual gives each channel's
    noise back; the loop takes it, decides in it and says so.

    Here each channel is its own sensor kind (a lab whose IMU axes share nothing), so no
    kin lends its colour (:func:`popup.noise.noise_stds`; with the registry's kinds the other
    IMU axes resolve it and no first floor is below 0.8 ×:
    ``test_the_kin_colour_mends_the_first_floors_of_that_run``)."""
    import popup.problem as pm
    from popup.problem import ReplayProblem

    monkeypatch.setattr(pm, "SENSORS", {c: c for c in pm.CHANNELS})

    run, truth, imu, true = _coloured_payload_run(nominal, tmp_path)
    p0 = ReplayProblem(nominal, run, threads=0)
    assert min(p0.noise[c] / true[c] for c in imu) < 0.5  # the bias the check is for
    cp = p0.with_model(truth)
    new = cp.noise_from()
    for c in imu:
        assert new[c] == pytest.approx(true[c], rel=0.15), (c, new[c], true[c])
    e, per = cp.error()
    assert e > 1.0  # the truth looks far from its floor in the biased units
    off = dgl._noise_recheck(cp)
    up = {c for c, r in off.items() if r > 1.5}
    assert len(up) >= 2 and up <= set(imu), off  # the coloured channels found back up
    st0 = dgl._step(cp, ["payload_mass"], {}, 1)
    assert not dg.results.step_at_floor(st0, cp)  # in the first floors the truth is not at its floor: the loop would go on
    st = st0.in_floors(off)
    assert st.error < 0.3 and max(st.channel_error.values()) < 1.2, st.channel_error
    # floors estimated from the right model: nothing to re-estimate
    pt = ReplayProblem(truth, run, threads=0)
    assert dgl._noise_recheck(pt) == {}
    # the loop re-estimates them on the refitted model and decides in them: at the floor
    # after round 1, no second round is diagnosed (in the first floors the truth sits at
    # S > 1, above the floor, and the other candidates would be tried)
    h = dg.improve(nominal, run, effects=["payload_mass", "sensor_delay", "air_drag"], max_rounds=3)
    assert h.effects == ["payload_mass"] and len(h.diagnoses) == 1, (h.effects, len(h.diagnoses))
    assert h.steps[-1].error < 0.3 and h.steps[0].error > 10
    for c in up:
        assert h.noise_initial[c] < 0.5 * true[c] and h.noise[c] == pytest.approx(true[c], rel=0.2), (c, h.noise[c], true[c])
    assert h.notes and h.notes[-1].startswith("round 1: the noise floors re-estimated from the residual of the model with payload_mass")
    assert "the history's errors are in noise floors re-estimated on a refitted model" in h.conclusion
    assert "what is left is at the noise floor" in h.conclusion and "not explained by the library" not in h.conclusion
    js = h.to_dict()
    c = sorted(up)[0]
    assert js["noise"][c] == pytest.approx(h.noise[c]) and js["noise_initial"][c] == pytest.approx(h.noise_initial[c])
    # every step is in the final floors: the nominal step rescaled from the first floors
    from popup.unseen import fit_unseen_motion

    per0 = fit_unseen_motion(p0).error()[1]
    for ch in per0:
        assert h.steps[0].channel_error[ch] == pytest.approx(per0[ch] * h.noise_initial[ch] / h.noise[ch], rel=1e-9)
    assert js["nominal_error"] == pytest.approx(h.steps[0].error)
    assert js["channels"][c]["encoder_floor"] == pytest.approx(h.problem.encoder_floor[c])
    assert js["rounds"][0]["noise"][c] == pytest.approx(h.noise_initial[c])  # a round keeps the floors it was computed in


def test_the_kin_colour_mends_the_first_floors_of_that_run(nominal, tmp_path):
    """The run of the test above with the registry's sensor kinds: the IMU axes whose colour
    the misfit hides take it from the axes that resolve it: alone two read 0.24-0.27 × the
    noise added, with their kin none is below 0.8 × (nor above 1.5 ×: the axes that resolve
    the colour carry 25-45 % of the misfit at their plateau's stride, as they did before)."""
    from popup.noise import CORRELATION_S, noise_std
    from popup.problem import ReplayProblem

    run, _, imu, true = _coloured_payload_run(nominal, tmp_path)
    p0 = ReplayProblem(nominal, run, threads=0)
    z = p0.nominal_simulation() - p0.measured
    alone = {c: noise_std(p0.time, z[:, p0.channels.index(c)], correlation_s=CORRELATION_S) for c in imu}
    assert min(alone[c] / true[c] for c in imu) < 0.5, alone
    for c in imu:
        assert 0.8 < p0.noise[c] / true[c] < 1.5, (c, p0.noise[c] / true[c])


def test_friction_is_judged_on_the_torques_beside_an_imu_error_no_effect_explains(nominal, tmp_path):
    """Friction acts on the motor torques only in replay: beside a large systematic IMU error
    that nothing in the library explains (here a 7 Hz wobble added to the IMUs' z axes, as
    a gear rattling in a wide gap differently from the model does), the share rule is
    applied to the torques. Friction is found although it explains a few % of the whole
    error; the payload, which acts on every channel, is not made significant by it."""
    t, q = popup.synth.lab_trajectory(6.0, seed=13)
    truth = nominal.with_effect("joint_friction", tau_c=[1.0, 1.4, 0.5], b=[0.2, 0.2, 0.1])
    run = popup.synth.measured_run(truth, t, q, tmp_path, seed=13)
    df = run.data.copy()
    tt = df["t"].to_numpy()
    for c in ("imu1_az", "imu2_az"):
        df[c] = df[c] + 1.5 * np.sin(2 * np.pi * 7.0 * tt)
    write_run(tmp_path, dict(run.experiment), df, overwrite=True)
    run = popup.read_run(tmp_path)
    d = dg.diagnose(nominal, run, effects=["joint_friction", "payload_mass"])
    fr = next(s for s in d.suspects if s.effect == "joint_friction")
    pm = next(s for s in d.suspects if s.effect == "payload_mass")
    assert fr.explained < dgr.MIN_EXPLAINED, fr.explained  # the whole error: mostly the IMU wobble
    assert fr.significant and "the only channels it acts on" in fr.message, (fr.score, fr.explained, fr.message)
    assert not pm.significant
    np.testing.assert_allclose(fr.params["tau_c"], [1.0, 1.4, 0.5], rtol=0.15)
    # the rule reads the core's registry: friction acts on the torques, a payload on everything
    assert popup.effects.acts_only_on("joint_friction", ["tau_c", "b"], d.problem.channels) == ["tau1", "tau2", "tau3"]
    assert popup.effects.acts_only_on("payload_mass", ["delta_kg"], d.problem.channels) is None


def test_the_compliant_flanks_variant_is_run_at_a_step_every_plausible_flank_allows():
    """The step of the compliant-flanks variant comes from the linearised stability limit of
    the gear at its stiffest plausible flank, with the margin. A flank exists only past a
    gap, so the check model needs one on every joint: with the gap left at 0 the flank was
    not in the linearisation (a 39 ms limit) and the variant ran at the run's 1 ms, where
    stiff, damped flanks diverge (a MuJoCo backlash run: "variant compliant flanks not
    tested: DivergenceError ... joint d22"). The step chosen must be stable at every corner
    of the fitted box (k_c, c_c) up to the check's damping (rules.FLANK_CHECK_DAMPING), the
    overdamped soft flank included, and at every corner of the whole box on a link side of
    0.03 kg·m²; past the check's damping on the default 0.01 kg·m² the soft flank's fast root
    c/J is not carried (session 69: the step the whole box needs there is 2.8 × smaller), and
    such a flank is refused by its rollout's own step check, outside the fit's region."""
    var = next(v for v in dgr.VARIANTS["backlash"] if v["name"] == "compliant flanks")
    m = popup.Model("popup-lab").with_effect("backlash", **var["structure"])
    check = m.with_effect("backlash", **var["stiffest"])
    q0 = [0.1, 0.4, 0.5]

    def limit(model):
        return model.with_dt(1.0).stable_dt([float(x) for x in model.rest_state(q0)], replay=True)

    assert all(g > 0 for g in check.effects["backlash"]["gap"])
    assert limit(check.with_effect("backlash", gap=[0.0] * 3)) > 1e-2  # no gap, no flank: only the arm's own modes
    step = dgr.STABILITY_MARGIN * limit(check)
    assert step < 1e-3  # the run's own step is not enough for the stiffest flank
    (k_lo, k_hi), (c_lo, c_hi) = est.BOUNDS[("backlash", "contact_k")], est.BOUNDS[("backlash", "contact_c")]
    assert c_lo < dgr.FLANK_CHECK_DAMPING < c_hi
    for k in (k_lo, k_hi):
        for c in (c_lo, dgr.FLANK_CHECK_DAMPING):
            corner = check.with_effect("backlash", contact_k=[k] * 3, contact_c=[c] * 3)
            assert step < limit(corner), (k, c, step, limit(corner))
        for c in (c_lo, c_hi):
            heavier = check.with_effect("backlash", contact_k=[k] * 3, contact_c=[c] * 3, inertia=[0.03] * 3)
            assert step < limit(heavier), (k, c, step, limit(heavier))
    soft = check.with_effect("backlash", contact_k=[k_lo] * 3, contact_c=[c_hi] * 3)
    assert limit(soft) < step, (step, limit(soft))


@pytest.mark.parametrize("frac", [0.9, 0.97])
def test_a_torque_limit_the_measured_torque_passes_is_refused(nominal, friction_run, tmp_path, frac):
    """A torque limit leaves the measured torque level at it wherever the command asks for
    more; a fitted limit that the measurement passes only trims the model's peaks (MuJoCo
    pair 612: a 22.9 N·m limit on joint 1 added in round 3 with 965 measured samples of tau1
    above it, up to 31 N·m). Limits drawn at 90 and 97 % of joint 2's peak torque."""
    flat_of = lambda tm: nominal.with_effect("actuator_saturation", tau_max=tm).effects_flat  # noqa: E731
    prob = popup.ReplayProblem(nominal, friction_run)
    peak = [float(np.nanmax(np.abs(friction_run.data[f"tau{j + 1}"].to_numpy()))) for j in range(3)]
    # no limit in the run: a limit below a joint's peak is passed by the measurement, one
    # above every measured sample never is
    why = dgc.limit_passed(prob, "actuator_saturation", flat_of([1e3, frac * peak[1], 1e3]))
    assert why.startswith("not significant: tau2 passes its tau_max") and "tau1" not in why, why
    assert dgc.limit_passed(prob, "actuator_saturation", flat_of([1e3, 1.01 * peak[1], 1e3])) == ""
    assert dgc.limit_passed(prob, "backlash", flat_of([1e3, frac * peak[1], 1e3])) == ""  # no limit in that law
    # a real limit at that level: its measured torque is level at it, and the fitted limit stands
    lim = frac * peak[1]
    t, q = popup.synth.lab_trajectory(8.0, seed=11)
    run = popup.synth.measured_run(nominal.with_effect("actuator_saturation", tau_max=[1e3, lim, 1e3]), t, q, tmp_path, seed=11)
    sat = popup.ReplayProblem(nominal, run)
    assert dgc.limit_passed(sat, "actuator_saturation", flat_of([1e3, lim, 1e3])) == ""
    # a limit fitted well below the plateau is passed by it
    assert dgc.limit_passed(sat, "actuator_saturation", flat_of([1e3, 0.8 * lim, 1e3])).startswith("not significant: tau2")
    # in the candidate's test: a fit that lowers the error a lot is still refused when the
    # measurement passes its limit, and the message says why
    n, C = prob.residuals(prob.nominal_simulation()).shape
    noise = np.random.default_rng(3).standard_normal((n, C))
    trimmed = np.zeros((n, C))
    trimmed[:, prob.channels.index("tau2")] = 3.0 * np.sin(2 * np.pi * np.asarray(prob.time) / (5 * float(np.median(np.diff(prob.time)))))
    z0, z1 = noise + trimmed, noise + 0.2 * trimmed
    free = popup.estimate.free_params("actuator_saturation")
    for tm, ok in (([1e3, frac * peak[1], 1e3], False), ([1e3, 1.01 * peak[1], 1e3], True)):
        out = popup.estimate.FitOutcome(x=np.zeros(1), flat=flat_of(tm), z=z1, J=np.zeros((1, 1)), weights=np.ones(C), nfev=0,
                                        r=np.zeros(1), row_t=np.zeros(1))
        f = dgc._Fitted("actuator_saturation", "", prob, z0, free, out)
        assert f.score > dg.SCORE_THRESHOLD and f.share >= dgr.MIN_EXPLAINED
        assert f.significant == ok and (f.unresolved == "") == ok, f.unresolved


def test_a_play_whose_interval_holds_zero_is_not_a_finding(nominal, friction_run):
    """A backlash is a finding only where some joint's gap clears one encoder reading by its
    95 % interval (MuJoCo nominal 677-003, 200 Hz trapezoids,
    12-bit encoders, quiet sensors: gaps of 0.15/0.52/0.28 readings ± 0.13/5.1/11 readings
    with a free link-side inertia were added, 0.70 → 0.54 noise units). The width rule alone
    passed it: joint 2's play is just over half a reading."""
    import types

    w = np.full(3, 1.534e-5)
    prob = types.SimpleNamespace(encoder_width=w)
    flat = np.zeros(len(nominal.effects_flat))
    sl = popup.effects.EFFECTS["backlash"].params["gap"].slice
    flat[sl] = np.array([0.15, 0.52, 0.28]) * w
    seen = {"gap": list(np.array([0.13, 5.11, 10.78]) * w)}
    why = dgc.unpinned_play(prob, "backlash", flat, seen)
    assert why.startswith("not significant: its gap") and "not pinned down" in why, why
    assert dgc.unresolved_play(prob, "backlash", flat) == ""  # the width rule alone lets it in
    # one joint clear of one reading by its interval is enough; a narrow joint pinned is
    # not; inf (not identifiable) is not pinned; nan (not fitted) leaves that joint to the
    # width rule
    assert dgc.unpinned_play(prob, "backlash", flat, {"gap": [0.13 * w[0], 0.4 * w[1], 10.78 * w[2]]}).startswith("not significant")
    flat[sl] = np.array([0.15, 1.6, 0.28]) * w
    assert dgc.unpinned_play(prob, "backlash", flat, {"gap": [0.13 * w[0], 0.4 * w[1], 10.78 * w[2]]}) == ""
    # MuJoCo nominal 685-009: a held play of 1.01 ± 0.03 readings on joint 1, what the
    # encoder's dither between two readings stands in for, is refused; the least clear play
    # of an archived run with a hidden backlash (popup 622: 2.91 ± 1.67 readings) is kept
    flat[sl] = np.array([1.01, 0.06, 0.20]) * w
    why = dgc.unpinned_play(prob, "backlash", flat, {"gap": list(np.array([0.03, 0.13, 0.22]) * w)})
    assert why.startswith("not significant") and "dithering" in why, why
    flat[sl] = np.array([1.02, 2.91, 2.21]) * w
    assert dgc.unpinned_play(prob, "backlash", flat, {"gap": list(np.array([0.01, 1.67, 3.21]) * w)}) == ""
    flat[sl] = np.array([0.45, 0.52, 0.28]) * w
    assert dgc.unpinned_play(prob, "backlash", flat, {"gap": [0.01 * w[0], math.inf, 0.01 * w[2]]}).startswith("not significant")
    assert dgc.unpinned_play(prob, "backlash", flat, {"gap": [math.nan, math.nan, math.nan]}) == ""
    assert dgc.unpinned_play(prob, "payload_mass", flat, seen) == ""  # no play in that law
    assert dgc.unpinned_play(types.SimpleNamespace(encoder_width=np.zeros(3)), "backlash", flat, seen) == ""  # exact encoder

    # in the candidate's test: the same fit, with a gap the data pin down or not (the
    # Jacobian's column sets its interval), is kept or refused, and says why
    real = popup.ReplayProblem(nominal, friction_run)
    wr = real.encoder_width
    n, C = real.residuals(real.nominal_simulation()).shape
    rng = np.random.default_rng(4)
    noise = rng.standard_normal((n, C))
    signal = np.zeros((n, C))
    signal[:, real.channels.index("tau2")] = 3.0 * np.sin(2 * np.pi * np.asarray(real.time) / 0.5)
    z0, z1 = noise + signal, noise + 0.2 * signal
    free = popup.estimate.free_params("backlash", ["gap"])
    gflat = nominal.with_effect("backlash", gap=[3.0 * wr[0], 0.0, 0.0]).effects_flat
    for col, ok in ((1e7, True), (1e3, False)):
        m = 400
        J = np.zeros((m, 3))
        J[:, 0] = col * rng.standard_normal(m)
        J[:, 1:] = 1e7 * rng.standard_normal((m, 2))
        out = popup.estimate.FitOutcome(x=np.asarray(gflat[sl], float), flat=gflat, z=z1, J=J, weights=np.ones(C), nfev=0,
                                        r=1e-3 * rng.standard_normal(m), row_t=np.linspace(0.0, 8.0, m))
        f = dgc._Fitted("backlash", "", real, z0, free, out)
        assert f.score > dg.SCORE_THRESHOLD and f.share >= dgr.MIN_EXPLAINED and f.unresolved == ""
        assert f.significant == ok and (f.unpinned == "") == ok, f.unpinned
        s = f.suspect({}, 0)
        assert s.ci95["gap"][0] < 3.0 * wr[0] if ok else s.ci95["gap"][0] >= 3.0 * wr[0], s.ci95
        assert ("not pinned down" in s.message) != ok, s.message


@pytest.mark.parametrize("base_score, tried_inertia", [(56.0, True), (5.0, False)])
def test_a_base_law_the_likelihood_favours_has_its_refinements_tried(monkeypatch, base_score, tried_inertia):
    """A base fit above the BIC threshold that fails the share (or held-out) test still has
    its refinements fitted, and a significant one is kept: on MuJoCo seed 628 the backlash
    gaps alone explained 35 % of the error (below the 40 % rule) where the law with its
    link-side inertia explains 49 %. A base below the threshold gets only its alternatives."""
    import types

    n = max(p.slice.stop for p in popup.effects.EFFECTS["backlash"].params.values())
    calls = []

    class Fake:
        def __init__(self, variant, score, significant):
            self.variant, self.score, self.significant, self.unresolved, self.free, self.k = variant, score, significant, "", [], 1
            self.unpinned, self.unpredictable_after = "", None
            # residual grids of their own (shape differs per fit): _gain compares scores
            self.out = types.SimpleNamespace(flat=np.zeros(n), z=np.zeros((len(calls), 1)))
            self.prob = types.SimpleNamespace(time=np.zeros(len(calls)))

        def suspect(self, ev, nfev, message=""):
            return types.SimpleNamespace(variant=self.variant, significant=self.significant, message=message)

    def fake_fit(prob, name, structure, only, start, extra_seeds, max_iter, variant="", **kw):
        calls.append(variant)
        if variant == "":
            return Fake("", base_score, False), ""
        if variant == "fitted link-side inertia":
            return Fake(variant, 200.0, True), ""
        return Fake(variant, -5.0, False), ""

    monkeypatch.setattr(dgc, "_fit_candidate", fake_fit)
    s = dgc.try_effect(types.SimpleNamespace(nfev=0, horizon=None), "backlash", {}, 15)
    assert ("fitted link-side inertia" in calls) == tried_inertia, calls
    assert "held link side (play operator)" in calls  # an alternative law: tried either way
    assert (s.variant, s.significant) == (("fitted link-side inertia", True) if tried_inertia else ("", False)), s
    # a variant marked on_horizon is tried only on a problem cut at its predictable horizon
    assert "compliant flanks and link side" not in calls
    calls.clear()
    dgc.try_effect(types.SimpleNamespace(nfev=0, horizon=5.0), "backlash", {}, 15)
    assert ("compliant flanks and link side" in calls) == tried_inertia, calls


def _spectrum(rows):
    import pandas as pd

    return pd.DataFrame({"peak_hz": [r[1] for r in rows], "line_fraction": [r[2] for r in rows],
                         "line_halfwidth_hz": [0.16] * len(rows), "dominant_band": ["1-2 Hz"] * len(rows)},
                        index=[r[0] for r in rows])


def test_the_unexplained_error_names_every_line_not_only_the_worst_channels():
    """A periodic torque on a bending joint drives some channels at its own frequency and can
    leave a mode it excites as the worst channel's line (MuJoCo disturbance 675-003: 3.34 Hz
    on imu2_az, the 1.458 Hz forcing on imu2_ay, ee_z, tau2). The conclusion names both, each
    line once, with the channels that carry it; channels at their floor, broadband residuals
    and constant offsets are not named as lines."""
    import types

    import pandas as pd

    from popup.diagnosis import conclusion as dgk

    sp = _spectrum([("imu2_az", 3.341, 0.95), ("imu2_ay", 1.457, 0.81), ("ee_z", 1.458, 0.94), ("tau1", 3.340, 0.96),
                    ("tau2", 1.457, 0.83), ("imu1_ay", 11.5, 0.25), ("ee_x", 5.0, 0.99)])
    per = {"imu2_az": 32.0, "imu2_ay": 29.0, "ee_z": 27.0, "tau1": 20.0, "tau2": 10.0, "imu1_ay": 5.0, "ee_x": 0.9}
    windows = pd.DataFrame({"rank": [1], "t_start": [8.75], "t_end": [10.0], "error_share": [0.15]})
    d = types.SimpleNamespace(channel_error=per, problem=None, comparison=types.SimpleNamespace(windows=windows, spectrum=sp))
    txt = dgk._where(d)
    assert "imu2_az's residual is concentrated in a line at 3.341 Hz" in txt, txt
    other = txt.split("other lines in the residual: ", 1)[1]
    assert other.startswith("1.457 Hz on imu2_ay (81 %), ee_z (94 %), tau2 (83 %)"), txt
    assert "tau1" not in other and "imu1_ay" not in other and "ee_x" not in other, txt   # c0's line, broadband, at its floor
    # one line only: nothing more is said
    sp1 = _spectrum([("imu2_az", 1.7, 0.95), ("ee_z", 1.701, 0.9)])
    d1 = types.SimpleNamespace(channel_error={"imu2_az": 9.0, "ee_z": 4.0}, problem=None,
                               comparison=types.SimpleNamespace(windows=windows, spectrum=sp1))
    assert "other lines" not in dgk._where(d1)
    # at most OTHER_LINES further lines, the worst channels' first
    many = [("a", 1.0, 0.9)] + [(f"c{i}", 2.0 + i, 0.9) for i in range(4)]
    per_m = {"a": 10.0, **{f"c{i}": 9.0 - i for i in range(4)}}
    assert dgk._other_lines(_spectrum(many), per_m, "a", {}) == "; other lines in the residual: 2 Hz on c0 (90 %); 3 Hz on c1 (90 %)"
    # a channel read as a constant offset is not a line
    assert dgk._other_lines(_spectrum(many), per_m, "a", {"c0": {}}).startswith("; other lines in the residual: 3 Hz on c1")


@pytest.mark.parametrize("stribeck", [True, False])
def test_a_richer_law_is_tried_again_with_every_effect_in(nominal, tmp_path, stribeck):
    """After the rounds, an effect in the model is tried again with each richer law that only
    adds parameters (:func:`loop._try_richer_laws`): a Stribeck truth fitted at the base law
    gets its Stribeck terms back (a pair of friction and a leak ended at 2.84 noise units
    with "not explained by the library" where the Stribeck law replays at 0.23); a base-law
    truth keeps its law."""
    from popup.problem import ReplayProblem
    from popup.unseen import fit_unseen_motion

    t, q = popup.synth.lab_trajectory(5.0, rate=250.0, seed=51)
    law = dict(FRICTION) if stribeck else {**FRICTION, "tau_s": [0.0, 0.0, 0.0]}
    run = popup.synth.measured_run(nominal.with_effect("joint_friction", **law), t, q, tmp_path, seed=51)
    base = nominal.with_effect("joint_friction", tau_c=FRICTION["tau_c"], b=FRICTION["b"])
    cprob = fit_unseen_motion(ReplayProblem(base, run))
    notes: list = []
    out = dgl._try_richer_laws(cprob, ["joint_friction"], {"joint_friction": ["tau_c", "b"]}, 15, None, notes)
    assert len(notes) == 3 and all(n.startswith("joint_friction with its ") for n in notes), notes
    if not stribeck:
        assert out is None, notes
        return
    assert out is not None, notes
    e, name, model, pb, ci, fitted = out
    assert e == "joint_friction" and "Stribeck" in name and {"tau_s", "v_s"} <= set(fitted["joint_friction"])
    np.testing.assert_allclose(model.effects["joint_friction"]["tau_s"], FRICTION["tau_s"], rtol=0.15, atol=0.05)
    assert pb.error()[0] < 0.5 * cprob.error()[0]
    nom = fit_unseen_motion(ReplayProblem(nominal, run))
    steps = [dgl._step(nom, [], {}, 0), dgl._step(cprob, ["joint_friction"], {}, 1), dgl._step(pb, ["joint_friction"], ci, 1, law_refined=f"{e}: {name}")]
    h = dg.History(steps, [], "", run="x", seconds=0.0, error="", noise=nom.noise, notes=notes, noise_initial=nom.noise, problem=nom)
    text = dgl.conclude(h, 6, nom)
    assert f"gave joint_friction its {name} law (" in text and "tau_s=" in text and f"to {steps[2].error:.3g} noise units" in text, text
    assert h.to_dict()["history"][2]["law_refined"] == f"joint_friction: {name}" and "law" in str(h.to_pandas()["change"].iloc[2])
