"""popup.sweep: designs, bit-for-bit agreement with single scenario runs and the CLI,
determinism over threads / batch sizes / executors (a real dask LocalCluster), errors,
the robustness helper and the plots."""

from __future__ import annotations

import concurrent.futures as cf
import math
import os
import pickle
import tempfile
from pathlib import Path
from typing import Any, Dict, List

import numpy as np
import pandas as pd
import pytest

import popup
from popup import _core
from popup.control import CONTROL_CHANNELS, Controller, Phase, Task, step
from popup.sweep import (
    CLI_COLUMNS,
    METRICS,
    MetricOptions,
    SweepError,
    SweepResult,
    UnknownParameterError,
    robustness,
    run_chunk,
    scenario_from_task,
    sweep,
)

DUR = 0.4  # simulated seconds per run: short, the sweeps below are about bookkeeping


def _base(noise: bool = False) -> Dict[str, Any]:
    """A small closed-loop scenario: a min-jerk move with the damping PIDs on, 10 kHz."""
    d: Dict[str, Any] = {
        "format": "popup-scenario/1",
        "arm": "popup-lab",
        "payload_kg": 1.0,
        "pressure_pa": [40000.0, 40000.0],
        "q0": [0.0, 0.6, -0.4],
        "duration_s": DUR,
        "dt": 1e-4,
        "sample_rate_hz": 250.0,
        "seed": 4,
        "controller": {"rate_hz": 10000.0, "damping": True, "gains": {"vel_kp": 5000.0}},
        "faults": {"wrinkle": "continue"},
        "phases": [{"kind": "moving", "name": "Go", "move_to": {"q": [0.1, 0.7, -0.5], "duration": 0.3}}],
    }
    if noise:
        d["noise"] = {"imu_m_s2": 0.05, "encoder_rad": 1e-4}
    return d


@pytest.fixture(scope="module")
def base() -> popup.Scenario:
    return popup.Scenario.from_dict(_base())


def _numeric(df: pd.DataFrame) -> np.ndarray:
    return df[[c for c in df.columns if df[c].dtype.kind in "fiub"]].to_numpy(dtype=np.float64)


def _same(a: SweepResult, b: SweepResult) -> None:
    """Bit for bit: every numeric column, status, error, events, alarms, series."""
    assert list(a.table.columns) == list(b.table.columns)
    assert np.array_equal(_numeric(a.table), _numeric(b.table), equal_nan=True)
    assert a.table["status"].tolist() == b.table["status"].tolist()
    assert a.table["error"].tolist() == b.table["error"].tolist()
    assert repr(a.events) == repr(b.events)  # repr: exact floats, NaN == NaN
    assert repr(a.alarms) == repr(b.alarms)
    if a.series is not None or b.series is not None:
        assert a.series is not None and b.series is not None
        assert np.array_equal(a.series.values, b.series.values, equal_nan=True)


def _single(sc: popup.Scenario, res: SweepResult, i: int) -> popup.ControlResult:
    s = sc
    for k in res.params:
        s = s.set(k, float(res.table[k].iloc[i]))
    if res.table["seed"].iloc[i] != s.seed:
        s = s.set("seed", float(res.table["seed"].iloc[i]))
    return s.run()


def _machine_events(r: popup.ControlResult) -> List[Any]:
    """The run's log without the wrinkling-episode entries (a sweep keeps those in ``alarms``)."""
    return [e for e in r.events if e.kind not in ("wrinkle_start", "wrinkle_end")]


def _series_of(r: popup.ControlResult, channels: List[str]) -> np.ndarray:
    cols = []
    for c in channels:
        cols.append(r.channel(c) if c in popup.CHANNELS else r.control_channel(c))
    return np.stack(cols, axis=1)


