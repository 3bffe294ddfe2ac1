"""popup.compare: model vs measured run (measured runs simulated by the model itself)."""

import json

import numpy as np
import pytest

import popup
import popup.compare as pc
from popup.io import from_sim, read_run, write_run

IMU_TIP = ["imu1_ax", "imu1_ay", "imu1_az", "imu2_ax", "imu2_ay", "imu2_az", "ee_x", "ee_y", "ee_z"]


@pytest.fixture(scope="module")
def truth() -> popup.Model:
    return popup.Model(payload_kg=2.0)


@pytest.fixture(scope="module")
def wrong(truth) -> popup.Model:
    return truth.with_params(payload_kg=1.5)


@pytest.fixture(scope="module")
def sim_df(truth):
    """A smooth 4 s encoder move at 500 Hz, replayed by the 2 kg model."""
    t = np.arange(0, 4.0 + 1e-12, 0.002)
    s = 0.5 - 0.5 * np.cos(np.pi * np.clip(t / 3.0, 0, 1))
    q = np.stack([0.4 * s, 0.3 * s, -0.3 * s], axis=1)
    return from_sim(truth.replay(t, q, sample_rate=500.0))


def _write(tmp_path, df, name="run", **exp):
    e = dict(df.attrs["experiment"])
    e.update(exp)
    return read_run(write_run(tmp_path / name, e, df))


@pytest.fixture(scope="module")
def clean_run(sim_df, tmp_path_factory):
    return _write(tmp_path_factory.mktemp("clean"), sim_df)


@pytest.fixture(scope="module")
def noisy_run(sim_df, tmp_path_factory):
    rng = np.random.default_rng(12345)
    df = sim_df.copy()
    df.attrs = dict(sim_df.attrs)
    for c in pc.DEFAULT_CHANNELS:
        df[c] = df[c] + 0.01 * float(np.std(df[c])) * rng.standard_normal(len(df))
    return _write(tmp_path_factory.mktemp("noisy"), df)


@pytest.fixture(scope="module")
def cmp_wrong(wrong, clean_run):
    return pc.compare(wrong, clean_run)


def test_same_model_is_exact(truth, clean_run):
    c = pc.compare(truth, clean_run)
    assert isinstance(c, pc.Comparison)
    assert c.channels == list(pc.DEFAULT_CHANNELS)
    # a sparser encoder gives another spline: close, not exact
    assert c.overall["fit_pct"] > 90.0
    assert c.metrics.loc["ee_z", "nrmse_fit_pct"] > 99.0
    assert np.allclose(c.metrics["nrmse_fit_pct"], 100.0)
    assert c.overall["fit_pct"] == pytest.approx(100.0)
    assert c.overall["nrmse"] < 1e-9
    assert c.overall["sample_rate_hz"] == pytest.approx(500.0)
    assert set(c.metrics.columns) >= {"rmse", "nrmse_fit_pct", "max_abs_error", "t_max_error", "unit"}
    assert c.metrics.loc["tau1", "unit"] == "N·m"
    assert np.abs(c.residuals.to_numpy()).max() < 1e-9
    assert any("compared 12 channel" in n for n in c.notes)
    assert c.params == truth.describe()
    # the measured data is untouched
    assert np.array_equal(c.measured.channel("ee_z"), clean_run.channel("ee_z"))


def test_wrong_payload_is_worse_and_shares_sum_to_one(truth, clean_run, cmp_wrong):
    c = cmp_wrong
    assert c.overall["fit_pct"] < 90.0
    assert c.overall["nrmse"] > 0.1
    assert (c.metrics["rmse"] > 1e-6).all()
    assert any("differ from the run's declared" in n for n in c.notes)
    w = c.windows
    assert len(w) == 10 and np.isfinite(w["error_share"]).all()
    assert w["error_share"].sum() == pytest.approx(1.0)
    assert sorted(w["rank"]) == list(range(1, 11))
    cond = c.conditions
    assert set(cond["binning"]) == {"sign dq1", "sign dq2", "sign dq3", "|M|/M_w", "tip speed", "time"}
    for _, g in cond.groupby("binning"):
        assert np.isfinite(g["error_share"]).all() and np.isfinite(g["sample_share"]).all()
        assert g["error_share"].sum() == pytest.approx(1.0)
        assert g["sample_share"].sum() == pytest.approx(1.0)
        assert g["share tau2"].sum() == pytest.approx(1.0)
    # the worst channel is one of the load-carrying torques
    assert c.overall["worst_channel"] in ("tau2", "tau3")


