"""MCAP logs written by the Rust core and the headless CLI (issue 5): round trip,
schema/CRC validity, nothing lost on SIGKILL, clean finish on SIGINT/SIGTERM, scenario
checks, sweeps."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import List, Tuple

import numpy as np
import pytest

import popup
from popup.control import CONTROL_CHANNELS
from popup.results import CHANNELS

sys.path.insert(0, str(Path(__file__).resolve().parent))
import mcap_check  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PICK = ROOT / "examples" / "scenarios" / "pick_and_place.toml"

HOLD = """
format = "popup-scenario/1"
description = "hold test"
arm = "popup-lab"
payload_kg = 1.0
q0 = [0.0, 0.6, -0.4]
duration_s = {duration}
dt = 5e-4
sample_rate_hz = 100.0
seed = 3
[noise]
imu_m_s2 = 0.05
torque_nm = 0.1
[log]
viz_rate_hz = 10.0
flush_every_s = {flush}
[controller]
rate_hz = 2000.0
"""


def hold_file(tmp_path: Path, duration: float = 2.0, flush: float = 0.5) -> Path:
    p = tmp_path / "hold.toml"
    p.write_text(HOLD.format(duration=duration, flush=flush))
    return p


def popup_cmd(*args: str) -> List[str]:
    return [sys.executable, "-m", "popup", *args]


def assert_same_run(res: popup.ControlResult, log: popup.RunLog, n: int) -> None:
    """The first n samples of ``res`` equal the log's, bit for bit (every channel)."""
    t = log.table
    assert len(t) >= n
    for i, c in enumerate(CHANNELS):
        a = t[c].to_numpy()[:n]
        assert np.array_equal(a, res.data[:n, i]), c
    for i, c in enumerate(CONTROL_CHANNELS):
        if c == "d_min":  # +inf (no obstacle) is left out of the messages
            assert c not in t.columns
            assert np.all(np.isinf(res.control[:n, i]))
            continue
        assert np.array_equal(t[c].to_numpy()[:n], res.control[:n, i]), c


def test_round_trip_arrays_events_and_metadata(tmp_path: Path) -> None:
    sc = popup.Scenario.read(PICK)
    out = tmp_path / "pick.mcap"
    res = sc.run(out=out, duration=4.0)
    assert res.status == "completed"
    log = popup.read_log(out)
    assert log.complete and len(log.table) == len(res.data) == 2001
    assert_same_run(res, log, len(res.data))
    ev = log.events
    assert list(ev["kind"]) == [e.kind for e in res.events]
    assert np.array_equal(ev["t"].to_numpy(), np.array([e.t for e in res.events]))
    assert list(ev["to"]) == [e.to_phase for e in res.events]
    assert log.run_end is not None and log.run_end["status"] == "completed"
    assert int(log.run_end["samples"]) == len(res.data)
    assert log.scenario == sc.to_toml()
    assert log.metadata["popup"]["seed"] == str(sc.seed)
    # the measured-run view of the same file: replay = "reference" with the controller
    run = popup.read_run(out)
    assert run.replay == "reference" and run.payload_kg == 0.0 and run.pressure_pa == (50000.0, 50000.0)
    assert np.array_equal(run.channel("ref_q2"), res.ref_q[:, 1])
    assert np.array_equal(run.channel("imu2_az"), res.channel("imu2_az"))


def test_noise_is_seeded_and_logged(tmp_path: Path) -> None:
    sc = popup.Scenario.read(hold_file(tmp_path))
    a = sc.run(duration=0.5)
    b = sc.run(duration=0.5)
    c = sc.run(duration=0.5, seed=4)
    assert np.array_equal(a.data, b.data)
    assert not np.array_equal(a.channel("imu2_az"), c.channel("imu2_az"))
    assert np.array_equal(a.channel("q2"), c.channel("q2"))  # encoder noise is 0 in this file
    assert a.params["seed"] == 3 and c.params["seed"] == 4


