"""`popup.fit_params`: fit any named effect parameters to a measured run — here a beam link's
E and stiffness-proportional damping recovered from a run of the same model with known
values (noise free), and bad requests refused by name."""

import numpy as np
import pytest

import popup
from popup.io import from_sim, read_run, write_run

TRUE_E, TRUE_LAM = 0.25e9, 6e-4


def _beam(e: float, lam: float) -> popup.Model:
    m = popup.Model("popup-lab", payload_kg=1.0, dt=1e-4, integrator="semi_implicit")
    return m.with_links("prbm", "beam(2)", e_pa=[0.557e9, e], lambda_s=[3.896e-4, lam])


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    m = _beam(TRUE_E, TRUE_LAM)
    t = np.arange(0.0, 1.2 + 1e-9, 5e-3)
    q = np.column_stack([0.2 * np.sin(3 * t), 0.3 + 0.25 * np.sin(5 * t), -0.3 * np.sin(7 * t)])
    res = m.replay(t, q, sample_rate=200.0)
    d = tmp_path_factory.mktemp("run") / "beam"
    df = from_sim(res, description="beam link 2, E and λ known")
    write_run(d, df.attrs["experiment"], df)
    return read_run(d)


def test_beam_e_and_damping_are_recovered(run):
    start = _beam(0.5e9, 2e-4)
    names = ["higher_bending_modes.e_pa[1]", "higher_bending_modes.lambda_s[1]"]
    res = popup.fit_params(
        start,
        run,
        names,
        bounds={"higher_bending_modes.e_pa": (5e7, 2e9), "higher_bending_modes.lambda_s": (1e-5, 5e-3)},
        grid={"higher_bending_modes.e_pa[1]": [0.1e9, 0.2e9, 0.4e9, 0.8e9]},
        channels=["ee_x", "ee_z", "imu2_ay"],
    )
    assert res.names == names
    assert res.params[names[0]] == pytest.approx(TRUE_E, rel=1e-3)
    assert res.params[names[1]] == pytest.approx(TRUE_LAM, rel=2e-2)
    assert res.error < 1e-2 * res.error_before
    assert np.all(res.ci95 >= 0) and np.all(np.isfinite(res.ci95))
    # the fitted model carries the values; link 1's material is untouched
    hbm = res.model.effects["higher_bending_modes"]
    assert hbm["e_pa"][0] == 0.557e9 and hbm["e_pa"][1] == pytest.approx(res.x[0])
    df = res.to_pandas()
    assert list(df.index) == names and {"start", "fitted", "ci95", "lower", "upper"} <= set(df.columns)
    assert df.loc[names[0], "lower"] == 5e7
    fig = res.plot()
    assert len(fig.axes) == 3
    assert "e_pa[1]" in repr(res)


@pytest.mark.parametrize(
    "params, kw, needle",
    [
        (["nope.x"], {}, "unknown effect"),
        (["joint_friction.q"], {}, "no parameter"),
        (["higher_bending_modes.elements[1]"], {}, "structural"),
        (["joint_friction.b[5]"], {}, "out of range"),
        (["joint_friction.b[0]"], {"x0": {"joint_friction.b[0]": 500.0}}, "outside its bounds"),
        (["joint_friction.b[0]"], {"bounds": {"joint_friction.tau_c": (0, 1)}}, "not among the fitted"),
        (["joint_friction.b[0]"], {"x0": {"joint_friction.b[2]": 0.1}}, "not among the fitted"),
        (["joint_friction.b[0]"], {"bounds": {"joint_friction.b": (1.0, 0.5)}}, "lower < upper"),
        (["joint_friction.b", "joint_friction.b[1]"], {}, "named twice"),
        ("joint_friction", {}, "not 'effect.name'"),
    ],
)
def test_bad_requests_are_refused_by_name(run, params, kw, needle):
    with pytest.raises(popup.InputError, match=needle):
        popup.fit_params(_beam(0.5e9, 2e-4), run, params, **kw)


def test_payload_is_found_from_the_declared_start_by_multistart(tmp_path):
    """A payload 0.5 kg heavier than declared, fitted from the declared one: the effect's
    seed points (simulated in one batch) start the fit near the truth; the result says
    whether other starts ended elsewhere and reports identifiability."""
    nominal = popup.Model("popup-lab", payload_kg=1.0)
    t, q = popup.synth.lab_trajectory(6.0, rate=250.0, seed=4)
    run = popup.synth.measured_run(nominal.with_effect("payload_mass", delta_kg=0.5), t, q, tmp_path / "payload", seed=4)
    res = popup.fit_params(nominal, run, ["payload_mass.delta_kg"])
    assert res.params["payload_mass.delta_kg[0]"] == pytest.approx(0.5, abs=max(3 * res.ci95[0], 0.01))
    assert res.error < 0.3 < res.error_before  # systematic error in noise units: at the floor after
    assert res.identifiability["unidentifiable"] == [] and isinstance(res.warnings, list)
    assert set(res.noise) == set(res.channels)
    # one start only (no seeds, no grid): the same problem, fitted from the declared payload
    one = popup.fit_params(nominal, run, ["payload_mass.delta_kg"], seeds=False, starts=1)
    assert one.nfev < res.nfev


def test_max_iter_zero_evaluates_the_start_without_moving_it(tmp_path):
    """Found by tests/test_fuzz_api.py: ``max_iter=0`` reached scipy as ``max_nfev=0`` and
    raised its ValueError. It means: evaluate the start, report it, do not iterate."""
    nominal = popup.Model("popup-lab", payload_kg=1.0)
    t, q = popup.synth.lab_trajectory(6.0, rate=250.0, seed=4)
    run = popup.synth.measured_run(nominal.with_effect("payload_mass", delta_kg=0.5), t, q, tmp_path / "payload", seed=4)
    res = popup.fit_params(nominal, run, ["payload_mass.delta_kg"], max_iter=0, seeds=False, starts=1)
    assert res.params["payload_mass.delta_kg[0]"] == 0.0  # the declared start, not moved
    assert res.error == pytest.approx(res.error_before)
    moved = popup.fit_params(nominal, run, ["payload_mass.delta_kg"], max_iter=5, seeds=False, starts=1)
    assert moved.params["payload_mass.delta_kg[0]"] != 0.0
