"""Issue 19: property tests (hypothesis) of the public Python API beyond ``replay``: Model
construction (arm names, payload, pressure, dt, integrator), simulate / rollout arguments
(durations, torques of any shape and dtype, payload batches, threads, initial states),
Scenario from TOML text, compare and fit_params arguments.

Property: every call returns, or raises a :class:`popup.PopupError` that also derives from
a built-in exception (ValueError, LookupError, RuntimeError, OSError) and whose message
names one of the arguments given; never another exception type, never a hang (each case
is time-bounded; sizes are small). A short run here (CI); ``-m slow`` (or
``scripts/fuzz.sh``) for a long one."""

import math
import os
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import popup
from popup import io as pio
from test_fuzz_runs import bounded

FAST = settings(max_examples=int(os.environ.get("POPUP_FUZZ_CI_EXAMPLES", "15")), deadline=None, suppress_health_check=list(HealthCheck))
LONG = settings(max_examples=int(os.environ.get("POPUP_FUZZ_EXAMPLES", "2000")), deadline=None, suppress_health_check=list(HealthCheck))

BUILTINS = (ValueError, LookupError, RuntimeError, OSError)


def outcome(call, names):
    """Run ``call`` bounded: it returns, or raises a PopupError (and a built-in) whose
    message names one of ``names``; anything else fails the case."""
    with bounded(), warnings.catch_warnings():
        warnings.simplefilter("ignore", popup.PopupWarning)
        try:
            return call()
        except popup.PopupError as e:
            msg = str(e)
            assert isinstance(e, BUILTINS), (type(e).__mro__, msg)
            assert any(n in msg for n in names), (names, msg)
            return e


# ----------------------------------------------------------------------- values
ODD_FLOATS = st.sampled_from([math.nan, math.inf, -math.inf, 1e300, -1e300, 0.0, -0.0, -1.0, 1e-300, 5e-324])
ODD_THINGS = st.sampled_from(["x", "", None, True, [], [1.0, 2.0, 3.0, 4.0], {"a": 1}, b"1", 1j, object(), np.array([[1.0]]), "1e-3"])
NUMBER = st.one_of(st.floats(-10.0, 10.0), ODD_FLOATS, st.integers(-5, 5), st.integers(-(2**70), 2**70))
ANY = st.one_of(NUMBER, ODD_THINGS)


def small_array(max_dims: int = 3):
    """Arrays of small random shape and dtype (float, int, bool, complex, object, str)."""
    shapes = st.lists(st.integers(0, 4), min_size=0, max_size=max_dims).map(tuple)
    dtypes = st.sampled_from([np.float64, np.float32, np.int64, np.bool_, np.complex128, object, "U3"])

    @st.composite
    def build(draw):
        shape = draw(shapes)
        dt = draw(dtypes)
        n = int(np.prod(shape)) if shape else 1
        vals = draw(st.lists(st.one_of(st.floats(-3, 3), ODD_FLOATS), min_size=n, max_size=n))
        a = np.array(vals, dtype=np.float64).reshape(shape)
        if dt == "U3":
            return a.astype(str).astype("U3")
        with np.errstate(invalid="ignore", over="ignore"):
            return a.astype(dt) if dt is not object else a.astype(object)

    return build()


def arg(values):
    """An argument: a good value most of the time, else anything."""
    return st.one_of(values, ANY, small_array())


# ----------------------------------------------------------------------- Model(...)
ARM = st.one_of(
    st.sampled_from(["popup-lab", "popup-lab-thesis", "nope", "", "popup-lab ", "no/such/arm.toml", ".", "/", "arms"]),
    st.text(max_size=12),
    ODD_THINGS,
)


@st.composite
def model_args(draw):
    kw = {}
    for name, good in (
        ("payload_kg", st.floats(0.0, 5.0)),
        ("pressure_pa", st.tuples(st.floats(1e4, 5e4), st.floats(1e4, 5e4))),
        ("dt", st.sampled_from([1e-3, 5e-4, 2e-3])),
        ("integrator", st.sampled_from(["rk4", "semi_implicit", "euler", ""])),
        ("disable", st.lists(st.sampled_from(["gravity", "spring", "damper", "bogus"]), max_size=3)),
        ("gravity", st.booleans()),
    ):
        if draw(st.booleans()):
            kw[name] = draw(arg(good))
    return draw(ARM) if draw(st.integers(0, 3)) == 0 else "popup-lab", kw


