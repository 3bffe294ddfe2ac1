"""Issue 19: bounded work and interrupts. Every run's step count is derived from its inputs
and checked before it starts; Ctrl-C stops a long run from Python; ``threads`` is
validated against the machine's cores."""

import os
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import popup

CORES = os.cpu_count() or 1


@pytest.mark.parametrize("last_t, steps", [(1e300, "1e303 steps"), (1e9, "1e12 steps")])
def test_absurd_replay_span_is_refused_with_the_reason(model, last_t, steps):
    t = np.array([0.0, 0.5, last_t])
    with pytest.raises(popup.InputError) as e:
        model.replay(t, np.zeros((3, 3)))
    msg = str(e.value)
    assert "replay span" in msg and steps in msg and "the limit is 1e9 steps" in msg, msg
    assert len(msg) < 400, msg  # no 300-digit numbers


def test_absurd_duration_and_batch_are_refused(model):
    with pytest.raises(popup.InputError, match=r"duration 1e\+?300 s|duration 1e300 s"):
        model.simulate(duration=1e300)
    with pytest.raises(popup.InputError, match=r"values .*the limit is"):
        # 1000 runs of 1e5 s at 1 kHz: far beyond what a batch may hold in memory
        model.rollout(payload_kg=np.full(1000, 2.0), torque=[0.0, 0.0, 0.0], duration=1e5, sample_rate=1000)
    with pytest.raises(popup.InputError, match="sample_period"):
        model.simulate(duration=0.1, sample_rate=1e-300)


@pytest.mark.parametrize("threads", [-1, 10**6])
def test_bad_threads_are_refused_naming_the_cores(model, threads):
    with pytest.raises(popup.InputError) as e:
        model.rollout(torque=[0.0, 0.0, 0.0], duration=0.01, threads=threads)
    msg = str(e.value)
    assert f"threads: {threads} is out of range" in msg and f"has {CORES} core" in msg, msg
    task = popup.control.Task([popup.control.Phase("holding")])
    with pytest.raises(popup.InputError, match="threads"):
        popup.Model(dt=1e-4).rollout_task(task, duration=0.01, threads=threads)


def test_threads_above_the_cores_are_capped_not_refused(model):
    a = model.rollout(payload_kg=[1.0, 2.0], torque=[0.0, 0.0, 0.0], duration=0.05, threads=1)
    b = model.rollout(payload_kg=[1.0, 2.0], torque=[0.0, 0.0, 0.0], duration=0.05, threads=2 * CORES)
    assert np.array_equal(a.data, b.data)


def test_sweep_threads_are_refused(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "popup", "sweep", "nope.toml", "--param", "payload_kg=1", "--out", str(tmp_path), "--threads", "1000000"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2, r.stderr
    assert "--threads: 1000000 is out of range" in r.stderr and "core" in r.stderr, r.stderr


_LONG_RUN = textwrap.dedent(
    """
    import sys, numpy as np, popup
    m = popup.Model()
    kind = sys.argv[1]
    print("start", flush=True)
    try:
        if kind == "replay":
            m.replay(np.linspace(0.0, 5000.0, 5), np.zeros((5, 3)), sample_rate=10)
        elif kind == "batch":
            m.rollout(payload_kg=[1.0, 2.0, 1.5], torque=[0.0, 0.0, 0.0], duration=5000.0, sample_rate=10, threads=2)
        elif kind == "linearize":  # a sweep of 200000 operating points (minutes)
            popup.frequency.linearize(m, q_motor=np.zeros((200_000, 3)))
        elif kind == "frf":  # a stepped sine at a very low frequency (minutes)
            popup.frequency.simulate(m, [0.02], input="torque", settle_s=0.0, max_settle_s=1e4)
        else:
            t = popup.control.Task([popup.control.Phase("holding")])
            popup.Model(dt=1e-4).rollout_task(t, duration=500.0, sample_rate=10)
    except KeyboardInterrupt:
        print("KeyboardInterrupt", flush=True)
        sys.exit(3)
    print("finished", flush=True)
    """
)


def _default_sigint() -> None:
    """In the child: SIGINT back to its default (a shell's background job starts with it
    ignored, and Python then installs no KeyboardInterrupt handler)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.skipif(os.name != "posix", reason="POSIX signals")
@pytest.mark.parametrize("kind", ["replay", "batch", "closed_loop", "linearize", "frf"])
def test_ctrl_c_stops_a_long_run_from_python(kind):
    p = subprocess.Popen([sys.executable, "-c", _LONG_RUN, kind], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_default_sigint)
    try:
        assert p.stdout is not None
        assert p.stdout.readline().strip() == "start"
        import time

        time.sleep(1.0)  # inside the Rust loop (the runs take minutes)
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=60)  # generous: the run itself would take minutes
    finally:
        if p.poll() is None:
            p.kill()
            p.communicate()
    assert p.returncode == 3 and "KeyboardInterrupt" in out, (p.returncode, out, err)
