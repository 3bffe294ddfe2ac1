"""Issue 19: a measured run given as an MCAP file cut short says so, and where, whatever
the point of the cut; a killed writer's placeholder length is never printed as a size."""

import struct
import warnings
from pathlib import Path

import numpy as np
import pytest

import popup

CHUNK, METADATA = 0x06, 0x0C


@pytest.fixture(scope="module")
def logged(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("cut") / "full.mcap"
    t = np.arange(0.0, 0.6, 0.002)
    q = np.zeros((t.size, 3))
    q[:, 1] = 0.3 * t
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", popup.PopupWarning)
        popup.Model().replay(t, q, log=out)
    return out


def records(b: bytes):
    pos, out = 8, []
    while pos + 9 <= len(b):
        op, ln = struct.unpack("<BQ", b[pos : pos + 9])
        out.append((pos, op, ln))
        pos += 9 + ln
        if op == 0x02:  # footer
            break
    return out


def cut_points(b: bytes):
    rec = records(b)
    first_chunk = next(r for r in rec if r[1] == CHUNK)
    meta = [r for r in rec if r[1] == METADATA]
    return {
        "after the magic": 8,
        "after the header": rec[1][0],
        "inside the first chunk": first_chunk[0] + 9 + first_chunk[2] // 2,
        "after the metadata, no samples": meta[0][0] + 9 + meta[0][2],
    }


@pytest.mark.parametrize("where", ["after the magic", "after the header", "inside the first chunk", "after the metadata, no samples"])
def test_read_run_says_the_file_was_cut_short(tmp_path, logged, where):
    b = logged.read_bytes()
    short = tmp_path / "short.mcap"
    short.write_bytes(b[: cut_points(b)[where]])
    with pytest.raises(popup.LogFileError) as e:
        popup.read_run(short)
    msg = str(e.value)
    assert str(short) in msg and "the file was cut short (file ends" in msg, msg
    assert "byte" in msg or "right after the MCAP magic" in msg, msg


def test_killed_writers_placeholder_length_is_not_a_byte_count(tmp_path, logged):
    b = logged.read_bytes()
    rec = records(b)
    chunk = next(r for r in rec if r[1] == CHUNK)
    # the records up to the first chunk, then a chunk whose length field still holds the
    # placeholder a killed writer leaves (u64::MAX)
    torn = b[: chunk[0]] + struct.pack("<BQ", CHUNK, 2**64 - 1) + b[chunk[0] + 9 : chunk[0] + 9 + 500]
    path = tmp_path / "killed.mcap"
    path.write_bytes(torn)
    log = popup.read_log(path)
    assert not log.complete
    assert "18446744073709551" not in log.lost, log.lost
    assert f"chunk record at byte {chunk[0]} whose length was never written" in log.lost, log.lost
