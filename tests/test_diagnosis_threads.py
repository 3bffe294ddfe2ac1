"""The diagnosis fits its candidates on several threads at once (``popup.diagnosis.rank``):
the same bits as one by one, whatever the thread count, and an interrupt still stops it."""

from __future__ import annotations

import math
import os
import signal
import threading

import numpy as np
import pytest

import popup
from popup.diagnosis import rank as dgrank
from popup.problem import ReplayProblem

FRICTION = {"tau_c": [1.2, 1.8, 0.6], "b": [0.2, 0.3, 0.1]}
CANDIDATES = ["joint_friction", "payload_mass", "sensor_delay", "air_drag"]


@pytest.fixture(scope="module")
def nominal():
    return popup.Model("popup-lab", payload_kg=1.0)


@pytest.fixture(scope="module")
def run(nominal, tmp_path_factory):
    t, q = popup.synth.lab_trajectory(5.0, seed=23)
    return popup.synth.measured_run(nominal.with_effect("joint_friction", **FRICTION), t, q, tmp_path_factory.mktemp("fr"), seed=23)


def _same(a: popup.Diagnosis, b: popup.Diagnosis) -> None:
    assert [s.effect for s in a.suspects] == [s.effect for s in b.suspects]
    for x, y in zip(a.suspects, b.suspects):
        for f in ("significant", "tested", "variant", "message", "n_rollouts", "fitted"):
            assert getattr(x, f) == getattr(y, f), (x.effect, f)
        for f in ("score", "error_after", "validation_after", "explained"):
            u, v = getattr(x, f), getattr(y, f)
            assert u == v or (math.isnan(u) and math.isnan(v)), (x.effect, f, u, v)
        for f in ("params", "ci95", "refitted"):
            assert set(getattr(x, f)) == set(getattr(y, f)), (x.effect, f)
            for k, u in getattr(x, f).items():
                np.testing.assert_array_equal(np.asarray(u, dtype=object), np.asarray(getattr(y, f)[k], dtype=object), err_msg=f"{x.effect} {f} {k}")
    assert a.n_rollouts == b.n_rollouts
    assert a.conclusion == b.conclusion


def test_candidates_on_threads_give_the_same_bits_as_one_by_one(nominal, run):
    """Round 1 (every candidate from its seeds), then a round with the found effect refitted
    jointly and the candidates screened from their starts: 1 thread and 3 threads give the
    same suspects, to the bit, with the same rollout counts."""
    one = popup.diagnose(nominal, run, effects=CANDIDATES, threads=1)
    many = popup.diagnose(nominal, run, effects=CANDIDATES, threads=3)
    _same(one, many)
    top = one.suspects[0]
    assert top.effect == "joint_friction" and top.significant
    # the next round: friction in the model, refitted with each candidate (joint-refit loop),
    # the candidates screened from their first-round fits (screen loop)
    m1 = top.apply(nominal)
    starts = {s.effect: s.params for s in one.suspects if s.tested and s.params and s.effect != "joint_friction"}
    kw = dict(effects=CANDIDATES[1:], refit={"joint_friction": []}, starts=starts, screen=1)
    p1 = ReplayProblem(m1, run, threads=1)
    p3 = ReplayProblem(m1, run, threads=3)
    a = popup.diagnose(m1, run, problem=p1, rank_at_floor=True, **kw)
    b = popup.diagnose(m1, run, problem=p3, rank_at_floor=True, **kw)
    _same(a, b)
    assert any("screened" in s.message for s in a.suspects) and any(s.refitted for s in a.suspects)
    # a rollout count is the candidate's own: the problem's count is the sum over them all
    assert p1.nfev == p3.nfev


def test_an_interrupt_while_candidates_run_on_threads_stops_them_all(nominal, run, monkeypatch):
    """SIGTERM sent from a candidate's thread (the kernel may hand a signal to any thread):
    the main thread's handler raises, the other candidates stop at their next simulation,
    every thread ends and the interrupt reaches the caller."""
    orig = dgrank.try_effect
    ran = []

    def first_signals(prob, name, *a, **kw):
        ran.append(name)
        if name == CANDIDATES[0]:
            os.kill(os.getpid(), signal.SIGTERM)
        return orig(prob, name, *a, **kw)

    def handler(signum, frame):
        raise KeyboardInterrupt("SIGTERM received")

    monkeypatch.setattr(dgrank, "try_effect", first_signals)
    old = signal.signal(signal.SIGTERM, handler)
    prob = ReplayProblem(nominal, run, threads=2)
    n0 = prob.nfev
    try:
        with pytest.raises(KeyboardInterrupt, match="SIGTERM"):
            popup.diagnose(nominal, run, effects=CANDIDATES, problem=prob)
    finally:
        signal.signal(signal.SIGTERM, old)
    assert not [t for t in threading.enumerate() if t.name.startswith("popup-candidate")]
    # only the candidates already started ran, and they stopped early: fewer rollouts than
    # the first candidate alone needs (the stopped ones' rollouts are counted too)
    assert 1 <= len(ran) <= 2
    monkeypatch.undo()
    alone = popup.diagnose(nominal, run, effects=CANDIDATES[:1], threads=1).suspects[0]
    assert 0 < prob.nfev - n0 < alone.n_rollouts, (prob.nfev - n0, alone.n_rollouts)
