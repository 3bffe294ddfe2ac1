"""Measured runs (measured-run.md): write_run -> read_run round trips, every malformed
input refused with a MeasuredRunError naming file, row/column and what was expected,
unknown columns warned about, simulated runs written and read back as measured runs."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any, Dict, Optional

import numpy as np
import pandas as pd
import pytest

import popup
import popup.io as pio

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    tomllib = pytest.importorskip("tomli")

GOOD_TOML = """\
format = "popup-run/1"
arm = "popup-lab"
payload_kg = 2.0
pressure_pa = [30000.0, 30000.0]
gravity = true
replay = "encoder"
"""

GOOD_CSV = """\
t,q1,q2,q3,ee_z
0.000,0.0,0.0,0.0,-0.05
0.002,0.001,0.002,-0.001,-0.051
0.004,0.002,0.004,-0.002,-0.052
"""


def make_run(folder: Path, toml: Optional[str] = GOOD_TOML, csv: Optional[str] = GOOD_CSV, *, data_name: str = "measurements.csv") -> Path:
    """A run folder from raw file texts (None: leave the file out)."""
    folder.mkdir(parents=True, exist_ok=True)
    if toml is not None:
        (folder / "experiment.toml").write_text(toml, encoding="utf-8")
    if csv is not None:
        (folder / data_name).write_text(csv, encoding="utf-8")
    return folder


def experiment(**kw: Any) -> Dict[str, Any]:
    exp: Dict[str, Any] = {
        "format": "popup-run/1",
        "arm": "popup-lab",
        "payload_kg": 2.0,
        "pressure_pa": [30000.0, 30000.0],
        "gravity": True,
        "replay": "encoder",
    }
    exp.update(kw)
    return exp


def refused(path: Path, *needles: str) -> str:
    """read_run refuses ``path``; the message holds every needle. Returns it."""
    with pytest.raises(popup.MeasuredRunError) as e:
        pio.read_run(path)
    msg = str(e.value)
    assert isinstance(e.value, ValueError) and isinstance(e.value, popup.PopupError)
    for n in needles:
        assert n in msg, f"{n!r} not in {msg!r}"
    return msg


# ------------------------------------------------------------------------------ round trips


def test_roundtrip_nothing_changed(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    n = 50
    t = np.cumsum(rng.uniform(1e-4, 3e-3, n))  # variable rate
    data = {
        "t": t,
        "q1": rng.standard_normal(n),
        "q2": rng.standard_normal(n) * 1e-9,
        "q3": rng.uniform(-3.0, 3.0, n),  # plausible angles (issue 19: the reader refuses 1e6 rad)
        "tau2": rng.standard_normal(n),
        "imu2_az": rng.standard_normal(n),
        "p1": np.full(n, 30000.0),
        "p2": 3e4 + rng.standard_normal(n) * 1e3,  # large magnitudes round-trip bit-exactly too
    }
    data["tau2"][[3, 4, 10]] = np.nan  # missing samples
    exp = experiment(
        payload_kg=1.25,
        pressure_pa=(25000.0, 31000.5),
        description='bench "A", 2nd try\nλ = 0.5',
        initial={"bending_rad": [0.01, -0.02, 0.0, 0.03], "rate_radps": [0.0, 0.0, 0.0, 0.0]},
    )
    folder = pio.write_run(tmp_path / "run", exp, data)
    run = pio.read_run(folder)

    assert run.columns == list(data)  # file order kept
    assert len(run) == n and run.warnings == []
    for c, v in data.items():
        np.testing.assert_array_equal(run.data[c].to_numpy(), v)  # bit-exact, NaN where missing
        np.testing.assert_array_equal(run.channel(c), v)
    assert run.data["tau2"].isna().sum() == 3
    np.testing.assert_array_equal(run.time, t)
    # experiment dict as parsed, typed fields
    assert run.experiment == {**exp, "pressure_pa": [25000.0, 31000.5]}
    assert (run.format, run.arm, run.payload_kg, run.pressure_pa) == ("popup-run/1", "popup-lab", 1.25, (25000.0, 31000.5))
    assert run.gravity is True and run.replay == "encoder" and run.controller is None
    assert run.description == 'bench "A", 2nd try\nλ = 0.5'
    assert run.initial == exp["initial"]
    assert run.source == folder and run.data_file == folder / "measurements.csv"
    # to_pandas: indexed by t, experiment attached
    df = run.to_pandas()
    np.testing.assert_array_equal(df.index.to_numpy(), t)
    assert df.attrs["experiment"]["payload_kg"] == 1.25 and "t" not in df.columns
    # encoder samples = the q columns
    te, qe = run.encoder()
    np.testing.assert_array_equal(te, t)
    np.testing.assert_array_equal(qe, np.stack([data["q1"], data["q2"], data["q3"]], axis=1))
    # reading the folder through one of its files gives the same run
    assert pio.read_run(folder / "experiment.toml").columns == run.columns


def test_written_toml_parses_back(tmp_path: Path) -> None:
    exp = experiment(
        replay="reference",
        description="tab\there, quote \" backslash \\ unicode ü, del \x7f",
        controller={"kind": "pid", "kp": [100.0, 80.0, 40.0], "kd": [5, 4, 2], "limits": {"tau_max": 60.0, "inf_ok": float("inf")}},
        initial={"bending_rad": np.array([0.0, 0.01, 0.0, -0.01]), "note key": np.float64(1.5)},
    )
    data = {"t": [0.0, 0.1, 0.2], "ref_q1": [0.0, 0.1, 0.2], "ref_q2": [0.0, 0.0, 0.0], "ref_q3": [0.0, -0.1, -0.2]}
    folder = pio.write_run(tmp_path / "run", exp, data)
    parsed = tomllib.loads((folder / "experiment.toml").read_text(encoding="utf-8"))
    expected = dict(exp)
    expected["initial"] = {"bending_rad": [0.0, 0.01, 0.0, -0.01], "note key": 1.5}
    assert parsed == expected
    run = pio.read_run(folder)
    assert run.replay == "reference" and run.controller == exp["controller"]
    t, ref = run.reference()
    np.testing.assert_array_equal(ref[:, 2], [0.0, -0.1, -0.2])


def test_handwritten_csv_read_as_is(tmp_path: Path) -> None:
    # spaces after commas, a blank line, integer cells, empty and nan cells, a BOM
    csv = "\ufefft, q1, q2, q3, p1\n0, 0, 0, 0, 30000\n\n0.5, 0.1, nan, 0.2,\n1, 0.2, 0.3, 0.4, NaN\n"
    folder = make_run(tmp_path / "run", csv=csv)
    with pytest.warns(popup.PopupWarning, match=r"1 of 3 rows have a missing q1/q2/q3 .*rows 2 \(line 4\)") as rec:
        run = pio.read_run(folder)
    assert len(rec) == 1 and run.warnings == [str(rec[0].message)]
    assert run.columns == ["t", "q1", "q2", "q3", "p1"]
    assert all(run.data[c].dtype == np.float64 for c in run.columns)
    np.testing.assert_array_equal(run.time, [0.0, 0.5, 1.0])
    np.testing.assert_array_equal(run.channel("q2"), [0.0, np.nan, 0.3])
    np.testing.assert_array_equal(run.channel("p1"), [30000.0, np.nan, np.nan])
    # encoder() skips the incomplete row and does not warn a second time (warnings are errors here)
    t, q = run.encoder()
    np.testing.assert_array_equal(t, [0.0, 1.0])
    np.testing.assert_array_equal(q, [[0.0, 0.0, 0.0], [0.2, 0.3, 0.4]])
    assert len(run.warnings) == 1
    # the data frame itself still has every row
    assert len(run.data) == 3


def test_crlf_line_endings_and_line_numbers(tmp_path: Path) -> None:
    folder = make_run(tmp_path / "run", csv=None)
    (folder / "measurements.csv").write_bytes(b"t,q1,q2,q3\r\n0,0,0,0\r\n\r\n1,0,0,0\r\n0.5,0,0,0\r\n")
    refused(folder, "row 3 (line 5) has t = 0.5 s", "row 2 (line 4) (t = 1.0 s)")


def test_write_run_takes_frame_indexed_by_t(tmp_path: Path) -> None:
    df = pd.DataFrame({"q1": [0.0, 0.1], "q2": [0.0, 0.2], "q3": [0.0, 0.3]}, index=pd.Index([0.0, 0.01], name="t"))
    run = pio.read_run(pio.write_run(tmp_path / "run", experiment(), df))
    assert run.columns == ["t", "q1", "q2", "q3"]
    np.testing.assert_array_equal(run.time, [0.0, 0.01])


def test_channel_missing_is_keyerror(tmp_path: Path) -> None:
    run = pio.read_run(make_run(tmp_path / "run"))
    with pytest.raises(KeyError, match=r"no column 'tau1'.*'ee_z'"):
        run.channel("tau1")


# ------------------------------------------------------------------------------ malformed runs

BAD_TOML = {
    "format_missing": (GOOD_TOML.replace('format = "popup-run/1"\n', ""), ["experiment.toml", "missing key format", "popup-run/1"]),
    "format_unknown": (GOOD_TOML.replace("popup-run/1", "popup-run/2"), ["experiment.toml", "'popup-run/2' is not supported", 'format = "popup-run/1"']),
    "arm_missing": (GOOD_TOML.replace('arm = "popup-lab"\n', ""), ["experiment.toml", "missing key arm"]),
    "payload_missing": (GOOD_TOML.replace("payload_kg = 2.0\n", ""), ["missing key payload_kg"]),
    "arm_unknown": (GOOD_TOML.replace('"popup-lab"', '"popup-lbb"'), ["experiment.toml", "unknown arm 'popup-lbb'", "built-ins: popup-lab", "no arm file"]),
    "arm_file_missing": (GOOD_TOML.replace('"popup-lab"', '"arms/mine.toml"'), ["unknown arm 'arms/mine.toml'", "mine.toml"]),
    "arm_not_string": (GOOD_TOML.replace('"popup-lab"', "3"), ["arm = 3", "built-in arm name"]),
    "payload_negative": (GOOD_TOML.replace("payload_kg = 2.0", "payload_kg = -1.0"), ["payload_kg = -1.0", ">= 0 [kg]"]),
    "payload_nan": (GOOD_TOML.replace("payload_kg = 2.0", "payload_kg = nan"), ["payload_kg = nan", "finite"]),
    "payload_string": (GOOD_TOML.replace("payload_kg = 2.0", 'payload_kg = "2 kg"'), ["payload_kg = '2 kg'", "number"]),
    "pressure_negative": (GOOD_TOML.replace("[30000.0, 30000.0]", "[30000.0, -5.0]"), ["pressure_pa[1] (link 2) = -5.0", ">= 0 [Pa]"]),
    "pressure_nan": (GOOD_TOML.replace("[30000.0, 30000.0]", "[nan, 30000.0]"), ["pressure_pa[0] (link 1) = nan", "finite"]),
    "pressure_scalar": (GOOD_TOML.replace("[30000.0, 30000.0]", "30000.0"), ["pressure_pa = 30000.0", "list of 2 numbers"]),
    "pressure_three": (GOOD_TOML.replace("[30000.0, 30000.0]", "[1.0, 2.0, 3.0]"), ["pressure_pa = [1.0, 2.0, 3.0]", "list of 2 numbers"]),
    "pressure_string": (GOOD_TOML.replace("[30000.0, 30000.0]", '[30000.0, "high"]'), ["pressure_pa[1] (link 2) = 'high'", "number"]),
    "gravity_not_bool": (GOOD_TOML.replace("gravity = true", 'gravity = "yes"'), ["gravity = 'yes'", "true or false"]),
    "gravity_int": (GOOD_TOML.replace("gravity = true", "gravity = 1"), ["gravity = 1", "true or false"]),
    "replay_unknown": (GOOD_TOML.replace('"encoder"', '"closed-loop"'), ["replay = 'closed-loop'", "'encoder', 'reference'"]),
    "reference_no_controller": (GOOD_TOML.replace('"encoder"', '"reference"'), ["replay = \"reference\" needs a [controller] table"]),
    "description_not_string": (GOOD_TOML + "description = 5\n", ["description = 5", "string"]),
    "controller_not_table": (GOOD_TOML + 'controller = "pid"\n', ["controller = 'pid'", "[controller] table"]),
    "malformed_toml": (GOOD_TOML.replace("gravity = true", "gravity = tru e"), ["experiment.toml", "malformed TOML", "line 5", "'gravity = tru e'"]),
    "malformed_table": (GOOD_TOML + "[controller\nkp = 1\n", ["malformed TOML", "line 7", "'[controller'"]),
}


@pytest.mark.parametrize("case", sorted(BAD_TOML))
def test_bad_experiment(tmp_path: Path, case: str) -> None:
    toml, needles = BAD_TOML[case]
    refused(make_run(tmp_path / "run", toml=toml), *needles)


BAD_CSV = {
    "empty_file": ("", ["measurements.csv", "file is empty", "header row"]),
    "whitespace_only": ("\n  \n", ["measurements.csv", "file is empty"]),
    "header_only": ("t,q1,q2,q3\n", ["measurements.csv", "no data rows"]),
    "t_missing": ("q1,q2,q3\n0,0,0\n", ["measurements.csv", "missing column t", "q1, q2, q3"]),
    "t_repeated": (
        "t,q1,q2,q3\n0.0,0,0,0\n0.002,0,0,0\n0.002,0,0,0\n",
        ["measurements.csv", "strictly increasing", "row 3 (line 4) has t = 0.002 s", "not after row 2 (line 3) (t = 0.002 s)"],
    ),
    "t_decreasing": (
        "t,q1,q2,q3\n0.0,0,0,0\n0.2,0,0,0\n\n0.1,0,0,0\n",
        ["strictly increasing", "row 3 (line 5) has t = 0.1 s", "row 2 (line 3) (t = 0.2 s)"],
    ),
    "t_cell_missing": ("t,q1,q2,q3\n0.0,0,0,0\n,0,0,0\n", ["row 2 (line 3), column t: missing", "finite time t"]),
    "t_infinite": ("t,q1,q2,q3\n0.0,0,0,0\ninf,0,0,0\n", ["row 2 (line 3), column t: inf"]),
    "non_numeric": ("t,q1,q2,q3\n0.0,0,0,0\n0.1,0,abc,0\n0.2,0,x,0\n", ["measurements.csv", "row 2 (line 3), column 'q2': 'abc' is not a number", "rad"]),
    "na_is_not_missing": ("t,q1,q2,q3\n0.0,0,0,0\n0.1,0,0,NA\n", ["row 2 (line 3), column 'q3': 'NA' is not a number", "empty cell / nan"]),
    "comma_decimal": ('t,q1,q2,q3\n0.0,0,0,0\n0.1,0,"0,5",0\n', ["row 2 (line 3), column 'q2': '0,5' is not a number"]),
    "bool_column": ("t,q1,q2,q3,p1\n0.0,0,0,0,True\n0.1,0,0,0,False\n", ["row 1 (line 2), column 'p1'", "is not a number", "Pa"]),
    "ragged_short": ("t,q1,q2,q3\n0.0,0,0,0\n0.1,0,0\n", ["measurements.csv", "row 2 (line 3) has 3 fields", "header has 4 columns"]),
    "ragged_long": ("t,q1,q2,q3\n0.0,0,0,0,9\n0.1,0,0,0\n", ["row 1 (line 2) has 5 fields", "header has 4 columns"]),
    "duplicate_column": ("t,q1,q2,q1\n0.0,0,0,0\n", ["line 1 (header)", "'q1' appears twice", "columns 2 and 4"]),
    "empty_column_name": ("t,q1,q2,q3,\n0.0,0,0,0,\n", ["line 1 (header)", "column 5 has an empty name"]),
    "encoder_q_absent": ("t,q1,q2,ee_z\n0.0,0,0,0\n0.1,0,0,0\n", ['replay = "encoder"', "needs columns q1, q2, q3", "missing q3"]),
    "encoder_too_few_rows": ("t,q1,q2,q3\n0.0,0,0,0\n0.1,0,,0\n0.2,,0,0\n", ["needs at least 2 rows with q1, q2, q3 all present", "found 1 of 3", "q1 in 1, q2 in 1"]),
    "encoder_infinite": ("t,q1,q2,q3\n0.0,0,0,0\n0.1,0,-inf,0\n", ["row 2 (line 3), column q2: -inf is not finite"]),
}


@pytest.mark.parametrize("case", sorted(BAD_CSV))
def test_bad_measurements(tmp_path: Path, case: str) -> None:
    csv, needles = BAD_CSV[case]
    refused(make_run(tmp_path / "run", csv=csv), *needles)


def test_reference_needs_ref_columns(tmp_path: Path) -> None:
    toml = GOOD_TOML.replace('"encoder"', '"reference"') + "\n[controller]\nkp = [1.0, 1.0, 1.0]\n"
    refused(make_run(tmp_path / "run", toml=toml), 'replay = "reference"', "needs columns ref_q1, ref_q2, ref_q3", "missing ref_q1, ref_q2, ref_q3")


def test_missing_files(tmp_path: Path) -> None:
    refused(tmp_path / "nowhere", "no such run folder")
    refused(make_run(tmp_path / "a", toml=None), "experiment.toml: missing")
    refused(make_run(tmp_path / "b", csv=None), "missing measurements file", "measurements.csv")
    (tmp_path / "notes.txt").write_text("x")
    refused(tmp_path / "notes.txt", "expected a run folder")
    both = make_run(tmp_path / "c")
    (both / "measurements.parquet").write_bytes(b"PAR1")
    refused(both, "both measurements.csv and measurements.parquet")


def test_mcap_run_needs_experiment_metadata(tmp_path: Path) -> None:
    # MCAP runs are read by popup.read_log (tests/test_mcaplog.py); a bare file has no experiment
    p = tmp_path / "run.mcap"
    p.write_bytes(b"\x89MCAP0\r\n")
    refused(p, "run.mcap", "no experiment metadata record")


def test_parquet_without_pyarrow(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # import pyarrow -> ImportError
    folder = make_run(tmp_path / "run", csv=None)
    (folder / "measurements.parquet").write_bytes(b"PAR1 not really")
    refused(folder, "measurements.parquet", "needs pyarrow", "not installed", "measurements.csv")


def test_parquet_roundtrip_with_pyarrow(tmp_path: Path) -> None:
    pytest.importorskip("pyarrow")
    folder = make_run(tmp_path / "run", csv=None)
    df = pd.DataFrame({"t": [0.0, 0.1, 0.2], "q1": [0.0, 0.1, np.nan], "q2": [0.0] * 3, "q3": [1, 2, 3]})
    df.to_parquet(folder / "measurements.parquet")
    with pytest.warns(popup.PopupWarning, match="missing q1/q2/q3"):
        run = pio.read_run(folder)
    np.testing.assert_array_equal(run.channel("q1"), [0.0, 0.1, np.nan])
    np.testing.assert_array_equal(run.channel("q3"), [1.0, 2.0, 3.0])


# ------------------------------------------------------------------------------ warnings


def test_unknown_columns_warn(tmp_path: Path) -> None:
    csv = "t,q1,q2,q3,ee_zz,q1 \n0.0,0,0,0,1,2\n0.1,0,0,0,3,4\n"
    folder = make_run(tmp_path / "run", csv=csv)
    with pytest.warns(popup.PopupWarning, match=r"measurements.csv: unknown columns 'ee_zz', 'q1 ' \(did you mean 'q1'\?\)") as rec:
        run = pio.read_run(folder)
    assert len(rec) == 1 and run.warnings == [str(rec[0].message)]
    np.testing.assert_array_equal(run.channel("ee_zz"), [1.0, 3.0])  # kept, unchanged


def test_unknown_experiment_key_warns(tmp_path: Path) -> None:
    folder = make_run(tmp_path / "run", toml=GOOD_TOML + 'operator = "kim"\n')
    with pytest.warns(popup.PopupWarning, match=r"experiment.toml: unknown key 'operator'"):
        run = pio.read_run(folder)
    assert run.experiment["operator"] == "kim" and len(run.warnings) == 1


def test_defaults_for_optional_keys(tmp_path: Path) -> None:
    toml = 'format = "popup-run/1"\narm = "popup-lab"\npayload_kg = 0\npressure_pa = [20000, 40000]\n'
    run = pio.read_run(make_run(tmp_path / "run", toml=toml))
    assert run.gravity is True and run.replay == "encoder" and run.description == "" and run.initial is None
    assert run.payload_kg == 0.0 and run.pressure_pa == (20000.0, 40000.0)
    assert "gravity" not in run.experiment  # the dict is as parsed


# ------------------------------------------------------------------------------ write_run


def test_write_run_refuses_bad_input_and_writes_nothing(tmp_path: Path) -> None:
    with pytest.raises(popup.MeasuredRunError, match=r"mismatched array lengths: column 'q1' has 2 samples, column 't' has 3"):
        pio.write_run(tmp_path / "a", experiment(), {"t": [0.0, 1.0, 2.0], "q1": [0.0, 1.0]})
    with pytest.raises(popup.MeasuredRunError, match=r"column 'q' has shape \(3, 3\)"):
        pio.write_run(tmp_path / "a", experiment(), {"t": [0.0, 1.0, 2.0], "q": np.zeros((3, 3))})
    with pytest.raises(popup.MeasuredRunError, match=r"write_run data: column t must be strictly increasing, but row 2"):
        pio.write_run(tmp_path / "a", experiment(), {"t": [1.0, 0.0], "q1": [0, 0], "q2": [0, 0], "q3": [0, 0]})
    with pytest.raises(popup.MeasuredRunError, match=r"write_run experiment: payload_kg = -2"):
        pio.write_run(tmp_path / "a", experiment(payload_kg=-2), {"t": [0.0, 1.0], "q1": [0, 0], "q2": [0, 0], "q3": [0, 0]})
    with pytest.raises(popup.MeasuredRunError, match=r"row 2, column 'q1': 'x' is not a number"):
        pio.write_run(tmp_path / "a", experiment(), pd.DataFrame({"t": [0.0, 1.0], "q1": [0.0, "x"], "q2": [0, 0], "q3": [0, 0]}))
    assert not (tmp_path / "a").exists()


def test_write_run_overwrite(tmp_path: Path) -> None:
    data = {"t": [0.0, 1.0], "q1": [0.0, 1.0], "q2": [0.0, 0.0], "q3": [0.0, 0.0]}
    pio.write_run(tmp_path / "r", experiment(), data)
    with pytest.raises(FileExistsError, match="overwrite=True"):
        pio.write_run(tmp_path / "r", experiment(), data)
    pio.write_run(tmp_path / "r", experiment(payload_kg=0.5), data, overwrite=True)
    assert pio.read_run(tmp_path / "r").payload_kg == 0.5


# ------------------------------------------------------------------------------ simulated runs, models


@pytest.fixture(scope="module")
def sim() -> popup.SimResult:
    t = np.arange(0.0, 0.6 + 1e-12, 0.002)
    s = 0.5 - 0.5 * np.cos(np.pi * t / 0.6)
    q = np.stack([0.2 * s, 0.6 * s, -0.3 * s], axis=1)
    return popup.Model().replay(t, q)


def test_simulated_run_as_measured_run(tmp_path: Path, sim: popup.SimResult) -> None:
    df = pio.from_sim(sim, description="smooth move")
    assert list(df.columns) == [c for c in pio.MEASURED_COLUMNS if not c.startswith("ref_")]
    exp = df.attrs["experiment"]
    assert exp["arm"] == "popup-lab" and exp["payload_kg"] == 2.0 and exp["pressure_pa"] == [30000.0, 30000.0]
    assert exp["gravity"] is True and exp["replay"] == "encoder" and exp["description"] == "smooth move"
    run = pio.read_run(pio.write_run(tmp_path / "sim", exp, df))
    assert run.warnings == []
    t, q = run.encoder()
    np.testing.assert_array_equal(t, sim.time)
    np.testing.assert_array_equal(q, sim.q)  # the replay input q, at the samples
    for c in df.columns:
        np.testing.assert_array_equal(run.channel(c), sim.channel(c))
    # replaying the measured run in its model reproduces the simulated one
    again = run.model().replay(t, q)
    np.testing.assert_array_equal(again.data, sim.data)


def test_from_sim_refuses_a_batch(sim: popup.SimResult) -> None:
    batch = popup.BatchResult(sim.data[None], dict(sim.params), [None], [[]], [[]])
    with pytest.raises(TypeError, match=r"batch\[b\]"):
        pio.from_sim(batch)  # type: ignore[arg-type]


def test_model_from_declared_experiment(tmp_path: Path) -> None:
    toml = GOOD_TOML.replace("payload_kg = 2.0", "payload_kg = 1.5").replace("[30000.0, 30000.0]", "[25000.0, 28000.0]")
    toml = toml.replace("gravity = true", "gravity = false")
    run = pio.read_run(make_run(tmp_path / "run", toml=toml))
    m = run.model()
    assert isinstance(m, popup.Model)
    assert m.payload_kg == 1.5 and m.pressure_pa == (25000.0, 28000.0)
    assert "gravity" in m.core.disabled and m.arm.name == "popup-lab"
    m2 = run.model(dt=5e-4, payload_kg=0.0)
    assert m2.dt == 5e-4 and m2.payload_kg == 0.0


def test_arm_file_relative_to_run_folder(tmp_path: Path) -> None:
    folder = make_run(tmp_path / "run", toml=GOOD_TOML.replace('"popup-lab"', '"arms/lab.toml"'))
    (folder / "arms").mkdir()
    (folder / "arms" / "lab.toml").write_text(popup.Arm.builtin("popup-lab").to_toml(), encoding="utf-8")
    run = pio.read_run(folder)
    assert run.arm == "arms/lab.toml" and run.arm_source == str(folder / "arms" / "lab.toml")
    assert run.model().arm.name == "popup-lab"