def check_model(args):
    arm, kw = args
    names = list(kw) + ["arm", str(arm)]
    return outcome(lambda: popup.Model(arm, **kw), names)


@FAST
@given(args=model_args())
def test_model_construction_is_a_model_or_a_named_error(args):
    check_model(args)


@pytest.mark.slow
@LONG
@given(args=model_args())
def test_model_construction_long(args):
    check_model(args)


# ----------------------------------------------------------------------- simulate / rollout
@pytest.fixture(scope="module")
def model():
    return popup.Model()


@st.composite
def rollout_args(draw):
    kw = {"duration": draw(st.one_of(st.floats(0.0, 0.05), ODD_FLOATS, ODD_THINGS))}
    for name, good in (
        ("torque", st.lists(st.floats(-5.0, 5.0), min_size=3, max_size=3)),
        ("payload_kg", st.one_of(st.floats(0.0, 3.0), st.lists(st.floats(0.0, 3.0), min_size=1, max_size=3))),
        ("pressure_pa", st.tuples(st.floats(1e4, 5e4), st.floats(1e4, 5e4))),
        ("sample_rate", st.sampled_from([100.0, 500.0, 1000.0, 333.0])),
        ("threads", st.one_of(st.integers(-3, 8), st.sampled_from([10**6, 2**64]))),
        ("initial_q", st.lists(st.floats(-0.5, 0.5), min_size=7, max_size=7)),
        ("initial_v", st.lists(st.floats(-0.5, 0.5), min_size=7, max_size=7)),
        ("torque_times", st.lists(st.floats(0.0, 0.05), min_size=0, max_size=4)),
        ("check_step", st.booleans()),
    ):
        if draw(st.booleans()):
            kw[name] = draw(arg(good))
    return kw


def check_rollout(model, kw):
    r = outcome(lambda: model.rollout(**kw), list(kw) + ["input", "values"])
    if not isinstance(r, popup.PopupError):
        assert np.asarray(r.data).ndim == 3


@FAST
@given(kw=rollout_args())
def test_rollout_on_generated_arguments_is_a_result_or_a_named_error(model, kw):
    check_rollout(model, kw)


@pytest.mark.slow
@LONG
@given(kw=rollout_args())
def test_rollout_long(model, kw):
    check_rollout(model, kw)


@FAST
@given(kw=rollout_args())
def test_simulate_on_generated_arguments_is_a_result_or_a_named_error(model, kw):
    kw = {k: v for k, v in kw.items() if k not in ("payload_kg", "pressure_pa", "threads")}
    outcome(lambda: model.simulate(**kw), list(kw) + ["input", "values"])


# ----------------------------------------------------------------------- Scenario
SCENARIO = """name = "fuzz"
arm = "popup-lab"
duration_s = {duration}
seed = {seed}

[controller]
rate_hz = {rate}

[[phase]]
name = "hold"
mode = "holding"
"""

TOML_VALUES = st.sampled_from(["0.02", "0", "-1", "nan", "inf", "1e300", '"x"', "[]", "true", "1e9", "0.01", "{a = 1}", ""])


@st.composite
def scenario_texts(draw):
    text = SCENARIO.format(
        duration=draw(st.one_of(st.sampled_from(["0.02", "0.01"]), TOML_VALUES)),
        seed=draw(st.one_of(st.sampled_from(["1", "0"]), TOML_VALUES, st.just("-1"), st.just("18446744073709551616"))),
        rate=draw(st.one_of(st.sampled_from(["1000.0", "10000"]), TOML_VALUES)),
    )
    lines = text.splitlines()
    for _ in range(draw(st.integers(0, 2))):  # random damage: drop, duplicate or mangle a line
        i = draw(st.integers(0, len(lines) - 1))
        how = draw(st.integers(0, 3))
        if how == 0:
            del lines[i]
        elif how == 1:
            lines.insert(i, lines[i])
        elif how == 2:
            lines[i] = lines[i][: draw(st.integers(0, len(lines[i])))]
        else:
            lines.insert(i, draw(st.sampled_from(["bogus = 1", "[unknown]", "[[phase]]", 'mode = "nope"', "arm = 3", "\x00"])))
        if not lines:
            break
    return "\n".join(lines) + "\n"


def check_scenario(text):
    def run():
        sc = popup.Scenario.from_toml(text, source="fuzz.toml")
        if sc.duration_s <= 0.05:
            return sc.run()
        return sc.run(duration=0.02)

    outcome(run, ["fuzz.toml", "duration"])