def test_cli_file_passes_crc_and_foxglove_schemas(tmp_path: Path) -> None:
    out = tmp_path / "h.mcap"
    r = subprocess.run(popup_cmd("run", str(hold_file(tmp_path, 1.0)), "--out", str(out)), capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    counts = mcap_check.validate_file(out)
    # /tf at 10 Hz of 100 Hz samples over 1 s: samples 0, 10, ..., 100
    assert counts["/tf"] == 11 and counts["/scene"] == 11
    assert counts["/popup/joints"] == 101
    tf = popup.read_log(out).messages("/tf")[0]
    names = [x["child_frame_id"] for x in tf["transforms"]]
    assert names[0] == "base" and names[-1] == "ee" and "q2" in names and "d22" in names
    scene = popup.read_log(out).messages("/scene")[0]
    assert [e["id"] for e in scene["entities"]] == ["link1", "link2", "payload"]
    assert all(len(e["cylinders"]) > 0 for e in scene["entities"][:2])


def test_non_finite_values_are_reported_not_nulled(tmp_path: Path) -> None:
    # a run that goes unstable: a huge velocity gain and no torque limit
    extra = "[controller.gains]\nvel_kp = 5e7\n[controller.motor]\ntau_max = 1e12"
    text = hold_file(tmp_path, 3.0).read_text().replace("[controller]\nrate_hz = 2000.0", "[controller]\nrate_hz = 2000.0\n" + extra)
    sc = popup.Scenario.from_toml(text, "unstable.toml")
    out = tmp_path / "u.mcap"
    res = sc.run(out=out)
    assert res.status == "unstable"
    log = popup.read_log(out)
    assert log.run_end["status"] == "unstable"
    raw = (out.read_bytes())
    assert b"null" not in raw and b"NaN" not in raw
    assert any(e["level"] == 4 for e in log.log)  # the Unstable fault is an ERROR
    mcap_check.validate_file(out)


def read_flush_lines(proc: subprocess.Popen, n: int, timeout: float = 120.0) -> List[float]:
    """Times of the first n 'log flushed' progress lines of a running `popup run`."""
    ts: List[float] = []
    assert proc.stderr is not None
    for line in proc.stderr:
        if "log flushed" in line:
            ts.append(float(line.split("t = ")[1].split(" s")[0]))
            if len(ts) >= n:
                break
    assert len(ts) >= n, "the run ended before it flushed"
    return ts


def start_run(tmp_path: Path, out: Path, flush: float = 0.5) -> subprocess.Popen:
    sc = hold_file(tmp_path, duration=600.0, flush=flush)
    return subprocess.Popen(popup_cmd("run", str(sc), "--out", str(out), "--progress", "lines"), stderr=subprocess.PIPE, text=True)


def test_sigkill_loses_at_most_the_last_flush_interval(tmp_path: Path) -> None:
    out = tmp_path / "killed.mcap"
    flush = 0.5
    proc = start_run(tmp_path, out, flush)
    flushed = read_flush_lines(proc, 3)
    proc.kill()
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    log = popup.read_log(out)
    assert not log.complete and log.run_end is None
    assert "did not finish" in log.lost or "no run_end" in log.lost, log.lost
    t_read = float(log.table["t"].iloc[-1])
    # everything announced as flushed is there (the sensor rows lag their state by <= 1 sample)
    assert t_read >= flushed[-1] - 1e-9, (t_read, flushed)
    # and it is the start of the same run, bit for bit
    sc = popup.Scenario.read(tmp_path / "hold.toml")
    res = sc.run(duration=t_read)
    assert_same_run(res, log, len(log.table))
    # what was read ends at a flush: only the unflushed tail (< one interval) is lost
    k = round(t_read / flush)
    assert abs(t_read - (k * flush - 0.01)) < 1e-9 or abs(t_read - k * flush) < 1e-9, t_read


@pytest.mark.parametrize("sig,code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_signal_finishes_the_file(tmp_path: Path, sig: int, code: int) -> None:
    out = tmp_path / "stopped.mcap"
    proc = start_run(tmp_path, out)
    read_flush_lines(proc, 2)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == code, err
    assert "interrupted" in err
    counts = mcap_check.validate_file(out)  # summary and footer written: seeking reader works
    log = popup.read_log(out)
    assert log.complete and log.run_end["status"] == "interrupted"
    assert log.events["kind"].iloc[-1] == "interrupted"
    assert counts["/popup/joints"] == int(log.run_end["samples"])


def test_check_lists_every_problem_with_line_and_key(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(
        "\n".join(
            [
                'format = "popup-scenario/1"',
                "payload_kg = -1.0",
                "duration_s = 5.0",
                "colour = 3",
                "[controller]",
                "rate_hz = 2000.0",
                "[controller.gains]",
                "vel_kp = -5.0",
                "[[phases]]",
                'kind = "flying"',
                "[log]",
                'topics = ["joints", "radar"]',
            ]
        )
        + "\n"
    )
    r = subprocess.run(popup_cmd("check", str(bad)), capture_output=True, text=True)
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("popup: error:")]
    where = {(ln.split(":")[2].strip(), ln.split(":")[3].strip()) for ln in lines}
    src = str(bad)
    for line, key in [(2, "payload_kg"), (4, "colour"), (8, "controller.gains.vel_kp"), (10, "phases[0].kind"), (12, "log.topics")]:
        assert any(f"{src}:{line}: {key}" in ln for ln in lines), (line, key, r.stderr)
    assert len(where) >= 5
    with pytest.raises(popup.ScenarioError) as ei:
        popup.Scenario.read(bad)
    assert len(ei.value.problems) == len(lines)
    assert isinstance(ei.value, ValueError)
    ok = subprocess.run(popup_cmd("check", str(PICK)), capture_output=True, text=True)
    assert ok.returncode == 0 and "ok" in ok.stdout


def test_malformed_scenarios_are_refused_precisely(tmp_path: Path) -> None:
    cases: List[Tuple[str, str]] = [
        ('format = "popup-scenario/1"\nduration_s = 1.0\npayload_kg = [1\n', ":3:"),  # syntax
        ('format = "popup-scenario/2"\nduration_s = 1.0\n', "format"),
        ('format = "popup-scenario/1"\n', "duration_s"),
        ('format = "popup-scenario/1"\nduration_s = 1.0\narm = "no-such-arm"\n', "arm"),
        ('format = "popup-scenario/1"\nduration_s = 1.0\ndt = 3e-4\n[controller]\nrate_hz = 2000.0\n', "dt"),
    ]
    for text, needle in cases:
        with pytest.raises(popup.ScenarioError) as ei:
            popup.Scenario.from_toml(text, "m.toml")
        assert needle in str(ei.value), (text, str(ei.value))
    r = subprocess.run(popup_cmd("run", str(tmp_path / "missing.toml"), "--out", str(tmp_path / "x.mcap")), capture_output=True, text=True)
    assert r.returncode == 2 and "missing.toml" in r.stderr
    assert not (tmp_path / "x.mcap").exists()


def test_sweep_grid_matches_single_runs_and_thread_counts(tmp_path: Path) -> None:
    sc_path = hold_file(tmp_path, duration=0.5)
    rows = {}
    for threads in ("1", "2"):
        d = tmp_path / f"sweep{threads}"
        r = subprocess.run(
            popup_cmd("sweep", str(sc_path), "--param", "payload_kg=0:1:0.5", "--param", "pressure_pa=30000,40000", "--out", str(d), "--threads", threads, "--mcap"),
            capture_output=True,
            text=True,
        )
        assert r.returncode == 0, r.stderr
        with open(d / "summary.csv") as f:
            rows[threads] = list(csv.DictReader(f))
        assert len(rows[threads]) == 6 and len(list(d.glob("run_*.mcap"))) == 6
    assert rows["1"] == rows["2"]
    import pandas as pd

    d = tmp_path / "sweep_pq"
    r = subprocess.run(popup_cmd("sweep", str(sc_path), "--param", "payload_kg=0,0.5", "--out", str(d), "--parquet"), capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    pq = pd.read_parquet(d / "summary.parquet")
    assert list(pq["payload_kg"]) == [0.0, 0.5] and pq.equals(pd.read_csv(d / "summary.csv"))
    row = rows["1"][3]  # payload 0.5 (second value), pressure 40000 (second value)
    assert float(row["payload_kg"]) == 0.5 and float(row["pressure_pa"]) == 40000.0 and row["status"] == "completed"
    single = popup.Scenario.read(sc_path).set("payload_kg", 0.5).set("pressure_pa", 40000.0).run()
    assert float(row["peak_m2_ratio"]) == float(np.max(single.channel("m2_ratio")))
    assert float(row["ee_z"]) == float(single.channel("ee_z")[-1])
    log = popup.read_log(tmp_path / "sweep1" / "run_0003.mcap")
    assert np.array_equal(log.table["imu2_az"].to_numpy(), single.channel("imu2_az"))


def test_documented_scenario_example_is_valid() -> None:
    text = (ROOT / "docs" / "logging.md").read_text()
    block = text.split("## Scenario files", 1)[1].split("```toml\n", 1)[1].split("```", 1)[0]
    sc = popup.Scenario.from_toml(block, "docs/logging.md")
    assert sc.duration_s == 10.0 and sc.phase_names() == ["Holding"]
    assert sc.set("payload_kg", 2.0).to_dict()["payload_kg"] == 2.0


def test_open_loop_replay_and_torque_runs_are_logged(tmp_path: Path) -> None:
    model = popup.Model("popup-lab", payload_kg=1.0)
    t = np.arange(0.0, 2.0, 0.002)
    q = np.stack([0 * t, 0.6 * np.minimum(t, 1.0), -0.3 * np.minimum(t, 1.0)], axis=1)
    out = tmp_path / "replay.mcap"
    res = model.replay(t, q, sample_rate=100, log=out)
    plain = model.replay(t, q, sample_rate=100)
    assert np.array_equal(res.data, plain.data)  # logging does not change the run
    log = popup.read_log(out)
    assert log.complete and log.run_end["status"] == "completed"
    for i, c in enumerate(CHANNELS):
        assert np.array_equal(log.table[c].to_numpy(), res.data[:, i]), c
    assert log.topics.get("/popup/control", 0) == 0 and log.topics["/tf"] > 0  # no controller in open loop
    mcap_check.validate_file(out)
    run = popup.read_run(out)  # an encoder replay of the logged run reproduces it
    assert run.replay == "encoder" and run.payload_kg == 1.0
    again = run.model().replay(*run.encoder(), sample_rate=100)
    assert np.allclose(again.channel("imu2_az"), res.channel("imu2_az"), atol=1e-6)
    tq = tmp_path / "torque.mcap"
    r2 = model.simulate(model.holding_torque((0.0, 0.6, -0.3)), duration=0.5, initial_q=model.rest_state((0.0, 0.6, -0.3)), log=tq)
    assert np.array_equal(popup.read_log(tq).table["q2"].to_numpy(), r2.channel("q2"))
    with pytest.raises(popup.InputError, match="one run"):
        model.rollout(payload_kg=[0.0, 1.0], encoder_t=t, encoder_q=q, log=tmp_path / "b.mcap")


def test_second_run_in_one_python_process_still_finishes_on_ctrl_c(tmp_path: Path) -> None:
    """The handlers are installed once per process and re-armed per run: a second CLI run
    in the same Python process (a notebook, a script calling popup.cli.main twice) still
    finishes its file on SIGINT, and exits 130."""
    sc = hold_file(tmp_path, duration=600.0, flush=0.5)
    first, second = tmp_path / "a.mcap", tmp_path / "b.mcap"
    script = (
        "import sys, popup.cli as c\n"
        f"c.main(['run', {str(sc)!r}, '--out', {str(first)!r}, '--duration', '0.5'])\n"
        f"sys.exit(c.main(['run', {str(sc)!r}, '--out', {str(second)!r}, '--progress', 'lines']))\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", script], stderr=subprocess.PIPE, text=True)
    read_flush_lines(proc, 3)  # the first run prints none (no --progress lines)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert popup.read_log(first).run_end["status"] == "completed"
    log = popup.read_log(second)
    assert log.complete and log.run_end["status"] == "interrupted"


def test_zero_pressure_keeps_the_finite_bending_channels(tmp_path: Path) -> None:
    # issue 19: only m*_ratio (|M|/M_w with M_w = 0) is infinite; the bending angles and
    # moments of the same samples must survive, the count is reported, check warns first
    sc = hold_file(tmp_path, 0.3)
    sc.write_text(sc.read_text().replace("payload_kg = 1.0", "payload_kg = 1.0\npressure_pa = [0.0, 0.0]"))
    chk = subprocess.run(popup_cmd("check", str(sc)), capture_output=True, text=True, timeout=120)
    assert chk.returncode == 0, chk.stderr
    assert "warning" in chk.stderr and "pressure_pa[0] (link 1) = 0 Pa" in chk.stderr and "m1_ratio" in chk.stderr, chk.stderr
    out = tmp_path / "p0.mcap"
    r = subprocess.run(popup_cmd("run", str(sc), "--out", str(out), "--progress", "none"), capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "non-finite values left out of the log (their samples kept)" in r.stderr, r.stderr
    log = popup.read_log(out)
    bending = log.messages("/popup/bending")
    assert len(bending) == int(log.run_end["samples"]) > 0, "no sample of /popup/bending is dropped"
    keys = set(bending[0])
    assert "m1_ratio" not in keys and "m2_ratio" not in keys
    assert {"d11", "d12", "d21", "d22", "m11", "m12", "m21", "m22", "energy"} <= keys, keys
    assert int(log.run_end["nonfinite_dropped"]) == 2 * len(bending)
    assert np.isfinite(log.table["d11"].to_numpy()).all()
    assert "m1_ratio" not in log.table.columns or np.isnan(log.table["m1_ratio"].to_numpy()).all()
    mcap_check.validate_file(out)