# ---------------------------------------------------------------- agreement
def test_grid_runs_equal_single_scenario_runs_bit_for_bit(base: popup.Scenario) -> None:
    res = sweep(base, grid={"payload_kg": [0.0, 2.0], "pressure_pa[1]": [20e3, 60e3], "effects.joint_friction.tau_c": [0.0, 0.8]}, series=True)
    assert len(res) == 8 and res.kind == "grid" and list(res.grid) == res.params
    # row-major: the last axis varies fastest, as popup sweep
    assert res.table["effects.joint_friction.tau_c"].tolist() == [0.0, 0.8] * 4
    assert res.table["payload_kg"].tolist() == [0.0] * 4 + [2.0] * 4
    assert res.info["batched_runs"] == 8 and res.info["scenario_runs"] == 0
    assert res.series is not None and res.series.dims == ("run", "time", "channel")
    assert res.series.shape == (8, int(round(DUR * 250)) + 1, len(popup.CHANNELS) + len(CONTROL_CHANNELS))
    for i in range(len(res)):
        r = _single(base, res, i)
        assert r.status == res.table["status"].iloc[i] == "completed"
        assert np.array_equal(res.series.values[i], _series_of(r, res.series.channels), equal_nan=True)
        assert repr(res.events[i]) == repr(_machine_events(r))
        assert repr(res.alarms[i]) == repr(r.alarms)
        assert res.table["wrinkle_alarms"].iloc[i] == len(r.alarms)
    # the parameters did something
    assert len(set(res.table["peak_m2_ratio"])) == 8


def test_metrics_equal_the_cli_summary_bit_for_bit(base: popup.Scenario, tmp_path: Path) -> None:
    path = base.write(tmp_path / "s.toml")
    out = tmp_path / "out"
    rc = _core.run_cli(["popup", "sweep", str(path), "--param", "payload_kg=0,2.5", "--param", "controller.gains.damp_kp=0,0.04", "--out", str(out)])
    assert rc == 0
    cli = pd.read_csv(out / "summary.csv")
    res = sweep(path, grid={"payload_kg": [0, 2.5], "controller.gains.damp_kp": [0, 0.04]})
    t = res.table
    assert len(cli) == len(t) == 4
    for k in ("payload_kg", "controller.gains.damp_kp"):
        assert np.array_equal(cli[k].to_numpy(float), t[k].to_numpy(float))
    for c in CLI_COLUMNS:
        if c == "status":
            assert cli[c].tolist() == t[c].tolist()
        else:
            assert np.array_equal(cli[c].to_numpy(float), t[c].to_numpy(float), equal_nan=True), c
    # derived metrics follow from the shared ones
    assert np.array_equal(t["peak_moment_ratio"], np.maximum(t["peak_m1_ratio"], t["peak_m2_ratio"]))
    assert set(METRICS) <= set(t.columns)


def test_task_keys_initial_pose_and_gains_group_and_match_single_runs(base: popup.Scenario) -> None:
    # a reference amplitude (a key inside the task) makes separate groups; pose and gains batch
    pts = {"phases[0].move_to.q[1]": [0.7, 0.9, 0.7], "q0[1]": [0.6, 0.6, 0.5], "controller.gains.damp_kp": [0.0, 0.04, 0.02]}
    res = sweep(base, points=pts, series=["q2", "ref_q2", "m2_ratio"], batch_size=1)
    assert res.kind == "points" and len(res) == 3 and res.info["chunks"] == 3
    for i in range(3):
        r = _single(base, res, i)
        assert np.array_equal(res.series.values[i], _series_of(r, ["q2", "ref_q2", "m2_ratio"]), equal_nan=True)
    # the reference amplitude reached the run: the final reference is the target
    assert res.series.channel("ref_q2")[0, -1] == pytest.approx(0.7)
    assert res.series.channel("ref_q2")[1, -1] == pytest.approx(0.9)