@FAST
@given(text=scenario_texts())
def test_scenario_text_is_a_run_or_a_named_error(text):
    check_scenario(text)


@pytest.mark.slow
@LONG
@given(text=scenario_texts())
def test_scenario_text_long(text):
    check_scenario(text)


# ----------------------------------------------------------------------- compare / fit_params
@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A short measured run (0.1 s at 500 Hz), written and read back."""
    m = popup.Model()
    t = np.arange(51) * 0.002
    q = np.column_stack([0.1 * t, 0.2 * t, -0.1 * t])
    sim = m.replay(t, q, sample_rate=500)
    data = {"t": t, "q1": q[:, 0], "q2": q[:, 1], "q3": q[:, 2], "tau2": sim.channel("tau2")[: len(t)], "imu2_az": sim.channel("imu2_az")[: len(t)]}
    exp = {"format": "popup-run/1", "arm": "popup-lab", "payload_kg": 2.0, "pressure_pa": [30000.0, 30000.0], "replay": "encoder"}
    folder = pio.write_run(tmp_path_factory.mktemp("fuzz") / "run", exp, data)
    return pio.read_run(folder)


CHANNELS = st.lists(st.sampled_from(["tau2", "imu2_az", "ee_z", "q1", "bogus", "", "t"]), max_size=3)


@st.composite
def compare_args(draw):
    kw = {}
    for name, good in (
        ("channels", CHANNELS),
        ("sample_rate", st.sampled_from([500.0, 250.0, 100.0, 333.0])),
        ("lags", st.integers(0, 30)),
        ("n_windows", st.integers(1, 5)),
    ):
        if draw(st.booleans()):
            kw[name] = draw(arg(good))
    return kw


@FAST
@given(kw=compare_args())
def test_compare_on_generated_arguments_is_a_result_or_a_named_error(run, kw):
    m = popup.Model()
    outcome(lambda: popup.compare.compare(m, run, **kw), list(kw))


PARAM_NAMES = st.sampled_from(
    ["joint_friction.coulomb[1]", "payload_mass.delta_kg", "joint_friction.coulomb", "nope.x", "payload_mass", "", "payload_mass.delta_kg[7]"]
)


@st.composite
def fit_args(draw):
    kw = {"params": draw(st.one_of(st.lists(PARAM_NAMES, min_size=0, max_size=2), ODD_THINGS))}
    name = kw["params"][0] if isinstance(kw["params"], list) and kw["params"] else "payload_mass.delta_kg"
    for key, good in (
        ("bounds", st.fixed_dictionaries({name: st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0))})),
        ("x0", st.fixed_dictionaries({name: st.floats(-1.0, 1.0)})),
        ("scale", st.fixed_dictionaries({name: st.floats(-1.0, 1.0)})),
        ("channels", CHANNELS),
        ("threads", st.integers(-2, 4)),
        ("starts", st.integers(-1, 2)),
    ):
        if draw(st.booleans()):
            kw[key] = draw(arg(good))
    kw["max_iter"] = draw(st.one_of(st.integers(0, 2), st.sampled_from([-1, 2**70])))
    kw["seeds"] = False
    return kw


@FAST
@given(kw=fit_args())
def test_fit_params_on_generated_arguments_is_a_result_or_a_named_error(run, kw):
    m = popup.Model()
    names = [k for k in kw if k not in ("seeds",)] + [str(p) for p in (kw["params"] if isinstance(kw["params"], list) else [])]
    outcome(lambda: popup.fit_params(m, run, **kw), names + ["params", "param"])


# ----------------------------------------------------------------------- long runs (-m slow)
@pytest.mark.slow
@LONG
@given(kw=rollout_args())
def test_simulate_long(model, kw):
    kw = {k: v for k, v in kw.items() if k not in ("payload_kg", "pressure_pa", "threads")}
    outcome(lambda: model.simulate(**kw), list(kw) + ["input", "values"])


@pytest.mark.slow
@LONG
@given(kw=compare_args())
def test_compare_long(run, kw):
    outcome(lambda: popup.compare.compare(popup.Model(), run, **kw), list(kw))


@pytest.mark.slow
@settings(LONG, max_examples=max(LONG.max_examples // 10, 1))  # each case fits: slower
@given(kw=fit_args())
def test_fit_params_long(run, kw):
    names = [k for k in kw if k not in ("seeds",)] + [str(p) for p in (kw["params"] if isinstance(kw["params"], list) else [])]
    outcome(lambda: popup.fit_params(popup.Model(), run, **kw), names + ["params", "param"])
