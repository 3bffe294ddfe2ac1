"""popup.setmembership: parameter uncertainty intervals under bounded noise (issue 9).

Simulated data from known linear systems (FIR, ARX, OE; MISO) with bounded uniform noise:
the truth lies in every interval, intervals shrink with N, a bound below the noise is
infeasible (and the minimal bound reported lies between the two); the output-error scheme
on data with a known truth, with a Monte Carlo check of coverage; and data from a popup
simulation and from the bundled measured run.
"""

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import lfilter

import popup
from popup import setmembership as sm
from popup.exceptions import InputError, ParameterError, PopupError


# ---------------------------------------------------------------- helpers
def _inputs(n, m, seed, pole=0.7):
    """Coloured random inputs starting at rest (u(0) = 0)."""
    rng = np.random.default_rng(seed)
    u = lfilter([1.0 - pole], [1.0, -pole], rng.standard_normal((n, m)), axis=0)
    u[0] = 0.0
    return u


def _den(r, w):
    """[f1, f2] of a pole pair r·e^{±iw}."""
    return [-2.0 * r * math.cos(w), r * r]


ARX = sm.arx(2, [2, 1], [1, 2], inputs=["u1", "u2"], output="y", offset=True)
ARX_TRUE = np.array([-1.2, 0.5, 1.0, 0.4, -0.7, 0.3])
FIR = sm.fir([3, 2], [0, 1], inputs=["u1", "u2"], output="y")
FIR_TRUE = np.array([1.0, 0.5, 0.2, -0.3, 0.1])
OE = sm.oe(nb=2, nf=2, nk=0, inputs=["u1", "u2"], output="y")
OE_TRUE = np.array([*_den(0.9, 0.3), *_den(0.8, 0.6), 0.5, 0.3, -0.4, 0.2, 0.1])
DELTA = 0.1  # noise amplitude: e ~ U(-DELTA, DELTA)


@pytest.fixture(scope="module")
def arx_data():
    rng = np.random.default_rng(0)
    u = _inputs(1000, 2, 1, pole=0.0)
    e = rng.uniform(-DELTA, DELTA, 1000)
    return sm.simulate(ARX, ARX_TRUE, u, e), u, e


@pytest.fixture(scope="module")
def fir_data():
    rng = np.random.default_rng(2)
    u = _inputs(1000, 2, 3, pole=0.5)
    e = rng.uniform(-DELTA, DELTA, 1000)
    return sm.simulate(FIR, FIR_TRUE, u, e), u, e


# ---------------------------------------------------------------- structures and regressors
def test_structure_names_and_orders():
    assert ARX.names == ["a1", "a2", "b_u1_1", "b_u1_2", "b_u2_2", "c"]
    assert ARX.max_lag == 2 and ARX.n_params == 6
    assert FIR.names == ["b_u1_0", "b_u1_1", "b_u1_2", "b_u2_1", "b_u2_2"]
    assert OE.names == ["f_u1_1", "f_u1_2", "f_u2_1", "f_u2_2", "b_u1_0", "b_u1_1", "b_u2_0", "b_u2_1", "c"]
    assert "OE(nb=[2, 2], nf=[2, 2], nk=[0, 0]) u1,u2 -> y, offset" == OE.describe()
    parts = OE.split(OE_TRUE)
    assert parts["f"]["u2"].tolist() == OE_TRUE[2:4].tolist() and parts["c"] == 0.1
    s = sm.oe(nb=2, nf=2, nk=0, inputs=sm.THESIS_INPUTS, output="ee_x")
    assert s.n_params == 17  # the thesis's G1..G4 (2 + 2 each) and the offset


@pytest.mark.parametrize(
    "make",
    [
        lambda: sm.arx(-1, 2),
        lambda: sm.arx(2, 1.5),
        lambda: sm.arx(2, [2, 2], inputs=["a"]),
        lambda: sm.fir(2, -1),
        lambda: sm.fir(0),
        lambda: sm.oe(nb=0, nf=2),
        lambda: sm.oe(nb=2, nf=True),
        lambda: sm.arx(1, 1, inputs=["u", "u"]),
    ],
)
def test_bad_orders_refused(make):
    with pytest.raises(ParameterError):
        make()


