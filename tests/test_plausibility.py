"""Issue 19: plausibility checks on measured runs, before anything is simulated. Errors
where the data cannot be right, warnings where it may be; each names the file, row and
column and says what to do. The limits are one registry (``popup_core::limits``)."""

import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import popup
from popup import _core
from popup import io as pio

EXP = 'format = "popup-run/1"\narm = "popup-lab"\npayload_kg = 2.0\npressure_pa = [30000.0, 30000.0]\nreplay = "encoder"\n'


def write(folder: Path, cols: dict) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "experiment.toml").write_text(EXP)
    names = list(cols)
    n = len(cols["t"])
    rows = [",".join(names)] + [",".join(repr(float(cols[c][i])) for c in names) for i in range(n)]
    (folder / "measurements.csv").write_text("\n".join(rows) + "\n")
    return folder


def base(n: int = 200) -> dict:
    t = np.arange(n) * 0.002
    s = 0.5 - 0.5 * np.cos(np.pi * t / t[-1])
    return {"t": t, "q1": 0.2 * s, "q2": 0.6 * s, "q3": -0.3 * s, "tau2": 10.0 + 5 * s}


def test_the_registry_is_the_engines_and_covers_every_channel():
    cols = [c for group in _core.CHANNEL_LIMITS for c in group[0]]
    assert len(cols) == len(set(cols)), "one limit per column"
    assert set(pio.MEASURED_COLUMNS) <= set(cols)
    assert set(pio.LIMITS) == set(cols)
    for c in ("q1", "tau2", "t"):
        unit, lo, warn, err, advice = pio.LIMITS[c]
        assert unit == pio.UNITS[c] and warn <= err and advice


def test_every_measured_channel_has_its_sensor_kind_in_the_core_registry():
    """``popup.results.SENSORS`` (``popup_core::sensor::SENSORS``): one kind per channel;
    every column of the run format is recorded by a sensor, the axes of both IMUs are one
    kind, and what no lab measures is ``model``."""
    from popup.results import CHANNELS, SENSORS

    assert list(SENSORS) == CHANNELS
    measured = [c for c in pio.MEASURED_COLUMNS if c in CHANNELS]
    assert measured and all(SENSORS[c] not in ("model", "") for c in measured), {c: SENSORS[c] for c in measured}
    assert {SENSORS[c] for c in CHANNELS if c.startswith("imu")} == {"imu"}
    assert {SENSORS[c] for c in ("tau1", "tau2", "tau3")} == {"drive"} and SENSORS["ee_x"] == "mocap"
    assert all(SENSORS[c] == "model" for c in CHANNELS if c not in pio.MEASURED_COLUMNS)


@pytest.mark.parametrize("last_t", [1e9, 1e300])
def test_absurd_time_stamp_is_named_before_anything_runs(tmp_path, last_t):
    d = base()
    d["t"][-1] = last_t
    f = write(tmp_path / "run", d)
    with pytest.raises(popup.MeasuredRunError) as e:
        pio.read_run(f)
    msg = str(e.value)
    assert "measurements.csv" in msg and "row 200 (line 201), column t" in msg, msg
    assert len(msg) < 600, msg


@pytest.mark.parametrize("last_t", ["1e9", "1e300"])
def test_diagnose_names_the_glitch_not_missing_physics(tmp_path, last_t):
    d = base()
    d["t"][-1] = float(last_t)
    f = write(tmp_path / "run", d)
    r = subprocess.run([sys.executable, "-m", "popup", "diagnose", str(f), "--no-progress"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    assert "measurements.csv" in r.stderr and "row 200 (line 201), column t" in r.stderr, r.stderr
    assert "missing" not in r.stdout


def test_gap_far_beyond_the_median_step_is_an_error_naming_rows(tmp_path):
    d = base()
    d["t"][150:] += 100.0  # 100 s hole in a 2 ms log
    f = write(tmp_path / "run", d)
    with pytest.raises(popup.MeasuredRunError, match=r"row 151 \(line 152\), column t: .* median step .*split the run"):
        pio.read_run(f)


def test_small_gap_is_a_warning(tmp_path):
    d = base()
    d["t"][150:] += 0.05  # 25 median steps: samples lost, the data may still be right
    f = write(tmp_path / "run", d)
    with pytest.warns(popup.PopupWarning, match=r"column t: 1 gap longer than 10 median steps"):
        run = pio.read_run(f)
    assert any("gap" in w for w in run.warnings)


@pytest.mark.parametrize(
    "col, value, needle",
    [
        ("q2", 1e300, "column q2: 1e+300 rad is not plausible"),
        ("tau2", 1e300, "column tau2: 1e+300 N·m is not plausible"),
        ("q1", float("inf"), "column q1: inf is not finite"),
        ("p1", -5e5, "column p1: -500000.0 Pa is not plausible"),
    ],
)
def test_impossible_values_are_errors_naming_row_and_column(tmp_path, col, value, needle):
    d = base()
    d.setdefault(col, np.full(len(d["t"]), 3e4 if col == "p1" else 0.0))
    d[col] = np.array(d[col], dtype=float)
    d[col][37] = value
    f = write(tmp_path / "run", d)
    with pytest.raises(popup.MeasuredRunError) as e:
        pio.read_run(f)
    msg = str(e.value)
    assert "row 38 (line 39)" in msg and needle in msg, msg


def test_angles_in_degrees(tmp_path):
    # up to 55 "rad": cannot be the arm's; the error says to convert
    d = base()
    for c in ("q1", "q2", "q3"):
        d[c] = np.degrees(d[c]) * 1.6
    with pytest.raises(popup.MeasuredRunError, match=r"column q2: .*look like degrees \(convert with × π/180\)"):
        pio.read_run(write(tmp_path / "a", d))
    # up to ~17 deg: may be right; a warning
    d = base()
    for c in ("q1", "q2", "q3"):
        d[c] = np.degrees(d[c]) * 0.5
    with pytest.warns(popup.PopupWarning) as rec:
        pio.read_run(write(tmp_path / "b", d))
    texts = [str(w.message) for w in rec]
    assert any("column q2:" in m and "values beyond 6.283 rad" in m and "degrees" in m for m in texts), texts


def test_plain_run_has_no_plausibility_warning(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        run = pio.read_run(write(tmp_path / "run", base()))
    assert run.warnings == []


def test_data_changed_after_reading_is_checked_before_diagnosis(tmp_path):
    run = pio.read_run(write(tmp_path / "run", base()))
    run.data.loc[20, "q2"] = 1e300
    with pytest.raises(popup.MeasuredRunError, match=r"row 21 \(line 22\), column q2"):
        run.check()
    with pytest.raises(popup.MeasuredRunError, match=r"column q2"):
        popup.ReplayProblem(run.model(), run)
