"""Issue 19: regression tests for what the API fuzzing (tests/test_fuzz_api.py) found:
arguments of the wrong kind gave TypeError, OverflowError, IndexError, a ComplexWarning
(the imaginary part silently dropped) or an error naming an internal name. Each now
raises a PopupError (and the matching built-in) naming the argument."""

import numpy as np
import pytest

import popup
from popup import io as pio


@pytest.mark.parametrize(
    "kw, needle",
    [
        ({"disable": 0.0}, "input disable"),
        ({"disable": [1]}, "input disable"),
        ({"integrator": 0.0}, "input integrator"),
        ({"dt": "x"}, "input dt"),
        ({"dt": [1e-3, 1e-3]}, "input dt"),
        ({"dt": 1j}, "input dt"),
        ({"gravity": np.array([1.0, 2.0])}, "input gravity"),
        ({"gravity": "yes"}, "input gravity"),
        ({"payload_kg": np.complex128(1j)}, "input payload_kg"),
        ({"pressure_pa": [3e4 + 1j, 3e4]}, "input pressure_pa"),
    ],
)
def test_model_arguments_of_the_wrong_kind_are_named(kw, needle):
    with pytest.raises(popup.InputError, match=needle) as e:
        popup.Model(**kw)
    assert isinstance(e.value, ValueError)


@pytest.mark.parametrize("arm", [3, None, 1.5, b"popup-lab", "a\x00b", ["popup-lab"]])
def test_an_arm_that_is_no_name_or_path_is_named(arm):
    with pytest.raises(popup.InputError, match="input arm") as e:
        popup.Model(arm)
    assert isinstance(e.value, ValueError)


def test_disable_may_be_one_name():
    assert popup.Model(disable="damper").core.disabled == ["damper"]


def test_complex_torque_is_refused_not_silently_made_real():
    m = popup.Model()
    with pytest.raises(popup.InputError, match="input torque: complex values"):
        m.simulate(np.array([0.0, 1j, 0.0]), duration=0.01)


@pytest.mark.parametrize("kw", [{"check_step": np.zeros(0)}, {"check_step": "no"}, {"raise_on_error": [True, False]}])
def test_flags_of_the_wrong_kind_are_named(kw):
    with pytest.raises(popup.InputError, match="input " + next(iter(kw))):
        popup.Model().rollout(duration=0.01, **kw)


def test_an_absurd_encoder_angle_is_named_not_blamed_on_the_statics():
    # found by tests/test_fuzz_runs.py: 1e300 rad in one encoder cell ended as "static
    # equilibrium did not converge ... the springs may be too weak for the load"
    t = [0.0, 2.246687641658144e-211, 1.0]
    q = [[0.0, 0.0, 0.0], [0.0, 0.0, 1e300], [0.0, 0.0, 0.0]]
    with pytest.raises(popup.InputError, match=r"encoder replay angles: value at row 1, column 2 \(q3\) is 1e300 rad, beyond 25\.13"):
        popup.Model().replay(t, q, sample_rate=100)


def test_a_sample_rate_that_does_not_divide_the_physics_rate_is_named():
    with pytest.raises(popup.InputError, match=r"sample_rate.*1\.5 Hz must divide the physics rate 1000\.0 Hz"):
        popup.Model().simulate(duration=0.01, sample_rate=1.5)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    t = np.arange(26) * 0.002
    data = {"t": t, "q1": 0.1 * t, "q2": 0.2 * t, "q3": -0.1 * t, "tau2": np.full(len(t), 37.6)}
    exp = {"format": "popup-run/1", "arm": "popup-lab", "payload_kg": 2.0, "pressure_pa": [30000.0, 30000.0], "replay": "encoder"}
    return pio.read_run(pio.write_run(tmp_path_factory.mktemp("api") / "run", exp, data))


@pytest.mark.parametrize(
    "kw, needle",
    [
        ({"lags": None}, "input lags"),
        ({"lags": float("nan")}, "input lags"),
        ({"n_windows": float("inf")}, "input n_windows"),
        ({"channels": 0.0}, "input channels"),
        ({"sample_rate": [500.0]}, "input sample_rate"),
        ({"sample_rate": "x"}, "input sample_rate"),
        ({"sample_rate": 1.5}, "sample_rate"),
        ({"n_windows": 4_267_948_480_560_694}, "input n_windows: 4267948480560694 windows for a run of 26 samples; at most 26 "),
    ],
)
def test_compare_arguments_are_named(run, kw, needle):
    with pytest.raises(popup.InputError, match=needle):
        popup.compare.compare(popup.Model(), run, **kw)


P = "payload_mass.delta_kg"


@pytest.mark.parametrize(
    "kw, needle",
    [
        ({"params": None}, "input params"),
        ({"params": 3}, "input params"),
        ({"params": [P], "bounds": 0.0}, "input bounds"),
        ({"params": [P], "bounds": {P: 1.0}}, "input bounds"),
        ({"params": [P], "bounds": {P: ("a", "b")}}, "input bounds"),
        ({"params": [P], "x0": {P: "x"}}, "input x0"),
        ({"params": [P], "scale": {P: [[1.0, 2.0]]}}, "input scale"),
        ({"params": [P], "x0": {3: 1.0}}, "input x0"),
        ({"params": [P], "max_iter": 2**70}, "input max_iter"),
        ({"params": [P], "max_iter": -1}, "input max_iter"),
        ({"params": [P], "starts": 0}, "input starts"),
        ({"params": [P], "threads": 1.5}, "input threads"),
        ({"params": ["joint_friction.coulomb"], "x0": {"joint_friction.coulomb": [0.1]}}, "joint_friction.coulomb"),
    ],
)
def test_fit_params_arguments_are_named(run, kw, needle):
    with pytest.raises(popup.InputError, match=needle) as e:
        popup.fit_params(popup.Model(), run, **kw)
    assert isinstance(e.value, ValueError)


def test_a_thread_count_beyond_64_bits_is_named():
    # found by tests/test_fuzz_api.py: 2**64 threads ended as OverflowError inside the binding
    with pytest.raises(popup.InputError, match="input threads: 18446744073709551616"):
        popup.Model().rollout(duration=0.01, threads=2**64)


def test_a_payload_the_springs_cannot_hold_names_the_payload():
    # found by tests/test_fuzz_api.py: the statics' message said "payload 138 kg", not the
    # argument's name
    with pytest.raises(popup.PopupError, match=r"payload_kg = 138 kg"):
        popup.Model().rollout(duration=0.0, payload_kg=138)


@pytest.mark.parametrize("call", ["diagnose", "improve"])
@pytest.mark.parametrize("max_iter", [-1, 2.5, True, 10**7])
def test_a_bad_max_iter_is_refused_before_any_work(run, call, max_iter):
    # a negative count reached scipy's least_squares inside every candidate's guarded fit,
    # so each effect was listed "not tested" instead of the argument being named
    with pytest.raises(popup.InputError, match="input max_iter"):
        getattr(popup, call)(popup.Model(), run, max_iter=max_iter)