def test_regressors_match_an_explicit_loop():
    rng = np.random.default_rng(5)
    y = rng.standard_normal(30)
    u = rng.standard_normal((30, 2))
    reg = sm.regressors(ARX, y, u)
    assert reg.phi.shape == (28, 6) and reg.rows[0] == 2
    for r, t in enumerate(reg.rows):
        expect = [-y[t - 1], -y[t - 2], u[t - 1, 0], u[t - 2, 0], u[t - 2, 1], 1.0]
        np.testing.assert_array_equal(reg.phi[r], expect)
    np.testing.assert_array_equal(reg.y, y[2:])
    # noise-free ARX data: the regression is exact
    y0 = sm.simulate(ARX, ARX_TRUE, u)
    reg0 = sm.regressors(ARX, y0, u)
    np.testing.assert_allclose(reg0.phi @ ARX_TRUE, reg0.y, atol=1e-12)
    # skip drops rows after the lags
    assert sm.regressors(ARX, y, u, skip=5).rows[0] == 7


def test_regressor_errors():
    y = np.zeros(50)
    u = np.zeros((50, 2))
    bad = u.copy()
    bad[17, 1] = np.nan
    with pytest.raises(InputError, match=r"'u2'.*sample 17"):
        sm.regressors(ARX, y, bad)
    with pytest.raises(InputError, match="mismatched lengths"):
        sm.regressors(ARX, y[:40], u)
    with pytest.raises(InputError, match="too few samples"):
        sm.regressors(ARX, y[:6], u[:6])
    with pytest.raises(InputError, match="2 input"):
        sm.regressors(ARX, y, u[:, :1])
    with pytest.raises(InputError, match="1-D"):
        sm.regressors(ARX, u, u)
    with pytest.raises(ParameterError, match="not linear"):
        sm.regressors(OE, y, u)
    with pytest.raises(ParameterError, match="skip"):
        sm.regressors(ARX, y, u, skip=-1)
    assert issubclass(InputError, ValueError)


# ---------------------------------------------------------------- exact PUI: FIR / ARX
def test_arx_truth_inside_and_intervals_shrink(arx_data):
    y, u, e = arx_data
    r100 = sm.pui((y[:100], u[:100]), ARX, DELTA)
    r1000 = sm.pui((y, u), ARX, DELTA)
    for r in (r100, r1000):
        assert r.exact and r.names == ARX.names
        assert r.contains(ARX_TRUE).all(), r.to_pandas(ARX_TRUE)
        # the Chebyshev centre and the minimax estimate are feasible points: inside
        assert r.contains(r.center).all() and r.contains(r.minimax).all()
        assert r.radius > 0 and r.center_metric == "regressors"
        # the minimal bound is attained by a parameter vector: at most the true noise
        assert r.eps_min <= np.max(np.abs(e)) + 1e-9
        assert r.n_lp == 2 * 6 + 2
    # the 1000-sample set is a subset of the 100-sample one: nested, and much smaller
    assert np.all(r1000.width <= r100.width * (1 + 1e-6))
    assert np.all(r1000.width < 0.5 * r100.width)
    assert np.max(np.abs(r1000.center - ARX_TRUE)) < np.max(np.abs(r100.center - ARX_TRUE))


def test_fir_truth_inside_shrinks_and_matches_pui_linear(fir_data):
    y, u, e = fir_data
    r100 = sm.pui((y[:100], u[:100]), FIR, DELTA)
    r1000 = sm.pui((y, u), FIR, DELTA, threads=1)
    assert r100.contains(FIR_TRUE).all() and r1000.contains(FIR_TRUE).all()
    assert np.all(r1000.width < 0.5 * r100.width)
    reg = sm.regressors(FIR, y, u)
    lin = sm.pui_linear(reg.phi, reg.y, DELTA, names=reg.names, threads=2)
    np.testing.assert_allclose(lin.lower, r1000.lower, rtol=0, atol=1e-9)
    np.testing.assert_allclose(lin.upper, r1000.upper, rtol=0, atol=1e-9)
    eps_min, theta = sm.min_bound(reg.phi, reg.y)
    assert eps_min == pytest.approx(r1000.eps_min, rel=1e-6)
    assert np.max(np.abs(reg.y - reg.phi @ theta)) == pytest.approx(eps_min, rel=1e-6)


def test_every_bound_is_attained_by_a_feasible_point(fir_data):
    y, u, _ = fir_data
    reg = sm.regressors(FIR, y, u)
    r = sm.pui_linear(reg.phi, reg.y, DELTA)
    assert r.witnesses is not None and r.witnesses.shape == (10, 5)
    for k, w in enumerate(r.witnesses):
        assert np.max(np.abs(reg.y - reg.phi @ w)) <= DELTA * (1 + 1e-6)
        i, side = divmod(k, 2)
        assert w[i] == pytest.approx(r.lower[i] if side == 0 else r.upper[i], abs=1e-9)