def test_structural_effects_and_noisy_scenarios(base: popup.Scenario) -> None:
    # segments of the PRBM change the compiled model: a group per value, still equal to single runs
    res = sweep(base, grid={"effects.higher_bending_modes.segments": [1, 2], "payload_kg": [0.5, 1.5]}, series=["d11", "imu2_az"])
    assert res.info["chunks"] == 2
    for i in range(len(res)):
        assert np.array_equal(res.series.values[i], _series_of(_single(base, res, i), ["d11", "imu2_az"]), equal_nan=True)
    # sensor noise: run one by one through the scenario runner (seeded), bit for bit, any batch size
    noisy = popup.Scenario.from_dict(_base(noise=True))
    a = sweep(noisy, grid={"payload_kg": [0.5, 1.5], "seed": [1, 2]}, series=["imu2_az", "q1"])
    assert a.info["scenario_runs"] == 4 and a.info["batched_runs"] == 0
    for i in range(len(a)):
        assert np.array_equal(a.series.values[i], _series_of(_single(noisy, a, i), ["imu2_az", "q1"]), equal_nan=True)
    # different seeds, different noise
    assert not np.array_equal(a.series.channel("imu2_az")[0], a.series.channel("imu2_az")[1])
    _same(a, sweep(noisy, grid={"payload_kg": [0.5, 1.5], "seed": [1, 2]}, series=["imu2_az", "q1"], batch_size=3, threads=1))


# ---------------------------------------------------------------- determinism
def test_identical_for_any_batch_size_and_thread_count(base: popup.Scenario) -> None:
    kw: Dict[str, Any] = dict(grid={"payload_kg": [0.0, 1.0, 2.5]}, distributions={"pressure_pa": ("uniform", 15e3, 80e3)}, n=2, seed=11, series=["d21", "tau_cmd3"])
    ref = sweep(base, **kw)
    assert ref.info["chunks"] == 1
    for bs, th in ((1, 1), (4, 2), (5, 0)):
        other = sweep(base, batch_size=bs, threads=th, **kw)
        assert other.info["chunks"] == math.ceil(6 / bs)
        _same(ref, other)
    with cf.ThreadPoolExecutor(max_workers=2) as ex:
        _same(ref, sweep(base, executor=ex, batch_size=2, **kw))


def test_monte_carlo_seed_and_common_random_numbers(base: popup.Scenario) -> None:
    import scipy.stats

    dists = {"payload_kg": ("uniform", 0.0, 2.5), "pressure_pa": scipy.stats.norm(40e3, 3e3), "q0[1]": ("choice", [0.5, 0.6])}
    a = sweep(base, distributions=dists, n=5, seed=3, duration=0.05)
    b = sweep(base, distributions=dists, n=5, seed=3, duration=0.05)
    c = sweep(base, distributions=dists, n=5, seed=4, duration=0.05)
    _same(a, b)
    assert a.seed == 3 and a.n_samples == 5 and a.kind == "monte_carlo"
    assert not np.array_equal(a.table["payload_kg"], c.table["payload_kg"])
    # the draws are numpy's default_rng(seed), in the order given
    rng = np.random.default_rng(3)
    assert np.array_equal(a.table["payload_kg"], rng.uniform(0.0, 2.5, 5))
    assert np.array_equal(a.table["pressure_pa"], scipy.stats.norm(40e3, 3e3).rvs(size=5, random_state=rng))
    assert set(a.table["q0[1]"]) <= {0.5, 0.6}
    assert a.table["sample"].tolist() == [0, 1, 2, 3, 4]
    # no seed given: one is drawn and stored, and repeats the sweep
    d = sweep(base, distributions={"payload_kg": ("uniform", 0.0, 2.5)}, n=3, duration=0.05)
    assert isinstance(d.seed, int)
    _same(d, sweep(base, distributions={"payload_kg": ("uniform", 0.0, 2.5)}, n=3, seed=d.seed, duration=0.05))
    # grid x Monte Carlo: the same draws at every grid point
    g = sweep(base, grid={"controller.gains.damp_kp": [0.0, 0.04]}, distributions={"payload_kg": ("normal", 1.0, 0.2)}, n=3, seed=9, duration=0.05)
    assert g.kind == "grid+monte_carlo" and len(g) == 6
    p = g.table["payload_kg"].to_numpy()
    assert np.array_equal(p[:3], p[3:]) and g.table["sample"].tolist() == [0, 1, 2, 0, 1, 2]
    assert g.grid_array("peak_m2_ratio").shape == (2, 3)


