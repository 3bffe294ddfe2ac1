"""Bad input gets a clear error and loses nothing."""

import numpy as np
import pytest

import popup


def test_hierarchy():
    for cls in (popup.ParameterError, popup.InputError, popup.StepTooLargeError, popup.UnreachableError, popup.ArmFileError):
        assert issubclass(cls, popup.PopupError) and issubclass(cls, ValueError)
    assert issubclass(popup.DivergenceError, RuntimeError)
    assert issubclass(popup.UnknownArmError, LookupError)


@pytest.mark.parametrize("payload", [float("nan"), -1.0])
def test_bad_payload(payload):
    with pytest.raises(popup.ParameterError, match="payload_kg"):
        popup.Model(payload_kg=payload)


@pytest.mark.parametrize("p", [float("nan"), -5.0])
def test_bad_pressure(p):
    with pytest.raises(popup.ParameterError, match=r"pressure_pa\[1\] \(link 2\)"):
        popup.Model(pressure_pa=(30e3, p))


def test_negative_mass_in_arm():
    arm = popup.Arm.builtin("popup-lab").with_overrides({"bodies": [{}, {}, {}, {"parts": [{"mass_kg": -0.5}]}]})
    with pytest.raises(popup.ParameterError, match=r"bodies\[3\]\.parts\[0\]\.mass_kg"):
        popup.Model(arm)


def test_unknown_arm():
    with pytest.raises(popup.UnknownArmError, match="popup-lab"):
        popup.Model("no-such-arm")


def test_malformed_arm_file(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text('base = "popup-lab"\n[links\n')
    with pytest.raises(popup.ArmFileError, match="line 2"):
        popup.Arm.load(p)
    p.write_text('base = "popup-lab"\nnot_a_key = 1\n')
    with pytest.raises(popup.ArmFileError, match="not_a_key"):
        popup.Arm.load(p)


def test_step_too_large_names_joint_and_limit():
    m = popup.Model(dt=0.05)
    with pytest.raises(popup.StepTooLargeError) as e:
        m.simulate(m.holding_torque(), duration=1.0, sample_rate=20)
    msg = str(e.value)
    assert "dt = 5e-2 s" in msg and "joint d" in msg and "use dt <=" in msg
    dt_max = float(msg.rsplit("use dt <=", 1)[1].split()[0])
    ok = popup.Model(dt=dt_max)
    ok.core.check_step(ok.payload_kg, ok.pressure_pa, ok.rest_state().tolist(), False)


def test_divergence_names_step_and_joint():
    m = popup.Model(dt=5e-3)
    with pytest.raises(popup.DivergenceError, match=r"diverged at step \d+ .* joint \w+"):
        m.simulate([0.0, 1e9, 0.0], duration=1.0, sample_rate=200, check_step=False)


def test_bad_replay_inputs(model):
    t = np.array([0.0, 0.1, 0.1, 0.3])
    q = np.zeros((4, 3))
    with pytest.raises(popup.InputError, match="strictly increasing"):
        model.replay(t, q)
    t = np.array([0.0, 0.1, 0.2, 0.3])
    q[2, 1] = np.nan
    with pytest.raises(popup.InputError, match="row 2, column 1"):
        model.replay(t, q)
    with pytest.raises(popup.InputError, match="shape"):
        model.replay(t, np.zeros((5, 3)))


def test_sample_rate_must_divide_physics_rate(model):
    with pytest.raises(popup.InputError, match="whole multiple of dt"):
        model.simulate(duration=0.1, sample_rate=300.0)


def test_torque_run_needs_duration(model):
    with pytest.raises(popup.InputError, match="duration"):
        model.rollout(torque=[0.0, 0.0, 0.0])


def test_failed_run_in_batch_does_not_lose_others(model):
    b = model.rollout(payload_kg=[1.0, -1.0, 2.0], torque=model.holding_torque(), duration=0.1, raise_on_error=False)
    assert b.errors[0] is None and b.errors[2] is None
    assert "payload_kg" in b.errors[1]
    assert np.all(np.isnan(b.data[1])) and np.all(np.isfinite(b.data[0]))


def test_unknown_disable_flag():
    with pytest.raises(popup.ParameterError, match="disable"):
        popup.Model(disable=["friction"])


# issue 19: every error a PopupError with the matching built-in, naming the argument
@pytest.mark.parametrize(
    "call, needle",
    [
        (lambda m: popup.Model(pressure_pa=(30e3,)), "input pressure_pa"),
        (lambda m: popup.Model(pressure_pa=[[1.0, 2.0]]), "input pressure_pa"),
        (lambda m: popup.Model(payload_kg="x"), "input payload_kg"),
        (lambda m: m.rollout(payload_kg=np.zeros(0), torque=[0.0, 0.0, 0.0], duration=0.01), "input payload_kg"),
        (lambda m: m.rollout(torque=[0.0, 0.0, 0.0], duration=0.01, threads=-1), "input threads"),
        (lambda m: m.rollout(torque=[0.0, 0.0, 0.0], duration=0.01, threads="2"), "input threads"),
        (lambda m: m.rigid().ik([1, 2]), "input p"),
        (lambda m: m.rigid().fk([1, 2]), "input q"),
        (lambda m: m.rest_state((0, 0.6)), "input q_motor"),
        (lambda m: m.holding_torque((0, 0.6)), "input q_motor"),
        (lambda m: m.simulate(duration=float("nan")), "input duration: nan s"),
        (lambda m: m.simulate(duration=0.1, sample_rate="fast"), "input sample_rate"),
        (lambda m: m.replay([0.0, 0.1], [["a", 0, 0], [0, 0, 0]]), "input encoder_q"),
    ],
)
def test_bad_arguments_are_popup_errors_naming_the_argument(model, call, needle):
    with pytest.raises(popup.PopupError) as e:
        call(model)
    assert isinstance(e.value, ValueError), type(e.value)
    assert needle in str(e.value), str(e.value)