def test_chebyshev_ball_is_inside_and_maximal(arx_data):
    """Every θ with ‖Φ(θ − centre)‖₂ <= radius·ε is feasible, and the ball touches the
    boundary (a slightly larger one is not inside)."""
    y, u, _ = arx_data
    r = sm.pui((y[:300], u[:300]), ARX, DELTA)
    reg = sm.regressors(ARX, y[:300], u[:300])
    rng = np.random.default_rng(9)
    for _ in range(200):
        d = rng.standard_normal(6)
        d *= 0.999 * r.radius * DELTA / np.linalg.norm(reg.phi @ d)
        assert np.max(np.abs(reg.y - reg.phi @ (r.center + d))) <= DELTA * (1 + 1e-9)
    # the binding row: the distance from the centre to its face, in the same metric
    slack = DELTA - np.abs(reg.y - reg.phi @ r.center)
    _, Rm = np.linalg.qr(reg.phi / DELTA)
    qn = np.linalg.norm(np.linalg.solve(Rm.T, (reg.phi / DELTA).T), axis=0)  # row norms of Φ R⁻¹
    assert np.min(slack / DELTA / qn) == pytest.approx(r.radius, rel=1e-5)


def test_infeasible_below_the_true_noise(arx_data):
    y, u, e = arx_data
    amp = np.max(np.abs(e))
    with pytest.raises(sm.InfeasibleError) as ei:
        sm.pui((y, u), ARX, 0.5 * DELTA)
    err = ei.value
    assert isinstance(err, PopupError) and isinstance(err, ValueError)
    assert 0.5 * DELTA < err.eps_min <= amp + 1e-9
    msg = str(err)
    assert "noise bound is too small" in msg and "model class is wrong" in msg and f"{err.eps_min:.6g}" in msg
    # at the reported minimal bound (plus a hair) the set is no longer empty, and tiny
    r = sm.pui((y, u), ARX, err.eps_min * (1 + 1e-6))
    assert r.contains(err.minimax, tol=1e-6).all()
    assert np.all(r.width < 1e-3)


def test_wrong_model_class_is_infeasible(fir_data):
    y, u, _ = fir_data
    short = sm.fir([1, 1], [0, 1], inputs=["u1", "u2"], output="y")  # the true FIR has 3 + 2 taps
    with pytest.raises(sm.InfeasibleError, match="model class is wrong") as ei:
        sm.pui((y, u), short, DELTA)
    assert ei.value.eps_min > DELTA


def test_per_sample_bounds_and_box(fir_data):
    y, u, e = fir_data
    eps = np.full(len(y), DELTA)
    eps[::10] = 2 * DELTA
    r = sm.pui((y, u), FIR, eps)
    assert isinstance(r.eps, np.ndarray) and r.contains(FIR_TRUE).all()
    boxed = sm.pui((y, u), FIR, DELTA, box=(FIR_TRUE - 1e-4, FIR_TRUE + 1e-4))
    assert np.all(boxed.width <= 2e-4 + 1e-12) and boxed.contains(FIR_TRUE).all()
    with pytest.raises(ParameterError):
        sm.pui((y, u), FIR, -1.0)
    with pytest.raises(ParameterError):
        sm.pui((y, u), FIR, 0.1, threads=-2)


def test_threads_do_not_change_the_result(arx_data):
    y, u, _ = arx_data
    a = sm.pui((y, u), ARX, DELTA, threads=1)
    b = sm.pui((y, u), ARX, DELTA, threads=2)
    np.testing.assert_array_equal(a.lower, b.lower)
    np.testing.assert_array_equal(a.upper, b.upper)


def test_to_pandas_and_plot(arx_data):
    import matplotlib.pyplot as plt

    y, u, _ = arx_data
    r = sm.pui((y, u), ARX, DELTA)
    df = r.to_pandas()
    assert df.shape == (6, 5)
    assert list(df.columns) == ["lower", "upper", "width", "center", "minimax"]
    assert list(df.index) == ARX.names and df.index.name == "parameter"
    assert df.attrs["eps"] == DELTA and df.attrs["n"] == 998
    dt = r.to_pandas(truth=ARX_TRUE)
    assert list(dt.columns)[-2:] == ["truth", "inside"] and dt["inside"].all()
    assert r["a1"][0] <= -1.2 <= r["a1"][1]
    assert "a1" in r.summary() and "PUIResult(" in repr(r)
    fig = r.plot(truth=ARX_TRUE)
    assert len([a for a in fig.axes if a.get_visible()]) == 6  # one panel per parameter
    plt.close(fig)