def test_workers_receive_plain_data_only(base: popup.Scenario) -> None:
    """The tasks an executor gets are module-level run_chunk + plain configs."""
    sent: List[Any] = []

    class Recorder(cf.Executor):
        def submit(self, fn: Any, *args: Any, **kwargs: Any) -> "cf.Future[Any]":
            sent.append((fn, args))
            f: "cf.Future[Any]" = cf.Future()
            f.set_result(fn(*pickle.loads(pickle.dumps(args))))
            return f

    plain = (str, float, int, bool, type(None), np.ndarray, np.floating, np.integer)

    def check(x: Any) -> None:
        if isinstance(x, dict):
            for k, v in x.items():
                assert isinstance(k, str)
                check(v)
        elif isinstance(x, (list, tuple)):
            for v in x:
                check(v)
        else:
            assert isinstance(x, plain), type(x)
            if isinstance(x, np.ndarray):
                assert x.dtype == np.float64

    res = sweep(base, grid={"payload_kg": [0.0, 1.0, 2.0]}, executor=Recorder(), batch_size=2, duration=0.05)
    assert len(sent) == 2 and all(fn is run_chunk for fn, _ in sent)
    for _, (cfg, chunk) in sent:
        check(cfg)
        check(chunk)
        assert cfg["threads"] == 1 and cfg["kind"] == "batch" and "[[phases]]" in cfg["task"]
    _same(res, sweep(base, grid={"payload_kg": [0.0, 1.0, 2.0]}, duration=0.05))


# ---------------------------------------------------------------- dask.distributed
def test_dask_local_cluster_equals_local_run_bit_for_bit(base: popup.Scenario, monkeypatch: pytest.MonkeyPatch) -> None:
    distributed = pytest.importorskip("distributed")
    # worker processes must import this popup (an editable or a PYTHONPATH checkout alike)
    root = str(Path(popup.__file__).resolve().parent.parent)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([root] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))
    kw: Dict[str, Any] = dict(grid={"payload_kg": [0.0, 1.25, 2.5]}, distributions={"pressure_pa": ("uniform", 20e3, 70e3)}, n=2, seed=21, series=["q2", "m1_ratio", "u_damp2"])
    noisy = popup.Scenario.from_dict(_base(noise=True))
    local = sweep(base, **kw)
    local_noisy = sweep(noisy, points={"payload_kg": [0.5, 2.0]}, series=["imu2_ax"])
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=40, death_timeout=30
    ) as cluster, distributed.Client(cluster, timeout=30) as client:
        client.wait_for_workers(2, timeout=30)
        remote = sweep(base, executor=client, batch_size=1, timeout=60, **kw)  # the Client itself
        remote2 = sweep(base, executor=client.get_executor(pure=False), batch_size=4, timeout=60, **kw)
        remote_noisy = sweep(noisy, executor=client, points={"payload_kg": [0.5, 2.0]}, series=["imu2_ax"], batch_size=1, timeout=60)
    for r in (remote, remote2):
        _same(local, r)
        assert r.info["executor"] == "distributed.cfexecutor.ClientExecutor" and r.info["threads"] == 1
        assert all(int(w.rsplit(":", 1)[1]) != os.getpid() for w in r.info["workers"])  # ran in the worker processes
    assert remote.info["chunks"] == 6
    _same(local_noisy, remote_noisy)
    assert remote_noisy.info["scenario_runs"] == 2


