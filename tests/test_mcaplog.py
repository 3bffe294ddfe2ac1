"""MCAP logs (docs/logging.md) read by popup.read_log and popup.read_run.

No Rust writer is needed: the files are written here with the Python ``mcap`` writer
following docs/logging.md, as a measured run from another tool would be. Checked: the
samples come back bit-exact and merged on the union of ``t``; both styles of experiment
metadata; read_run on an MCAP equals read_run on the same data as a CSV folder; files
cut short keep every complete chunk and say what was lost; corrupted and malformed files
are refused naming the file; tests/mcap_check.py validates the Foxglove channels against
the vendored schemas.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

import numpy as np
import pandas as pd
import pytest

import popup
import popup.io as pio
from popup.mcaplog import EVENT_TOPIC, MAGIC, SAMPLE_TOPICS

pytest.importorskip("mcap")
from mcap.reader import make_reader  # noqa: E402
from mcap.writer import CompressionType, Writer  # noqa: E402

import mcap_check  # noqa: E402  (tests/mcap_check.py)

Cols = Dict[str, np.ndarray]
Samples = Dict[str, Tuple[np.ndarray, Cols]]

TIME = {
    "type": "object",
    "properties": {"sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}},
    "required": ["sec", "nsec"],
}

EXPERIMENT_TOML = """\
format = "popup-run/1"
arm = "popup-lab"
payload_kg = 2.0
pressure_pa = [30000.0, 30000.0]
gravity = true
replay = "encoder"
description = "step test"
"""

EXPERIMENT = {
    "format": "popup-run/1",
    "arm": "popup-lab",
    "payload_kg": 2.0,
    "pressure_pa": [30000.0, 30000.0],
    "gravity": True,
    "replay": "encoder",
    "description": "step test",
}

SCENARIO = 'format = "popup-scenario/1"\nduration_s = 3.0\n'


# ------------------------------------------------------------------------------ writing


def popup_schema(name: str, keys: Iterable[str]) -> bytes:
    """The JSON schema of a popup sample topic (docs/logging.md)."""
    props: Dict[str, Any] = {"timestamp": TIME, "t": {"type": "number"}, **{k: {"type": "number"} for k in keys}}
    return json.dumps({"title": name, "type": "object", "properties": props, "required": ["timestamp", "t"]}).encode()


EVENT_SCHEMA = json.dumps(
    {
        "title": "popup.Event",
        "type": "object",
        "properties": {"timestamp": TIME, "t": {"type": "number"}, **{k: {"type": "string"} for k in ("kind", "from", "to", "detail")}},
        "required": ["timestamp", "t", "kind", "from", "to", "detail"],
    }
).encode()


def stamp(t: float) -> Tuple[int, Dict[str, int]]:
    """log_time [ns] and the ``timestamp`` object of a sample at ``t`` [s]."""
    ns = round(t * 1e9)
    return ns, {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


class LogWriter:
    """A popup-layout MCAP file written with the Python mcap writer."""

    def __init__(self, path: Path, *, compression: str = "zstd", chunk_size: int = 2048) -> None:
        self.path = path
        self._f = open(path, "wb")
        self.w = Writer(self._f, chunk_size=chunk_size, compression=CompressionType[compression.upper()])
        self.w.start(profile="", library="popup tests (python mcap)")
        self._channels: Dict[str, int] = {}
        self._seq: Dict[str, int] = {}
        self.queue: List[Tuple[int, int, str, bytes]] = []

    def channel(self, topic: str, schema_name: str, schema: bytes) -> int:
        if topic not in self._channels:
            sid = self.w.register_schema(name=schema_name, encoding="jsonschema", data=schema)
            self._channels[topic] = self.w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
        return self._channels[topic]

    def samples(self, samples: Samples) -> None:
        """Queue sample messages; a NaN value is left out of its message."""
        for topic, (t, cols) in samples.items():
            name = SAMPLE_TOPICS.get(topic, ("popup.Other", ()))[0]
            self.channel(topic, name, popup_schema(name, cols))
            for i, ti in enumerate(t):
                ns, ts = stamp(float(ti))
                msg = {"timestamp": ts, "t": float(ti), **{k: float(v[i]) for k, v in cols.items() if not math.isnan(v[i])}}
                self.queue.append((ns, len(self.queue), topic, json.dumps(msg).encode()))

    def message(self, topic: str, schema_name: str, schema: bytes, t: float, msg: Mapping[str, Any]) -> None:
        self.channel(topic, schema_name, schema)
        ns, _ = stamp(t)
        self.queue.append((ns, len(self.queue), topic, json.dumps(msg).encode()))

    def event(self, t: float, kind: str, frm: str, to: str, detail: str) -> None:
        _, ts = stamp(t)
        msg = {"timestamp": ts, "t": t, "kind": kind, "from": frm, "to": to, "detail": detail}
        self.message(EVENT_TOPIC, "popup.Event", EVENT_SCHEMA, t, msg)

    def flush_messages(self) -> None:
        """Write the queued messages in time order."""
        for ns, _, topic, data in sorted(self.queue):
            seq = self._seq.get(topic, 0)
            self._seq[topic] = seq + 1
            self.w.add_message(self._channels[topic], log_time=ns, data=data, publish_time=ns, sequence=seq)
        self.queue.clear()

    def finish(self) -> Path:
        self.flush_messages()
        self.w.finish()
        self._f.close()
        return self.path


def write_log(
    path: Path,
    samples: Samples,
    *,
    experiment: Optional[Dict[str, str]] = None,
    popup_md: Optional[Dict[str, str]] = None,
    run_end: Optional[Dict[str, str]] = None,
    events: Sequence[Tuple[float, str, str, str, str]] = (),
    compression: str = "zstd",
    chunk_size: int = 2048,
) -> Path:
    """A whole log: metadata first, then the messages in time order, then run_end."""
    lw = LogWriter(path, compression=compression, chunk_size=chunk_size)
    if experiment is not None:
        lw.w.add_metadata("experiment", experiment)
    if popup_md is not None:
        lw.w.add_metadata("popup", popup_md)
    lw.samples(samples)
    for ev in events:
        lw.event(*ev)
    lw.flush_messages()
    if run_end is not None:
        lw.w.add_metadata("run_end", run_end)
    return lw.finish()


# ------------------------------------------------------------------------------ data


def rates_samples(n: int = 300, seed: int = 3) -> Samples:
    """Joints at 100 Hz, pressure at 40 Hz (never at a joint time), bending at 20 Hz (at
    joint times), the joint keys given out of documented order."""
    rng = np.random.default_rng(seed)
    tj = np.arange(n) * 0.01
    tp = 0.0125 + np.arange(n * 2 // 5) * 0.025
    tb = tj[::5]
    joints = {k: rng.normal(0.0, 0.5, n) for k in reversed(SAMPLE_TOPICS["/popup/joints"][1])}
    joints["q1"][:6] = [0.1, 1.0 / 3.0, 5e-324, -0.0, 1e300, 2.0**-1022]  # exact round trip
    pressure = {"p1": 30_000.0 + rng.normal(0, 50, tp.size), "p2": 29_000.0 + rng.normal(0, 50, tp.size)}
    bending = {k: rng.normal(0, 0.01, tb.size) for k in ("d11", "d12", "m1_ratio")}
    return {"/popup/joints": (tj, joints), "/popup/pressure": (tp, pressure), "/popup/bending": (tb, bending)}


def measured_samples(n: int = 200, seed: int = 5) -> Tuple[Samples, pd.DataFrame]:
    """Every measured-run column at one rate (500 Hz) plus bending at 50 Hz; and the
    measured columns as a DataFrame in the order the MCAP table gives them."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.002
    samples: Samples = {}
    for topic in ("/popup/joints", "/popup/imu", "/popup/end_effector", "/popup/pressure", "/popup/reference"):
        keys = SAMPLE_TOPICS[topic][1]
        samples[topic] = (t, {k: rng.normal(0, 1, n) for k in keys})
    samples["/popup/bending"] = (t[::10], {"d11": rng.normal(0, 0.01, n // 10)})
    df = pd.DataFrame({"t": t, **{k: v for topic, (_, cols) in samples.items() if topic != "/popup/bending" for k, v in cols.items()}})
    return samples, df


def exact(a: np.ndarray, b: np.ndarray) -> bool:
    """Same float64 bits (NaN where NaN), so -0.0 != 0.0."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and bool(np.array_equal(a.view(np.uint64), b.view(np.uint64)))


def chunks(path: Path) -> List[Any]:
    """The chunk indexes of a finished file, in file order."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)


def cut(src: Path, n: int, dst: Path) -> Path:
    dst.write_bytes(src.read_bytes()[:n])
    return dst


def refused(fn: Any, path: Path, *needles: str, error: type = popup.LogFileError) -> str:
    """``fn(path)`` raises ``error`` naming the file and every needle. Returns the text."""
    with pytest.raises(error) as e:
        fn(path)
    msg = str(e.value)
    assert isinstance(e.value, popup.MeasuredRunError) and isinstance(e.value, popup.PopupError) and isinstance(e.value, ValueError)
    assert str(path) in msg, msg
    for n in needles:
        assert n in msg, f"{n!r} not in {msg!r}"
    return msg


# ------------------------------------------------------------------------------ (a) read back


def test_read_back_bit_exact_and_merged_on_union_of_t(tmp_path: Path) -> None:
    pytest.importorskip("jsonschema")
    samples = rates_samples()
    path = write_log(tmp_path / "run.mcap", samples, experiment={"toml": EXPERIMENT_TOML})
    log = popup.read_log(path)

    joint_keys = list(SAMPLE_TOPICS["/popup/joints"][1])
    assert log.columns == ["t", *joint_keys, "p1", "p2", "d11", "d12", "m1_ratio"]  # documented order
    assert all(log.table[c].dtype == np.float64 for c in log.columns)
    t_all = np.union1d(np.union1d(samples["/popup/joints"][0], samples["/popup/pressure"][0]), samples["/popup/bending"][0])
    assert exact(log.time, t_all)
    for topic, (t, cols) in samples.items():
        rows = np.searchsorted(t_all, t)
        other = np.setdiff1d(np.arange(t_all.size), rows)
        for k, v in cols.items():
            got = log.channel(k)
            assert exact(got[rows], v), (topic, k)
            assert np.isnan(got[other]).all(), (topic, k)
    q1 = log.channel("q1")[np.searchsorted(t_all, samples["/popup/joints"][0])]
    assert q1[:6].tolist() == [0.1, 1.0 / 3.0, 5e-324, -0.0, 1e300, 2.0**-1022]
    assert math.copysign(1.0, q1[3]) == -1.0

    assert log.complete and log.lost == ""
    assert log.topics == {"/popup/joints": 300, "/popup/pressure": 120, "/popup/bending": 60}
    assert log.run_end is None and log.scenario is None and log.log == []
    assert list(log.events.columns) == ["t", "kind", "from", "to", "detail"] and len(log.events) == 0
    df = log.to_pandas()
    assert df.index.name == "t" and df.attrs["complete"] is True and df.attrs["experiment"] == EXPERIMENT
    first = log.messages("/popup/joints")[0]
    assert first["t"] == 0.0 and first["timestamp"] == {"sec": 0, "nsec": 0} and first["q1"] == 0.1
    with pytest.raises(KeyError, match="no column 'nope'"):
        log.channel("nope")
    with pytest.raises(KeyError, match="no topic '/tf'"):
        log.messages("/tf")
    assert "complete=True" in repr(log) and "rows=" in repr(log)
    assert mcap_check.validate_file(path) == log.topics


def test_missing_keys_events_and_metadata(tmp_path: Path) -> None:
    t = np.arange(5) * 0.1
    q1 = np.array([0.0, np.nan, 0.2, 0.3, np.nan])  # left out of those messages
    samples: Samples = {"/popup/joints": (t, {"q1": q1, "q2": t * 2, "q3": -t}), "/popup/mystery": (t + 0.05, {"zz": t})}
    events = [(0.0, "transition", "", "holding", "start"), (0.35, "fault", "holding", "holding", "contact lost")]
    run_end = {"status": "completed", "t_end": "0.4", "samples": "5", "nonfinite_dropped": "0"}
    popup_md = {"version": popup.__version__, "scenario": SCENARIO, "seed": "0", "dt": "0.0001"}
    path = write_log(tmp_path / "run.mcap", samples, experiment={"toml": EXPERIMENT_TOML}, popup_md=popup_md, run_end=run_end, events=events)
    log = popup.read_log(path)
    assert log.columns == ["t", "q1", "q2", "q3", "zz"]  # unknown /popup/ topics after the documented ones
    assert exact(log.channel("q1")[::2], q1)
    assert log.events["kind"].tolist() == ["transition", "fault"]
    assert log.events["from"].tolist() == ["", "holding"] and log.events["detail"].tolist()[1] == "contact lost"
    assert exact(log.events["t"].to_numpy(), np.array([0.0, 0.35]))
    assert log.scenario == SCENARIO and log.run_end == run_end
    assert log.metadata["popup"]["seed"] == "0"
    assert log.topics[EVENT_TOPIC] == 2


# ------------------------------------------------------------------------------ (b) experiment


PER_KEY_STYLES = {
    "quoted": {"format": '"popup-run/1"', "arm": '"popup-lab"'},
    "bare": {"format": "popup-run/1", "arm": "popup-lab"},
}


@pytest.mark.parametrize("style", ["toml", "quoted", "bare"])
def test_experiment_metadata_both_styles(tmp_path: Path, style: str) -> None:
    if style == "toml":  # the popup writer: the whole experiment.toml plus display strings
        md = {"toml": EXPERIMENT_TOML, "arm": "popup-lab", "payload_kg": "2.0", "replay": "encoder"}
    else:  # another tool: one TOML value per key
        md = {
            **PER_KEY_STYLES[style],
            "payload_kg": "2.0",
            "pressure_pa": "[30000.0, 30000.0]",
            "gravity": "true",
            "replay": '"encoder"',
            "description": '"step test"',
        }
    samples, _ = measured_samples(20)
    path = write_log(tmp_path / "run.mcap", samples, experiment=md)
    assert popup.read_log(path).experiment == EXPERIMENT
    run = popup.read_run(path)
    assert (run.arm, run.payload_kg, run.pressure_pa, run.gravity, run.replay) == ("popup-lab", 2.0, (30000.0, 30000.0), True, "encoder")
    assert run.description == "step test" and run.experiment == EXPERIMENT and run.warnings == []


def test_experiment_metadata_is_checked_like_experiment_toml(tmp_path: Path) -> None:
    samples, _ = measured_samples(20)
    bad = write_log(tmp_path / "bad.mcap", samples, experiment={"toml": EXPERIMENT_TOML.replace("2.0", "-1.0")})
    refused(popup.read_run, bad, "(metadata record experiment)", "payload_kg = -1.0", ">= 0 [kg]", error=popup.MeasuredRunError)
    broken = write_log(tmp_path / "broken.mcap", samples, experiment={"toml": 'format = "popup-run/1"\narm = \n'})
    refused(popup.read_log, broken, "metadata record experiment, key toml", "malformed TOML", "line 2")
    text = write_log(tmp_path / "text.mcap", samples, experiment={"format": "popup-run/1", "arm": "popup-lab", "payload_kg": "2 kg", "pressure_pa": "[1.0, 1.0]"})
    refused(popup.read_run, text, "payload_kg = '2 kg'", error=popup.MeasuredRunError)
    nofile = write_log(tmp_path / "arm.mcap", samples, experiment={"toml": EXPERIMENT_TOML.replace('"popup-lab"', '"arms/mine.toml"')})
    refused(popup.read_run, nofile, "unknown arm 'arms/mine.toml'", str(tmp_path / "arms" / "mine.toml"), error=popup.MeasuredRunError)


# ------------------------------------------------------------------------------ (c) read_run


def test_read_run_mcap_equals_csv_folder(tmp_path: Path) -> None:
    samples, df = measured_samples()
    folder = pio.write_run(tmp_path / "csv", EXPERIMENT, df)
    toml = (folder / "experiment.toml").read_text(encoding="utf-8")
    path = write_log(tmp_path / "run.mcap", samples, experiment={"toml": toml})

    from_csv = pio.read_run(folder)
    from_mcap = pio.read_run(path)
    assert from_mcap.columns == from_csv.columns == list(df.columns)
    for c in from_csv.columns:
        assert exact(from_mcap.channel(c), from_csv.channel(c)), c
    assert from_mcap.experiment == from_csv.experiment == EXPERIMENT
    for attr in ("format", "arm", "payload_kg", "pressure_pa", "gravity", "replay", "description", "initial", "controller"):
        assert getattr(from_mcap, attr) == getattr(from_csv, attr), attr
    assert from_mcap.warnings == from_csv.warnings == []
    assert from_mcap.source == from_mcap.data_file == path and from_mcap.arm_source == "popup-lab"
    for a, b in zip(from_mcap.encoder(), from_csv.encoder()):
        assert exact(a, b)
    # the bending channel is no measured-run column: only in read_log, and it adds no rows
    assert "d11" not in from_mcap.columns and "d11" in popup.read_log(path).columns
    assert len(from_mcap) == len(df)


def test_read_run_mcap_rows_merge_measured_topics_only(tmp_path: Path) -> None:
    t = np.arange(10) * 0.01
    samples: Samples = {
        "/popup/joints": (t, {"q1": t, "q2": t, "q3": t}),
        "/popup/end_effector": (t[::2] + 0.0055, {"ee_z": t[::2]}),
        "/popup/control": (np.arange(100) * 0.001, {"phase": np.ones(100)}),
    }
    path = write_log(tmp_path / "run.mcap", samples, experiment={"toml": EXPERIMENT_TOML})
    with pytest.warns(popup.PopupWarning, match="5 of 15 rows have a missing q1/q2/q3"):
        run = popup.read_run(path)
    assert run.columns == ["t", "q1", "q2", "q3", "ee_z"] and len(run) == 15  # control adds no rows
    all_t = np.union1d(np.union1d(t, t[::2] + 0.0055), np.arange(100) * 0.001)
    assert exact(popup.read_log(path).time, all_t)


# ------------------------------------------------------------------------------ (d) truncated


@pytest.fixture()
def killed_run(tmp_path: Path) -> Tuple[Path, Any]:
    """A finished file without run_end (as if the run was then killed) and its full log."""
    path = write_log(tmp_path / "full.mcap", rates_samples(), experiment={"toml": EXPERIMENT_TOML}, chunk_size=2048)
    return path, popup.read_log(path)


def assert_prefix(log: Any, full: Any, end_ns: int) -> None:
    """``log`` holds exactly the samples of ``full`` up to log_time ``end_ns`` (a
    column with no sample yet is absent)."""
    keep = np.round(full.time * 1e9) <= end_ns
    assert log.columns == [c for c in full.columns if c in log.columns]
    for c in full.columns:
        if c in log.columns:
            assert exact(log.channel(c), full.channel(c)[keep]), c
        else:
            assert np.isnan(full.channel(c)[keep]).all(), c


def test_cut_inside_the_last_chunk(tmp_path: Path, killed_run: Tuple[Path, Any]) -> None:
    path, full = killed_run
    ci = chunks(path)
    assert len(ci) >= 4
    last = ci[-1]
    short = cut(path, last.chunk_start_offset + last.chunk_length // 2, tmp_path / "killed.mcap")
    log = popup.read_log(short)
    assert not log.complete
    assert_prefix(log, full, ci[-2].message_end_time)
    t_last = float(log.time[-1])
    assert log.lost == (
        f"file ends inside a chunk record at byte {last.chunk_start_offset} "
        f"({last.chunk_length // 2} of {last.chunk_length} bytes present): the run did not finish "
        f"(no run_end record); last sample t = {t_last!r} s"
    )
    assert log.experiment == EXPERIMENT and "lost=" in repr(log)
    assert sum(log.topics.values()) < sum(full.topics.values())


@pytest.mark.parametrize("k", [0, 1, 2])
def test_cut_right_after_a_chunk(tmp_path: Path, killed_run: Tuple[Path, Any], k: int) -> None:
    path, full = killed_run
    c = chunks(path)[k]
    log = popup.read_log(cut(path, c.chunk_start_offset + c.chunk_length, tmp_path / "killed.mcap"))
    assert not log.complete
    assert_prefix(log, full, c.message_end_time)
    assert log.lost.startswith(f"file ends after the chunk record at byte {c.chunk_start_offset} ({c.chunk_length} bytes), with no summary or footer: ")
    assert "no run_end" in log.lost


def test_cut_at_many_points_never_fails(tmp_path: Path, killed_run: Tuple[Path, Any]) -> None:
    path, full = killed_run
    data = path.read_bytes()
    ci = chunks(path)
    points = {8, 9, 17, len(data) - 1, len(data) - 8, len(data) - 9}
    for c in ci[:3] + ci[len(ci) // 2 : len(ci) // 2 + 1] + ci[-2:]:  # header, records, end, message indexes
        s, e = c.chunk_start_offset, c.chunk_start_offset + c.chunk_length
        points |= {s, s + 1, s + 9, s + 30, (s + e) // 2, e - 1, e, e + 1, e + 9, e + 20}
    for n in sorted(p for p in points if 8 <= p < len(data)):
        dst = tmp_path / "cut.mcap"
        dst.write_bytes(data[:n])
        log = popup.read_log(dst)
        assert not log.complete and log.lost, n
        done = [c for c in ci if c.chunk_start_offset + c.chunk_length <= n]
        if done:
            assert_prefix(log, full, done[-1].message_end_time)
        else:
            assert len(log.table) == 0
    log = popup.read_log(cut(path, len(data) - 1, tmp_path / "cut.mcap"))
    assert log.lost.startswith("file ends inside the closing magic, after the footer (no data is missing): only the closing magic is missing; ")
    assert_prefix(log, full, 10**12)


def test_cut_in_the_summary_with_run_end(tmp_path: Path) -> None:
    samples, _ = measured_samples(50)
    run_end = {"status": "completed", "t_end": "0.098", "samples": "50", "nonfinite_dropped": "0"}
    path = write_log(tmp_path / "full.mcap", samples, experiment={"toml": EXPERIMENT_TOML}, run_end=run_end)
    full = popup.read_log(path)
    log = popup.read_log(cut(path, path.stat().st_size - 40, tmp_path / "cut.mcap"))
    assert not log.complete and log.run_end == run_end
    assert "the run finished (run_end status = completed); only the summary and index after it are lost" in log.lost
    assert_prefix(log, full, 10**12)


def test_read_run_on_a_cut_file_warns_what_was_lost(tmp_path: Path) -> None:
    samples, df = measured_samples(400)
    path = write_log(tmp_path / "full.mcap", samples, experiment={"toml": EXPERIMENT_TOML})
    last = chunks(path)[-1]
    short = cut(path, last.chunk_start_offset + 100, tmp_path / "killed.mcap")
    with pytest.warns(popup.PopupWarning, match="cut short: file ends inside a chunk record") as rec:
        run = popup.read_run(short)
    assert len(rec) == 1
    assert run.warnings == [f"{short}: the file was cut short: {popup.read_log(short).lost}"]
    assert 0 < len(run) < len(df)
    assert exact(run.channel("q1"), df["q1"].to_numpy()[: len(run)])


def test_only_the_magic(tmp_path: Path) -> None:
    p = tmp_path / "empty-run.mcap"
    p.write_bytes(MAGIC)
    log = popup.read_log(p)
    assert not log.complete and log.columns == ["t"] and log.experiment == {}
    assert log.lost == "file ends right after the MCAP magic: the run did not finish (no run_end record); no sample was read"
    refused(popup.read_run, p, "no experiment metadata record")
    q = tmp_path / "half.mcap"
    q.write_bytes(MAGIC[:5])
    refused(popup.read_log, q, "ends inside the MCAP magic")


def test_zero_filled_tail_is_a_cut(tmp_path: Path, killed_run: Tuple[Path, Any]) -> None:
    path, full = killed_run
    c = chunks(path)[1]
    end = c.chunk_start_offset + c.chunk_length
    p = tmp_path / "zeros.mcap"
    p.write_bytes(path.read_bytes()[:end] + bytes(4096))
    log = popup.read_log(p)
    assert log.lost.startswith(f"file ends in 4096 zero bytes from byte {end}")
    assert_prefix(log, full, c.message_end_time)


# ------------------------------------------------------------------------------ (e) corrupted


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_corrupted_byte_in_a_chunk_is_an_error(tmp_path: Path, compression: str) -> None:
    path = write_log(tmp_path / "run.mcap", rates_samples(), experiment={"toml": EXPERIMENT_TOML}, compression=compression)
    c = chunks(path)[1]
    data = bytearray(path.read_bytes())
    data[c.chunk_start_offset + c.chunk_length // 2] ^= 0x20
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    msg = refused(popup.read_log, bad, f"the chunk record at byte {c.chunk_start_offset} ({c.chunk_length} bytes) is corrupted")
    if compression == "none":
        assert "CRC mismatch in the chunk" in msg
    refused(popup.read_run, bad, f"chunk record at byte {c.chunk_start_offset}")
    # the same corruption in the last, incomplete chunk of a cut file is a cut, not an error
    short = tmp_path / "short.mcap"
    short.write_bytes(bytes(data[: c.chunk_start_offset + c.chunk_length - 1]))
    assert not popup.read_log(short).complete


def test_corrupted_record_header_is_an_error(tmp_path: Path) -> None:
    path = write_log(tmp_path / "run.mcap", rates_samples(), experiment={"toml": EXPERIMENT_TOML})
    c = chunks(path)[2]
    data = bytearray(path.read_bytes())
    data[c.chunk_start_offset] = 0x42  # no such opcode
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    refused(popup.read_log, bad, f"byte {c.chunk_start_offset}: 0x42 is not an MCAP record opcode")


# ------------------------------------------------------------------------------ (f) malformed


def test_malformed_files(tmp_path: Path) -> None:
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    refused(popup.read_log, empty, "the file is empty (0 bytes)")
    refused(popup.read_run, empty, "the file is empty")
    csv = tmp_path / "measurements.mcap"
    csv.write_text("t,q1\n0,0\n")
    refused(popup.read_log, csv, "not an MCAP file", "expected the MCAP magic")
    refused(popup.read_run, csv, "not an MCAP file")
    refused(popup.read_log, tmp_path / "nowhere.mcap", "cannot be read")

    samples, _ = measured_samples(10)
    no_exp = write_log(tmp_path / "no-experiment.mcap", samples)
    assert popup.read_log(no_exp).experiment == {}
    refused(popup.read_run, no_exp, "no experiment metadata record", "key toml")
    no_samples = write_log(tmp_path / "no-samples.mcap", {"/popup/bending": (np.arange(3.0), {"d11": np.zeros(3)})}, experiment={"toml": EXPERIMENT_TOML})
    refused(popup.read_run, no_samples, "no measured-run samples", "/popup/bending")


def bad_message(tmp_path: Path, payload: bytes, name: str = "bad.mcap") -> Path:
    lw = LogWriter(tmp_path / name)
    lw.w.add_metadata("experiment", {"toml": EXPERIMENT_TOML})
    lw.samples({"/popup/joints": (np.array([0.0, 0.01]), {"q1": np.zeros(2), "q2": np.zeros(2), "q3": np.zeros(2)})})
    lw.queue.append((10**9, 99, "/popup/joints", payload))
    return lw.finish()


@pytest.mark.parametrize(
    "payload, needle",
    [
        (b'{"t": 1.0, "q1": NaN}', "not valid JSON (NaN is not JSON"),
        (b'{"t": 1.0, "q1": "0.5"}', "q1 = '0.5': expected a number"),
        (b'{"t": 1.0, "q1": true}', "q1 = True: expected a number"),
        (b'{"q1": 0.5}', "t = None: expected the sample time [s]"),
        (b'{"t": 0.005, "q1": 0.5}', "t must increase from message to message; message 2 has t = 0.005 s"),
        (b"[1, 2]", "expected a JSON object, got list"),
        (b"\xff{", "not valid JSON"),
    ],
)
def test_malformed_messages(tmp_path: Path, payload: bytes, needle: str) -> None:
    path = bad_message(tmp_path, payload)
    msg = refused(popup.read_log, path, needle)
    if "increase" not in needle:
        assert "/popup/joints message 2 (log_time 1000000000 ns, in the chunk record at byte" in msg


# ------------------------------------------------------------------------------ Foxglove + mcap_check


def foxglove_messages(t: float) -> Dict[str, Tuple[str, Dict[str, Any]]]:
    """One message of each Foxglove channel, built by hand after the schemas."""
    _, ts = stamp(t)
    pose = {"position": {"x": 0.0, "y": 0.0, "z": 0.25}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}
    entity = {
        "timestamp": ts,
        "frame_id": "world",
        "id": "link1",
        "lifetime": {"sec": 0, "nsec": 0},
        "frame_locked": False,
        "metadata": [{"key": "ratio", "value": "0.2"}],
        "arrows": [],
        "cubes": [],
        "spheres": [],
        "cylinders": [{"pose": pose, "size": {"x": 0.1, "y": 0.1, "z": 0.5}, "bottom_scale": 1.0, "top_scale": 1.0, "color": {"r": 0.4, "g": 1.0, "b": 0.0, "a": 1.0}}],
        "lines": [],
        "triangles": [],
        "texts": [],
        "models": [],
    }
    transform = {
        "timestamp": ts,
        "parent_frame_id": "world",
        "child_frame_id": "base",
        "translation": {"x": 0.0, "y": 0.0, "z": 0.0},
        "rotation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
    }
    log = {"timestamp": ts, "level": 2, "message": "holding -> moving", "name": "popup", "file": "", "line": 0}
    return {
        "/tf": ("foxglove.FrameTransforms", {"transforms": [transform]}),
        "/scene": ("foxglove.SceneUpdate", {"deletions": [], "entities": [entity]}),
        "/log": ("foxglove.Log", log),
    }


def foxglove_log(path: Path, override: Optional[Dict[str, Dict[str, Any]]] = None, schema_data: Optional[bytes] = None) -> Path:
    lw = LogWriter(path)
    lw.w.add_metadata("experiment", {"toml": EXPERIMENT_TOML})
    lw.samples({"/popup/joints": (np.array([0.0, 0.5]), {"q1": np.zeros(2), "q2": np.zeros(2), "q3": np.zeros(2)})})
    for t in (0.0, 0.5):
        for topic, (name, msg) in foxglove_messages(t).items():
            msg = (override or {}).get(topic, msg)
            data = schema_data if schema_data is not None else mcap_check.vendored_schema(name)
            lw.message(topic, name, data, t, msg)
    return lw.finish()


def test_vendored_foxglove_schemas() -> None:
    pytest.importorskip("jsonschema")
    from jsonschema import Draft202012Validator

    for name in ("foxglove.FrameTransforms", "foxglove.SceneUpdate", "foxglove.Log"):
        text = mcap_check.vendored_schema(name).decode("utf-8")
        schema = json.loads(text)
        assert schema["title"] == name and "foxglove" in schema["$comment"]
        assert text.endswith("}\n") and json.dumps(schema, indent=2, ensure_ascii=False) + "\n" == text  # generator layout
        Draft202012Validator.check_schema(schema)
    assert (mcap_check.SCHEMA_DIR / "README.md").is_file()


def test_mcap_check_accepts_valid_foxglove_messages(tmp_path: Path) -> None:
    pytest.importorskip("jsonschema")
    path = foxglove_log(tmp_path / "viz.mcap")
    assert mcap_check.validate_file(path) == {"/popup/joints": 2, "/tf": 2, "/scene": 2, "/log": 2}
    log = popup.read_log(path)
    assert log.log == [foxglove_messages(t)["/log"][1] for t in (0.0, 0.5)]
    assert log.messages("/scene")[1] == foxglove_messages(0.5)["/scene"][1]
    assert log.columns == ["t", "q1", "q2", "q3"] and log.topics["/tf"] == 2


def test_mcap_check_rejects_invalid_messages(tmp_path: Path) -> None:
    pytest.importorskip("jsonschema")
    no_level = {k: v for k, v in foxglove_messages(0.0)["/log"][1].items() if k != "level"}
    with pytest.raises(mcap_check.McapCheckError, match=r"/log message 0 .*'level' is a required property"):
        mcap_check.validate_file(foxglove_log(tmp_path / "a.mcap", {"/log": no_level}))
    bad_level = {**foxglove_messages(0.0)["/log"][1], "level": 7}
    with pytest.raises(mcap_check.McapCheckError, match=r"/log message 0 .*at level"):
        mcap_check.validate_file(foxglove_log(tmp_path / "b.mcap", {"/log": bad_level}))
    scene = foxglove_messages(0.0)["/scene"][1]
    no_top = json.loads(json.dumps(scene))
    del no_top["entities"][0]["cylinders"][0]["top_scale"]
    with pytest.raises(mcap_check.McapCheckError, match=r"/scene message 0 .*entities/0/cylinders/0"):
        mcap_check.validate_file(foxglove_log(tmp_path / "c.mcap", {"/scene": no_top}))
    with pytest.raises(mcap_check.McapCheckError, match="differs from the vendored"):
        mcap_check.validate_file(foxglove_log(tmp_path / "d.mcap", schema_data=b'{"type": "object"}'))


def test_mcap_check_rejects_popup_messages_against_their_schema(tmp_path: Path) -> None:
    pytest.importorskip("jsonschema")
    path = bad_message(tmp_path, b'{"timestamp": {"sec": 1, "nsec": 0}, "t": 1.0, "q1": "x"}')
    with pytest.raises(mcap_check.McapCheckError, match=r"/popup/joints message 2 .*at q1: 'x' is not of type 'number'"):
        mcap_check.validate_file(path)


def test_public_api() -> None:
    for name in ("read_log", "RunLog", "LogFileError"):
        assert name in popup.__all__
    assert issubclass(popup.LogFileError, popup.MeasuredRunError)