# ---------------------------------------------------------------- output error
def _oe_data(n, seed, delta=0.05):
    u = _inputs(n, 2, seed, pole=0.8)
    e = np.random.default_rng(seed + 1000).uniform(-delta, delta, n)
    return sm.simulate(OE, OE_TRUE, u, e), u


def test_oe_numerator_exact_when_denominator_is_right():
    y, u = _oe_data(600, 7)
    den = {"u1": OE_TRUE[0:2], "u2": np.r_[1.0, OE_TRUE[2:4]]}  # both spellings
    r = sm.oe_pui((y, u), OE, 0.05, denominators=den)
    assert r.exact
    assert r.contains(OE_TRUE).all(), r.to_pandas(OE_TRUE)
    np.testing.assert_array_equal(r.lower[:4], OE_TRUE[:4])  # given: point intervals
    np.testing.assert_array_equal(r.lower[4:], r.conditional.lower)
    with pytest.raises(ParameterError, match="unstable"):
        sm.oe_pui((y, u), OE, 0.05, denominators=[[-2.1, 1.2], OE_TRUE[2:4]])
    with pytest.raises(InputError, match="missing"):
        sm.oe_pui((y, u), OE, 0.05, denominators={"u1": OE_TRUE[:2]})


def test_oe_scheme_finds_the_denominator_and_covers_the_truth():
    y, u = _oe_data(1000, 11)
    r = sm.oe_pui((y, u), OE, 0.05)
    assert not r.exact and "linearised" in r.approximation
    # the denominator found is the true one to within the noise
    np.testing.assert_allclose(r.minimax[:4], OE_TRUE[:4], atol=0.02)
    for name, f in zip(OE.inputs, (OE_TRUE[:2], OE_TRUE[2:4])):
        np.testing.assert_allclose(r.denominators[name], np.r_[1.0, f], atol=0.02)
    assert r.eps_min <= 0.05
    assert r.contains(OE_TRUE).all(), r.to_pandas(OE_TRUE)
    # the reported intervals contain the exact numerator intervals given F̂
    assert np.all(r.lower[4:] <= r.conditional.lower + 1e-12)
    assert np.all(r.upper[4:] >= r.conditional.upper - 1e-12)
    accepted = [h for h in r.iterations if h["accepted"]]
    assert accepted[0]["source"] == "equation error" and accepted[-1]["eps_oe"] == pytest.approx(r.eps_min)
    assert all(b["eps_oe"] < a["eps_oe"] for a, b in zip(accepted, accepted[1:]))
    df = r.to_pandas(OE_TRUE)
    assert {"cond_lower", "cond_upper"} <= set(df.columns)
    import matplotlib.pyplot as plt

    plt.close(r.plot(truth=OE_TRUE))


def test_oe_monte_carlo_coverage():
    """Many noise realisations of the same OE system: the exact intervals given the true
    denominator contain the truth every time (a guarantee); the full scheme (estimated
    denominator, first-order joint intervals, an approximation) is checked to cover it
    too, and its intervals to be of the size of the Monte Carlo spread of the estimates."""
    runs = 12
    cover_exact = np.zeros(9)
    cover_scheme = np.zeros(9)
    centres, widths = [], []
    for k in range(runs):
        y, u = _oe_data(300, 100 + k)
        given = sm.oe_pui((y, u), OE, 0.05, denominators=[OE_TRUE[:2], OE_TRUE[2:4]], threads=1)
        full = sm.oe_pui((y, u), OE, 0.05, threads=1)
        cover_exact += given.contains(OE_TRUE)
        cover_scheme += full.contains(OE_TRUE)
        centres.append(full.center)
        widths.append(full.width)
    assert np.all(cover_exact == runs)
    assert np.all(cover_scheme >= runs - 1), cover_scheme / runs
    spread = np.ptp(np.array(centres), axis=0)
    w = np.mean(widths, axis=0)
    assert np.all(w > 0.3 * spread) and np.all(w < 20 * spread + 1e-3)


def test_oe_sweep_verifies_points_and_infeasible_bound():
    y, u = _oe_data(400, 21)
    r = sm.oe_pui((y, u), OE, 0.05, sweep=6, threads=1)
    sw = r.sweep
    assert sw is not None and sw["drawn"] >= 6 and 0 < sw["feasible"] <= sw["stable"] <= sw["drawn"]
    assert np.all(r.lower <= sw["lower"] + 1e-12) and np.all(r.upper >= sw["upper"] - 1e-12)
    with pytest.raises(sm.InfeasibleError, match="upper bound on the exact one") as ei:
        sm.oe_pui((y, u), OE, 0.02, threads=1)
    assert ei.value.eps_min > 0.02 and ei.value.minimax.shape == (9,)
    with pytest.raises(ParameterError, match="OE structure"):
        sm.oe_pui((y, u), FIR, 0.05)
    with pytest.raises(ParameterError, match="oe_pui"):
        sm.pui((y, u), OE, 0.05)
    assert sm.identify((y, u), OE, 0.05, threads=1).structure is OE
    assert sm.identify((y, u), FIR, 10.0).structure is FIR