# ---------------------------------------------------------------- errors
def test_bad_input_is_refused_clearly(base: popup.Scenario) -> None:
    with pytest.raises(UnknownParameterError, match="payload") as e:
        sweep(base, grid={"payload": [1.0]})
    assert isinstance(e.value, popup.PopupError) and isinstance(e.value, LookupError) and isinstance(e.value, ValueError)
    with pytest.raises(UnknownParameterError, match="unknown key in \\[controller.gains\\]"):
        sweep(base, grid={"controller.gains.nope": [1.0]})
    with pytest.raises(UnknownParameterError, match="no index 7"):
        sweep(base, points={"q0[7]": [1.0]})
    with pytest.raises(SweepError, match="empty sweep"):
        sweep(base)
    with pytest.raises(SweepError, match="empty"):
        sweep(base, grid={"payload_kg": []})
    with pytest.raises(SweepError, match="same number of values"):
        sweep(base, points={"payload_kg": [0.0, 1.0], "q0[1]": [0.5]})
    with pytest.raises(SweepError, match="twice"):
        sweep(base, grid={"payload_kg": [0.0]}, points={"payload_kg": [1.0]})
    with pytest.raises(SweepError, match="unknown distribution 'gauss'"):
        sweep(base, distributions={"payload_kg": ("gauss", 0, 1)}, n=2)
    with pytest.raises(SweepError, match="low < high"):
        sweep(base, distributions={"payload_kg": ("uniform", 2, 1)}, n=2)
    with pytest.raises(SweepError, match="takes 2 arguments"):
        sweep(base, distributions={"payload_kg": ("normal", 1.0)}, n=2)
    with pytest.raises(SweepError, match="scipy.stats frozen"):
        sweep(base, distributions={"payload_kg": 3.0}, n=2)
    with pytest.raises(SweepError, match="n = the number"):
        sweep(base, distributions={"payload_kg": ("uniform", 0, 1)})
    with pytest.raises(SweepError, match="distributions= too"):
        sweep(base, grid={"payload_kg": [1.0]}, n=3)
    with pytest.raises(SweepError, match="finite"):
        sweep(base, grid={"payload_kg": [float("nan")]})
    with pytest.raises(popup.ScenarioError, match=r"run 1: payload_kg=-1") as se:
        sweep(base, grid={"payload_kg": [1.0, -1.0]})
    assert se.value.problems and se.value.problems[0][2] == "payload_kg"
    with pytest.raises(SweepError, match="unknown channel"):
        sweep(base, grid={"payload_kg": [1.0]}, series=["q9"])
    with pytest.raises(SweepError, match="batch_size"):
        sweep(base, grid={"payload_kg": [1.0]}, batch_size=0)
    with pytest.raises(SweepError, match="executor"):
        sweep(base, grid={"payload_kg": [1.0]}, executor=object())
    with pytest.raises(SweepError, match="duration"):
        sweep(base, grid={"payload_kg": [1.0]}, duration=-1.0)
    with pytest.raises(SweepError, match="settle_tol_rel"):
        MetricOptions(settle_tol_rel=-0.1)
    with pytest.raises(SweepError, match="margin"):
        robustness(base, payload_kg=[0.0], pressure_pa=[30e3], margin=1.5)


def test_a_failed_run_is_a_row_not_an_exception() -> None:
    """At the worker: one run of a chunk fails (its time step is unstable at 0 kg and 90 kPa,
    stiffer and lighter), the other completes; the failure is a status, a message and NaN."""
    from dataclasses import asdict

    from popup import effects as fx

    dt = 0.025
    task = f"[controller]\nrate_hz = {1 / dt!r}\n\n[[phases]]\nkind = \"holding\"\n"
    cfg = {"kind": "batch", "arm": {"builtin": "popup-lab"}, "effects": {}, "dt": dt, "integrator": "rk4", "gravity": True, "task": task,
           "duration": 0.5, "sample_rate": 1 / dt, "series": ["q1"], "metrics": asdict(MetricOptions()), "threads": 1}
    g = Controller(rate_hz=1 / dt).flat_gains()
    chunk = {"runs": [3, 7], "payload_kg": np.array([2.0, 0.0]), "pressure_pa": np.array([[30e3, 30e3], [90e3, 90e3]]), "q0": np.zeros((2, 3)),
             "gains": np.array([g, g]), "effects": np.array([fx.neutral_flat()] * 2)}
    r = run_chunk(cfg, chunk)
    assert r["runs"] == [3, 7] and r["status"] == ["completed", "error"]
    assert r["errors"][0] is None and r["errors"][1].startswith("StepTooLargeError")
    assert np.isfinite(r["metrics"][0, :15]).all() and np.isnan(r["metrics"][1]).all()
    assert np.isfinite(r["series"][0]).all() and np.isnan(r["series"][1]).all()