def test_noise_whiteness(truth, wrong, noisy_run):
    good = pc.compare(truth, noisy_run)
    bad = pc.compare(wrong, noisy_run)
    assert good.whiteness["is_white"].mean() >= 0.75
    assert good.overall["fit_pct"] > 95.0
    assert not bad.whiteness.loc[IMU_TIP, "is_white"].any()
    assert bad.overall["fit_pct"] < good.overall["fit_pct"]
    # residual-input cross-correlation: the wrong model's residual follows the inputs
    xc = bad.cross_correlation
    assert set(xc["input"]) == {"dq1", "dq2", "dq3"}
    assert xc["significant"].any()
    assert good.cross_correlation["significant"].mean() <= 0.2
    assert bad.cross_correlation["peak_value"].abs().mean() > 2 * good.cross_correlation["peak_value"].abs().mean()
    # spectrum: energy fractions per band sum to 1, the dominant band is named
    frac = good.spectrum[[k for k in good.spectrum.columns if k.startswith("frac ")]]
    assert np.allclose(frac.sum(axis=1), 1.0)
    assert (bad.spectrum["dominant_band_hi_hz"] <= 250.0 + 1e-9).all()


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_periodic_error_is_a_line_at_its_frequency(truth, noisy_run, tmp_path, seed):
    """A sinusoid added to one channel (frequency drawn off any bin grid, amplitude 3-10 ×
    the noise) is found at its frequency to a twentieth of 1/T, where Welch's segments
    (the octave bands) resolve 1 Hz on this 4 s run, with most of the channel's residual
    power in the Hann main lobe (±2/T); a channel with only white noise has no line."""
    rng = np.random.default_rng(seed)
    df = noisy_run.data.copy()
    t = df["t"].to_numpy() if "t" in df else df.index.to_numpy()
    sd = 0.01 * float(np.std(noisy_run.channel("imu2_az")))
    f0 = float(rng.uniform(0.8, 40.0))
    df["imu2_az"] = df["imu2_az"] + rng.uniform(3, 10) * sd * np.sin(2 * np.pi * f0 * t + rng.uniform(0, 2 * np.pi))
    run = read_run(write_run(tmp_path / "line", dict(noisy_run.experiment), df))
    sp = pc.compare(truth, run).spectrum
    T = float(t[-1] - t[0])
    assert sp.loc["imu2_az", "peak_hz"] == pytest.approx(f0, abs=0.05 / T), (f0, sp.loc["imu2_az"])
    assert sp.loc["imu2_az", "line_fraction"] > 0.8
    assert sp.loc["imu2_az", "line_halfwidth_hz"] == pytest.approx(2.0 / T, rel=0.01)
    assert sp.loc["imu1_ax", "line_fraction"] < 0.1


def test_delay_shows_at_positive_lag(truth, sim_df, tmp_path):
    df = sim_df.copy()
    df.attrs = dict(sim_df.attrs)
    for c in [k for k in df.columns if k.startswith("imu")]:
        y = df[c].to_numpy()
        df[c] = np.concatenate([np.full(10, y[0]), y[:-10]])  # the sensor lags by 10 samples
    run = _write(tmp_path, df)
    c = pc.compare(truth, run)
    d = c.delay
    imu = [k for k in c.channels if k.startswith("imu")]
    strong = [k for k in imu if c.metrics.loc[k, "std_measured"] > 0.05]
    assert strong
    for k in strong:
        assert d.loc[k, "delay_samples"] == 10, (k, d.loc[k])
        assert d.loc[k, "delay_s"] == pytest.approx(0.02)
    assert (d.loc[["ee_x", "tau1"], "delay_samples"] == 0).all()
    assert (c.metrics.loc[["ee_x", "tau1"], "rmse"] < 1e-9).all()