# ---------------------------------------------------------------- popup data
@pytest.fixture(scope="module")
def popup_run():
    """8 s of encoder replay of popup-lab at 100 Hz: small multisine moves of q2 and q3
    from rest about the lab pose."""
    model = popup.Model("popup-lab", payload_kg=1.0)
    t = np.arange(800) / 100.0
    rng = np.random.default_rng(0)
    q = np.tile([0.0, -math.pi / 2 + 0.6, 0.5], (t.size, 1))
    ramp = np.clip(t / 2.0, 0, 1) ** 2 * (3 - 2 * np.clip(t / 2.0, 0, 1))
    for j in (1, 2):
        f = rng.uniform(0.05, 1.0, 6)
        ph = rng.uniform(0, 2 * math.pi, 6)
        s = np.sum(np.sin(2 * math.pi * f[:, None] * t + ph[:, None]) - np.sin(ph[:, None]), axis=0)
        q[:, j] += 0.05 * ramp * s / np.max(np.abs(s))
    return model.replay(t, q, sample_rate=100.0)


def test_popup_simulation_thesis_inputs(popup_run):
    d = sm.iddata(popup_run, "ee_x", sm.THESIS_INPUTS)
    assert len(d) == 800 and d.dt == pytest.approx(0.01) and d.inputs == sm.THESIS_INPUTS
    arx = sm.arx(2, 2, 0, inputs=sm.THESIS_INPUTS, output="ee_x", offset=True)
    r = sm.pui(popup_run, arx, 0.005)  # 5 mm, the thesis's bound, on the equation error
    assert r.unit == "m" and r.n == 798 and r.contains(r.center).all()
    s = sm.oe(nb=2, nf=2, nk=0, inputs=sm.THESIS_INPUTS, output="ee_x")
    o = sm.oe_pui(popup_run, s, 0.01)
    assert o.eps_min < 0.01 and o.n == 800 and len(o.names) == 17
    assert np.all(np.isfinite(o.lower[-1:])) and o.lower[-1] < 0.87 < o.upper[-1]  # c: x at rest [m]
    # the identified model reproduces x within the bound
    yhat = sm.simulate(s, o.minimax, d.u)
    assert np.max(np.abs(yhat - d.y)) == pytest.approx(o.eps_min, rel=1e-5)
    # windows and decimation
    w = sm.iddata(popup_run, "ee_x", ["q2", "q3"], t_start=2.0, t_stop=5.0, step=2)
    assert len(w) == 151 and w.dt == pytest.approx(0.02) and any("decimated" in n for n in w.notes)


def test_measured_run_with_derived_rates():
    run = popup.read_run(Path(__file__).resolve().parents[1] / "examples" / "data" / "lab_run")
    assert "dq2" not in run.columns
    arx = sm.arx(2, 2, 0, inputs=sm.THESIS_INPUTS, output="ee_x", offset=True)
    r = sm.pui(run, arx, 0.05, t_start=1.0, t_stop=6.0)
    assert any("dq2 derived from q2" in n for n in r.notes)
    assert r.eps_min < 0.05 and r.n_data == 1251
    with pytest.raises(sm.InfeasibleError):
        sm.pui(run, arx, 1e-6, t_start=1.0, t_stop=6.0)
    with pytest.raises(InputError, match="no channel 'imu9'"):
        sm.iddata(run, "ee_x", ["imu9"])
    with pytest.raises(InputError, match="no channel 'dq2'"):
        sm.iddata(run, "ee_x", ["dq2"], derive_rates=False)


def test_iddata_errors():
    t = np.r_[np.arange(10) * 0.01, 0.2]
    with pytest.raises(InputError, match="not uniform"):
        sm.iddata({"t": t, "y": np.zeros(11), "u": np.zeros(11)}, "y", "u")
    with pytest.raises(InputError, match="at least 2"):
        sm.iddata({"t": t, "y": np.zeros(11), "u": np.zeros(11)}, "y", "u", t_start=5.0)
    with pytest.raises(InputError, match="cannot take"):
        sm.iddata(42, "y", "u")
    with pytest.raises(ParameterError, match="step"):
        sm.iddata({"t": t, "y": np.zeros(11), "u": np.zeros(11)}, "y", "u", step=0)