# ---------------------------------------------------------------- robustness, plots, helpers
def test_robustness_region(base: popup.Scenario) -> None:
    reg = robustness(base, payload_kg=[0.0, 2.5], pressure_pa=[10e3, 90e3], margin=0.2, duration=0.2)
    assert reg.feasible.shape == reg.ratio.shape == (2, 2) and reg.limit == pytest.approx(0.8)
    t = reg.table
    assert t["feasible"].tolist() == ((t["status"] == "completed") & (t["faults"] == 0) & (t["peak_moment_ratio"] <= 0.8)).tolist()
    assert np.array_equal(reg.ratio.ravel(), t["peak_moment_ratio"].to_numpy())
    assert np.array_equal(reg.feasible.ravel(), t["feasible"].to_numpy())
    # heavier payload and softer links load the links more
    assert reg.ratio[1, 0] > reg.ratio[0, 1]
    mp = reg.max_payload()
    assert set(mp) == {10e3, 90e3}
    for j, p in enumerate(reg.pressure_pa):
        ok = reg.feasible[:, j]
        assert (mp[float(p)] == 2.5) == bool(ok.all())
    assert "margin 0.2" in reg.summary()
    fig = reg.plot()
    assert fig.axes


def test_plots(base: popup.Scenario) -> None:
    import matplotlib.pyplot as plt

    g = sweep(base, grid={"payload_kg": [0.0, 1.0, 2.0], "pressure_pa": [20e3, 50e3]}, duration=0.05)
    for fig in (g.plot(), g.plot("rms_track_rad", "payload_kg"), g.plot("peak_tau2", kind="line", x="pressure_pa"), g.plot(kind="hist")):
        assert fig.axes
        plt.close(fig)
    ax = g.plot().axes[0]
    assert ax.get_xlabel() == "payload_kg" and ax.get_ylabel() == "pressure_pa"
    mc = sweep(base, distributions={"payload_kg": ("uniform", 0, 2)}, n=4, seed=1, duration=0.05)
    fig = mc.plot("peak_m1_ratio")
    assert "seed 1" in fig.axes[0].get_title()
    assert mc.plot("peak_m1_ratio", "payload_kg").axes
    with pytest.raises(UnknownParameterError, match="unknown metric"):
        mc.plot("nope")
    with pytest.raises(UnknownParameterError, match="not a swept parameter"):
        mc.plot("peak_m1_ratio", "q0[1]")
    df = g.to_pandas()
    assert df.attrs["params"] == ["payload_kg", "pressure_pa"] and df.attrs["units"]["settling_s"] == "s"
    plt.close("all")