def test_a_constant_offset_is_the_errors_mean(truth, noisy_run, tmp_path):
    """A sensor bias on one channel shows as that channel's ``mean_error`` (measured −
    simulated) with ``mean_share`` near 1; the other channels' means stay at the noise's
    scatter."""
    df = noisy_run.data.copy()
    df["imu2_ax"] = df["imu2_ax"] + 0.2
    run = read_run(write_run(tmp_path / "biased", dict(noisy_run.experiment), df))
    c = pc.compare(truth, run)
    m = c.metrics
    n = int(m.loc["imu2_ax", "n_samples"])
    assert m.loc["imu2_ax", "mean_error"] == pytest.approx(0.2, abs=5 * m.loc["imu2_ax", "noise_std"] / np.sqrt(n))
    assert m.loc["imu2_ax", "mean_share"] > 0.95
    others = m.drop(index="imu2_ax")
    assert (others["mean_error"].abs() <= 5 * others["noise_std"] / np.sqrt(others["n_samples"])).all(), others[["mean_error", "noise_std"]]


def test_outputs_and_plots(cmp_wrong):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = cmp_wrong.to_pandas()
    assert list(t.index) == list(pc.DEFAULT_CHANNELS)
    d = cmp_wrong.to_dict()
    s = json.dumps(d, allow_nan=False)
    assert "nrmse_fit_pct" in s and d["overall"]["n_channels"] == 12
    for kind in ("overlay", "residuals"):
        fig = cmp_wrong.plot(kind)
        assert fig.axes
        plt.close(fig)
    with pytest.raises(popup.InputError):
        cmp_wrong.plot("nope")


def test_channels_and_errors(truth, sim_df, tmp_path, clean_run):
    c = pc.compare(truth, clean_run, channels=["ee_z", "dq1"])
    assert c.channels == ["ee_z", "dq1"]
    assert any("spline" in n for n in c.notes)
    with pytest.raises(popup.MeasuredRunError, match="cannot compare"):
        pc.compare(truth, clean_run, channels=["d11"])
    # a channel named twice is refused by name (found by the fuzz test: a pandas error before)
    with pytest.raises(popup.InputError, match=r"\['ee_z'\] named more than once"):
        pc.compare(truth, clean_run, channels=["ee_z", "dq1", "ee_z"])
    # no comparable channel: only the encoder
    only_q = sim_df[["t", "q1", "q2", "q3", "p1", "p2"]].copy()
    only_q.attrs = dict(sim_df.attrs)
    run = _write(tmp_path, only_q, "onlyq")
    with pytest.raises(popup.MeasuredRunError, match="nothing to compare") as e:
        pc.compare(truth, run)
    assert "q1" in str(e.value)
    # closed-loop replay: a [controller] table the controller model does not know is refused
    ref = sim_df[["t", "ee_z"]].copy()
    ref["ref_q1"], ref["ref_q2"], ref["ref_q3"] = sim_df["q1"], sim_df["q2"], sim_df["q3"]
    ref.attrs = dict(sim_df.attrs)
    run = _write(tmp_path, ref, "ref", replay="reference", controller={"kp": 100.0})
    with pytest.raises(popup.MeasuredRunError, match="(?s)controller.*kp"):
        pc.compare(truth, run)


def test_missing_cells_and_other_rate(truth, sim_df, tmp_path):
    df = sim_df.iloc[::3].reset_index(drop=True)  # 166.7 Hz
    df.attrs = dict(sim_df.attrs)
    df.loc[5:9, "ee_z"] = np.nan
    run = _write(tmp_path, df)
    c = pc.compare(truth, run)
    assert c.overall["sample_rate_hz"] == pytest.approx(1.0 / 0.006)
    assert c.metrics.loc["ee_z", "n_samples"] == len(df) - 5
    assert any("ee_z: 5 missing" in n for n in c.notes)
    # a sparser encoder gives another spline: close, not exact
    assert c.overall["fit_pct"] > 90.0
    assert c.metrics.loc["ee_z", "nrmse_fit_pct"] > 99.0