def test_scenario_from_task_matches_rollout_task(tmp_path: Path) -> None:
    model = popup.Model("popup-lab", dt=1e-4, payload_kg=1.5, pressure_pa=(35e3, 45e3)).with_effect("joint_friction", tau_c=[0.3, 0.2, 0.1])
    task = Task([Phase("moving", track=[0.0, step(0.6, 0.7, 0.05), -0.4])], Controller(damping=True), faults={"wrinkle": "continue"})
    sc = scenario_from_task(task, duration=0.3, model=model, q0=(0.0, 0.6, -0.4), sample_rate=500.0)
    res = sweep(sc, points={"payload_kg": [0.5, 2.0]}, series=True)
    ref = model.rollout_task(task, duration=0.3, q0=(0.0, 0.6, -0.4), payload_kg=[0.5, 2.0], sample_rate=500.0, threads=1)
    for i in range(2):
        want = np.concatenate([ref.data[i], ref.control[i][:, [CONTROL_CHANNELS.index(c) for c in res.series.channels[len(popup.CHANNELS):]]]], axis=1)
        assert np.array_equal(res.series.values[i], want, equal_nan=True)
    # a custom arm goes through a file
    arm = popup.Arm.builtin("popup-lab").with_overrides({"links": [{"radius_m": 0.09}, {}]})
    m2 = popup.Model(arm, dt=1e-4)
    with pytest.raises(SweepError, match="arm_file"):
        scenario_from_task(task, duration=0.1, model=m2)
    sc2 = scenario_from_task(task, duration=0.1, model=m2, arm_file=tmp_path / "arm.toml", q0=(0.0, 0.6, -0.4))
    r2 = sweep(sc2, points={"payload_kg": [1.0]}, series=["d11"])
    assert np.array_equal(r2.series.channel("d11")[0], m2.run_task(task, duration=0.1, q0=(0.0, 0.6, -0.4), payload_kg=1.0).channel("d11"))


def test_progress_callback_and_stderr(base: popup.Scenario, capsys: pytest.CaptureFixture[str]) -> None:
    calls: List[Any] = []
    sweep(base, grid={"payload_kg": [0.0, 0.5, 1.0, 1.5, 2.0]}, batch_size=2, duration=0.05, progress=lambda d, t: calls.append((d, t)))
    assert calls == [(2, 5), (4, 5), (5, 5)]
    sweep(base, grid={"payload_kg": [0.0, 1.0]}, batch_size=1, duration=0.05, progress=True)
    err = capsys.readouterr().err
    assert "2/2 runs" in err


def test_run_chunk_rejects_unknown_kind() -> None:
    with pytest.raises(SweepError, match="unknown chunk kind"):
        run_chunk({"kind": "nope", "metrics": {}, "threads": 1}, {"runs": []})


def test_metric_definitions_on_a_known_trajectory() -> None:
    """settling_s and the peak metrics on hand-made arrays (the worker's metric code alone)."""
    from popup.sweep import _run_metrics

    s = 1001
    t = np.linspace(0.0, 4.0, s)
    data = np.zeros((s, len(popup.CHANNELS)))
    ctrl = np.zeros((s, len(CONTROL_CHANNELS)))
    ci = {c: i for i, c in enumerate(popup.CHANNELS)}
    data[:, ci["t"]] = t
    # the tip moves 0.5 m in x at t = 1 s and rings down as exp(-t) (0.02 amplitude)
    x = np.where(t < 1.0, 0.0, 0.5 + 0.02 * np.exp(-3 * (t - 1.0)) * np.cos(20 * (t - 1.0)))
    data[:, ci["ee_x"]] = x
    data[:, ci["m1_ratio"]] = np.linspace(0, 0.7, s)
    data[:, ci["m2_ratio"]] = 0.9
    data[:, ci["tau2"]] = -np.linspace(0, 3, s)
    data[:, ci["q1"]] = 0.01
    m = _run_metrics(data, ctrl, [(0.0, "fault", "", "", "")], 2, MetricOptions(settle_from_s=1.0, settle_tol_abs_m=0.005, settle_tol_rel=0.0))
    v = dict(zip(METRICS, m))
    assert v["peak_m1_ratio"] == pytest.approx(0.7) and v["peak_moment_ratio"] == pytest.approx(0.9)
    assert v["peak_tau2"] == pytest.approx(3.0) and v["faults"] == 1 and v["wrinkle_alarms"] == 2
    assert v["rms_track_q1"] == pytest.approx(0.01) and v["t_end"] == 4.0 and v["samples"] == s
    # |x − 0.5| < 0.005 for good once 0.02 exp(-3 τ) < 0.005 (τ < ln 4 / 3 = 0.462 s), at a zero crossing of cos
    assert 0.3 < v["settling_s"] <= math.log(4) / 3 + 0.01
