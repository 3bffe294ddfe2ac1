"""MCAP logs: read a popup run log (``docs/logging.md``) back into tables.

A popup MCAP log holds JSON messages: the sample topics ``/popup/joints``,
``/popup/imu``, ... (one message per sample group: ``timestamp``, ``t`` [s] and one key
per column, SI units: s, rad, rad/s, N·m, m, m/s², Pa), the event log
``/popup/events``, the Foxglove channels ``/tf``, ``/scene``, ``/log`` and the metadata
records ``experiment``, ``popup`` and ``run_end``.

:func:`read_log` reads every complete record with the streaming reader
(:class:`mcap.stream_reader.StreamReader`, CRCs checked), so a file cut short by a
killed process (no summary, no footer) is read up to its last complete record and
:attr:`RunLog.lost` says what is missing. A record that is complete but corrupted (CRC
mismatch, undecodable chunk) is an error, never skipped.

Floats come back bit-exact: the writer writes the shortest representation that
round-trips an f64 and :func:`json.loads` parses it back to the same f64.
"""

from __future__ import annotations

import bisect
import json
import math
import numbers
import os
import struct
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, Dict, Iterator, List, Optional, Sequence, Tuple, Type, Union, cast

import numpy as np

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.9/3.10
    import tomli as tomllib

from .exceptions import LogFileError

if TYPE_CHECKING:  # pandas and mcap are imported lazily: `import popup` stays fast
    import pandas as pd

__all__ = ["RunLog", "read_log", "SAMPLE_TOPICS", "EVENT_TOPIC", "LOG_TOPIC", "EVENT_COLUMNS", "MAGIC"]

PathLike = Union[str, "os.PathLike[str]"]

MAGIC: bytes = b"\x89MCAP0\r\n"
"""The 8 bytes that open (and close) every MCAP file."""

SAMPLE_TOPICS: Dict[str, Tuple[str, Tuple[str, ...]]] = {
    "/popup/joints": ("popup.Joints", ("q1", "q2", "q3", "dq1", "dq2", "dq3", "tau1", "tau2", "tau3")),
    "/popup/imu": ("popup.Imu", ("imu1_ax", "imu1_ay", "imu1_az", "imu2_ax", "imu2_ay", "imu2_az")),
    "/popup/end_effector": ("popup.EndEffector", ("ee_x", "ee_y", "ee_z")),
    "/popup/pressure": ("popup.Pressure", ("p1", "p2")),
    "/popup/bending": (
        "popup.Bending",
        ("d11", "d12", "d21", "d22", "dd11", "dd12", "dd21", "dd22",
         "m11", "m12", "m21", "m22", "m1_ratio", "m2_ratio", "energy"),
    ),
    "/popup/reference": ("popup.Reference", ("ref_q1", "ref_q2", "ref_q3")),
    "/popup/control": (
        "popup.Control",
        ("vref1", "vref2", "vref3", "u_damp1", "u_damp2", "u_damp3", "a_rel1", "a_rel2", "a_rel3",
         "tau_cmd1", "tau_cmd2", "tau_cmd3", "phase", "d_min"),
    ),
}  # fmt: skip
"""Sample topics of ``docs/logging.md`` in table order: topic -> (schema name, keys)."""

EVENT_TOPIC: str = "/popup/events"
"""The controller's event log (schema ``popup.Event``)."""

EVENT_COLUMNS: Tuple[str, ...] = ("t", "kind", "from", "to", "detail")
"""Columns of :attr:`RunLog.events`: ``t`` [s] and four strings."""

LOG_TOPIC: str = "/log"
"""The ``foxglove.Log`` channel (INFO transitions, WARNING faults/alarms, ERROR)."""

_SAMPLE_PREFIX = "/popup/"
_ENVELOPE = ("timestamp", "t")  # keys of a sample message that are not columns


def _pd() -> Any:
    import pandas

    return pandas


def _num(x: float) -> str:
    """A float as Python writes it (shortest round-trip text)."""
    return repr(float(x))


def _is_number(v: Any) -> bool:
    """A JSON number (int or float, not bool); the type test first, it is the hot path."""
    return type(v) is float or type(v) is int or (isinstance(v, numbers.Real) and not isinstance(v, bool))


# ---------------------------------------------------------------------------- RunLog


@dataclass(eq=False)
class RunLog:
    """A popup MCAP log as read by :func:`read_log`.

    Attributes
    ----------
    path : Path
        The ``.mcap`` file.
    table : pandas.DataFrame
        ``t`` [s], then every sample column of the file (topics in the order of
        ``docs/logging.md``: joints, imu, end_effector, pressure, bending, reference,
        control; keys in the documented order), merged on the union of the topics' ``t``
        values; float64, NaN where a topic has no sample at that ``t``. SI units (s,
        rad, rad/s, N·m, m, m/s², Pa). A default RangeIndex.
    events : pandas.DataFrame
        ``/popup/events``: ``t`` [s] (float64), ``kind``, ``from``, ``to``, ``detail``
        (str), in file order.
    metadata : dict
        Every metadata record: name -> {key: value} (strings; a later record of the
        same name replaces an earlier one).
    experiment : dict
        The ``experiment`` metadata parsed: its ``toml`` key (a complete
        ``experiment.toml``), else one TOML value per key (a value that is not valid
        TOML is kept as the string, so ``arm = popup-lab`` works). ``{}`` when absent.
    scenario : str or None
        The scenario TOML (``popup`` metadata, key ``scenario``).
    run_end : dict or None
        The ``run_end`` metadata (``status``, ``t_end`` [s], ``samples``,
        ``nonfinite_dropped``, as strings); None if the run did not finish.
    topics : dict
        topic -> number of messages read, for every channel of the file.
    log : list of dict
        The ``/log`` messages (``foxglove.Log``: ``timestamp``, ``level``, ``message``,
        ``name``, ``file``, ``line``), decoded.
    complete : bool
        True if the file ends with its footer and closing magic (it was finished).
    lost : str
        "" for a complete file; else what is missing, e.g. "file ends inside a chunk
        record at byte 10234 (...): the run did not finish (no run_end record); last
        sample t = 12.34 s".
    """

    path: Path
    table: "pd.DataFrame"
    events: "pd.DataFrame"
    metadata: Dict[str, Dict[str, str]]
    experiment: Dict[str, Any]
    scenario: Optional[str]
    run_end: Optional[Dict[str, str]]
    topics: Dict[str, int]
    log: List[Dict[str, Any]]
    complete: bool
    lost: str = ""
    _parts: Dict[str, Tuple[np.ndarray, Dict[str, np.ndarray]]] = field(default_factory=dict, repr=False)
    _layout: Optional["_Layout"] = field(default=None, repr=False)

    def __repr__(self) -> str:
        t = self.table["t"].to_numpy() if len(self.table) else np.empty(0)
        span = f"{_num(t[0])} to {_num(t[-1])} s" if t.size else "no samples"
        lost = f", lost={self.lost!r}" if self.lost else ""
        return (
            f"RunLog(path={str(self.path)!r}, complete={self.complete}, rows={len(self.table)}, t={span}, "
            f"columns={self.columns[1:]}, events={len(self.events)}, topics={self.topics}{lost})"
        )

    @property
    def columns(self) -> List[str]:
        """Column names of :attr:`table` (``t`` first)."""
        return [str(c) for c in self.table.columns]

    @property
    def time(self) -> np.ndarray:
        """Sample times ``t`` [s] of :attr:`table`, shape (N,), float64 (a copy)."""
        return self.channel("t")

    def channel(self, name: str) -> np.ndarray:
        """One column of :attr:`table` (e.g. ``"q1"`` [rad], ``"m1_ratio"`` [1]) as a
        float64 array (a copy, NaN where that topic has no sample at ``t``). Raises
        KeyError if the log has no such column."""
        if name not in self.table.columns:
            raise KeyError(f"{self.path}: no column {name!r} in this log; columns are {self.columns}")
        return np.array(self.table[name].to_numpy(dtype=np.float64), copy=True)

    def to_pandas(self) -> "pd.DataFrame":
        """A copy of :attr:`table` indexed by ``t`` [s], with ``.attrs`` ``experiment``,
        ``source``, ``complete`` and ``lost``."""
        df = self.table.set_index("t", drop=True)
        df.attrs.update(experiment=dict(self.experiment), source=str(self.path), complete=self.complete, lost=self.lost)
        return df

    def messages(self, topic: str) -> List[Dict[str, Any]]:
        """Every message of ``topic`` (e.g. ``"/tf"``, ``"/scene"``), decoded from JSON,
        in file order. The file is read again (only complete records, CRCs checked).
        Raises KeyError if the file has no such channel."""
        if topic not in self.topics:
            raise KeyError(f"{self.path}: no topic {topic!r}; topics are {list(self.topics)}")
        layout = self._layout if self._layout is not None else _scan(self.path)
        reader = _Reader(self.path, layout, decode=(topic,))
        for rec, at in _records(self.path, layout):
            reader.add(rec, at)
        return reader.decoded.get(topic, [])

    def _frame(self, columns: Sequence[str]) -> "pd.DataFrame":
        """``t`` and the given columns (those present, in :attr:`table` order) merged on
        the ``t`` of the topics that carry them (other topics add no rows)."""
        want = set(columns)
        parts = {tp: (t, {k: v for k, v in cols.items() if k in want}) for tp, (t, cols) in self._parts.items()}
        return _merge({tp: p for tp, p in parts.items() if p[1]})


# ---------------------------------------------------------------------------- reading


def read_log(path: PathLike) -> RunLog:
    """Read a popup MCAP log (``docs/logging.md``), finished or cut short.

    Parameters
    ----------
    path : str or path
        The ``.mcap`` file.

    Returns
    -------
    RunLog
        The samples as one table (``t`` [s] and SI-unit columns), the events, the
        metadata, the Foxglove log and whether the file was finished
        (:attr:`RunLog.complete`, :attr:`RunLog.lost`).

    Raises
    ------
    popup.LogFileError
        The file is empty, not MCAP, has a corrupted complete record (CRC mismatch or an
        undecodable chunk: the message names the byte offset), or holds messages that do
        not follow ``docs/logging.md`` (not JSON, no finite ``t``, a non-number value,
        ``t`` not increasing within a topic). A file that merely ends early is not an
        error: it is read up to its last complete record.
    """
    p = Path(os.fspath(path))
    layout = _scan(p)
    reader = _Reader(p, layout, decode=(EVENT_TOPIC, LOG_TOPIC))
    for rec, at in _records(p, layout):
        reader.add(rec, at)
    return reader.finish()


@dataclass
class _Layout:
    """Where the complete records of a file are (byte offsets)."""

    starts: List[int] = field(default_factory=list)
    ends: List[int] = field(default_factory=list)
    ops: List[int] = field(default_factory=list)
    end: int = len(MAGIC)  # bytes the reader may read: complete records (+ closing magic)
    footer: bool = False  # footer and closing magic present
    tail: str = ""  # what is incomplete at the end ("" when finished)

    def record_at(self, pos: int) -> int:
        """Index of the record that holds byte ``pos - 1`` (the last byte read); -1 for
        the opening magic."""
        return bisect.bisect_right(self.starts, pos - 1) - 1

    def describe(self, i: int) -> str:
        if i < 0:
            return f"the MCAP magic (bytes 0 to {len(MAGIC) - 1})"
        return f"the {_kind(self.ops[i])} record at byte {self.starts[i]} ({self.ends[i] - self.starts[i]} bytes)"


def _kind(op: int) -> str:
    from mcap.opcode import Opcode

    try:
        return Opcode(op).name.lower().replace("_", " ")
    except ValueError:
        return f"0x{op:02x}"


def _scan(path: Path) -> _Layout:
    """Walk the record headers (opcode, length) to find the complete records."""
    try:
        size = path.stat().st_size
        with open(path, "rb") as f:
            head = f.read(len(MAGIC))
            _check_magic(path, head, size)
            return _walk(path, f, size)
    except OSError as e:
        raise LogFileError(f"{path}: cannot be read ({e.strerror or e})") from None


def _check_magic(path: Path, head: bytes, size: int) -> None:
    if size == 0:
        raise LogFileError(f"{path}: the file is empty (0 bytes); expected an MCAP log (docs/logging.md)")
    if head == MAGIC:
        return
    if len(head) < len(MAGIC) and MAGIC.startswith(head):
        raise LogFileError(f"{path}: the file ends inside the MCAP magic ({size} bytes): nothing was written")
    raise LogFileError(f"{path}: not an MCAP file: it starts with {head!r}, expected the MCAP magic {MAGIC!r}")


def _walk(path: Path, f: IO[bytes], size: int) -> _Layout:
    from mcap.opcode import Opcode

    lay = _Layout()
    known = {int(o) for o in Opcode}
    pos = len(MAGIC)
    while pos < size:
        hdr = f.read(9)
        if len(hdr) < 9:
            lay.tail = f"file ends inside a record header at byte {pos} ({len(hdr)} of 9 bytes)"
            return lay
        op, length = struct.unpack("<BQ", hdr)
        if op == 0 and _zeros_to_end(f, size - pos - 9):
            lay.tail = f"file ends in {size - pos} zero bytes from byte {pos} (data that never reached the disk)"
            return lay
        if op < 0x80 and op not in known:
            raise LogFileError(f"{path}: byte {pos}: 0x{op:02x} is not an MCAP record opcode; the file is corrupted there")
        end = pos + 9 + length
        if end > size:
            if length >= 1 << 62:
                # a killed writer leaves the placeholder length of the record it had open
                lay.tail = (
                    f"file ends inside a {_kind(op)} record at byte {pos} whose length was never written (the writer "
                    f"stopped while the record was open; {size - pos} bytes of it present)"
                )
            else:
                lay.tail = f"file ends inside a {_kind(op)} record at byte {pos} ({size - pos} of {end - pos} bytes present)"
            return lay
        lay.starts.append(pos)
        lay.ends.append(end)
        lay.ops.append(op)
        lay.end = pos = end
        f.seek(end)
        if op == Opcode.FOOTER:
            return _closing(path, f, lay, size)
    i = len(lay.starts) - 1
    lay.tail = "file ends right after the MCAP magic" if i < 0 else f"file ends after {lay.describe(i)}, with no summary or footer"
    return lay


def _zeros_to_end(f: IO[bytes], n: int) -> bool:
    """The next ``n`` bytes (the rest of the file) are all zero; ``f`` is left after them."""
    while n > 0:
        block = f.read(min(n, 1 << 20))
        if not block or block.count(0) != len(block):
            return False
        n -= len(block)
    return True


def _closing(path: Path, f: IO[bytes], lay: _Layout, size: int) -> _Layout:
    rest = f.read(len(MAGIC) + 1)
    if rest[: len(MAGIC)] == MAGIC and size == lay.end + len(MAGIC):
        lay.footer, lay.end = True, size
        return lay
    if len(rest) < len(MAGIC) and MAGIC.startswith(rest):
        lay.tail = "file ends inside the closing magic, after the footer (no data is missing)"
        return lay
    where = lay.end
    if rest[: len(MAGIC)] == MAGIC:
        raise LogFileError(f"{path}: {size - where - len(MAGIC)} bytes after the closing MCAP magic (byte {where + len(MAGIC)}); an MCAP file ends there")
    raise LogFileError(f"{path}: byte {where}: expected the closing MCAP magic {MAGIC!r} after the footer, found {rest[:len(MAGIC)]!r}")


class _Bounded:
    """The first ``limit`` bytes of a file, counting what was read (``pos``) and the
    size of the last request (``asked``)."""

    def __init__(self, f: IO[bytes], limit: int) -> None:
        self._f, self.limit, self.pos, self.asked = f, limit, 0, 0

    def read(self, n: int = -1) -> bytes:
        self.asked = n
        n = self.limit - self.pos if n < 0 else min(n, self.limit - self.pos)
        data = self._f.read(n) if n > 0 else b""
        self.pos += len(data)
        return data


def _records(path: Path, lay: _Layout) -> Iterator[Tuple[Any, int]]:
    """Every complete record (chunks expanded into their records, CRCs checked) with
    the index in ``lay`` of the top-level record it was read from."""
    from mcap.exceptions import EndOfFile
    from mcap.records import Footer
    from mcap.stream_reader import StreamReader

    errors = _decode_errors()
    ends = set(lay.ends)
    with open(path, "rb") as f:
        src = _Bounded(f, lay.end)
        it = StreamReader(cast(IO[bytes], src), validate_crcs=True).records
        rec: Any = None
        while True:
            try:
                rec = next(it)
            except StopIteration:
                return
            except EndOfFile:
                if src.pos == lay.end and not lay.footer and (src.asked == 1 or isinstance(rec, Footer)):
                    return  # the next opcode (or the closing magic) is past the end of a cut file
                raise _corrupt(path, lay, src.pos, "a field runs past the end of its record") from None
            except errors as e:
                raise _corrupt(path, lay, src.pos, _describe(e)) from None
            if src.pos not in ends:
                raise _corrupt(path, lay, src.pos, "a field runs past the end of its record")
            yield rec, lay.record_at(src.pos)


def _decode_errors() -> Tuple[Type[BaseException], ...]:
    """What the MCAP reader raises on a corrupted record (zstd, lz4, struct, CRC)."""
    from mcap.exceptions import McapError
    from zstandard import ZstdError

    return (McapError, ValueError, RuntimeError, struct.error, ZstdError)


def _describe(e: BaseException) -> str:
    from mcap.stream_reader import CRCValidationError

    if isinstance(e, CRCValidationError):
        return (
            f"CRC mismatch in the {type(e.record).__name__.lower()} (stored 0x{e.expected:08x}, computed "
            f"0x{e.actual:08x}): its bytes changed after it was written"
        )
    return f"{type(e).__name__}: {e}"


def _corrupt(path: Path, lay: _Layout, pos: int, what: str) -> LogFileError:
    return LogFileError(f"{path}: {lay.describe(lay.record_at(pos))} is corrupted: {what}")


# ---------------------------------------------------------------------------- messages


class _Group:
    """The samples of one topic: ``t`` [s] and one list per key (NaN where a message
    lacks the key)."""

    def __init__(self) -> None:
        self.t: List[float] = []
        self.cols: Dict[str, List[float]] = {}

    def add(self, d: Dict[str, Any], where: "_Where") -> None:
        t: Any = d.get("t")
        if not _is_number(t) or not math.isfinite(float(t)):
            raise LogFileError(f"{where}: t = {t!r}: expected the sample time [s], a finite number")
        n = len(self.t)
        for k, v in d.items():
            if k in _ENVELOPE:
                continue
            if not _is_number(v):
                raise LogFileError(f"{where}: {k} = {v!r}: expected a number (SI units); a missing sample is left out of the message")
            col = self.cols.get(k)
            if col is None:
                col = self.cols[k] = [math.nan] * n
            col.append(float(v))
        self.t.append(float(t))
        for col in self.cols.values():
            if len(col) == n:
                col.append(math.nan)

    def arrays(self, topic: str, path: Path) -> Tuple[np.ndarray, Dict[str, np.ndarray]]:
        t = np.asarray(self.t, dtype=np.float64)
        bad = np.flatnonzero(~(np.diff(t) > 0))
        if bad.size:
            i = int(bad[0]) + 1
            raise LogFileError(
                f"{path}: {topic}: t must increase from message to message; message {i} has t = {_num(t[i])} s, "
                f"not after message {i - 1} (t = {_num(t[i - 1])} s)"
            )
        return t, {k: np.asarray(v, dtype=np.float64) for k, v in self.cols.items()}


@dataclass
class _Where:
    """A message's place, formatted only for an error."""

    path: Path
    topic: str
    index: int
    log_time: int
    layout: _Layout
    record: int

    def __str__(self) -> str:
        where = self.layout.describe(self.record)
        return f"{self.path}: {self.topic} message {self.index} (log_time {self.log_time} ns, in {where})"


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not JSON (a non-finite sample is never written)")


class _Reader:
    """Collects the records of a log: schemas, channels, metadata, sample groups, and
    the decoded messages of the topics in ``decode``."""

    def __init__(self, path: Path, layout: _Layout, decode: Sequence[str]) -> None:
        self.path = path
        self.layout = layout
        self.decode = set(decode)
        self.channels: Dict[int, Any] = {}
        self.topics: Dict[str, int] = {}
        self.metadata: Dict[str, Dict[str, str]] = {}
        self.groups: Dict[str, _Group] = {}
        self.decoded: Dict[str, List[Dict[str, Any]]] = {}

    def add(self, rec: Any, at: int) -> None:
        from mcap.records import Channel, Message, Metadata

        if isinstance(rec, Message):
            self._message(rec, at)
        elif isinstance(rec, Channel):
            self.channels.setdefault(rec.id, rec)
            self.topics.setdefault(rec.topic, 0)
        elif isinstance(rec, Metadata):
            self.metadata[rec.name] = dict(rec.metadata)

    def _message(self, msg: Any, at: int) -> None:
        ch = self.channels.get(msg.channel_id)
        if ch is None:
            raise LogFileError(
                f"{self.path}: a message in {self.layout.describe(at)} is on channel {msg.channel_id}, "
                f"which has no channel record before it"
            )
        topic = ch.topic
        index = self.topics[topic]
        self.topics[topic] = index + 1
        sample = topic.startswith(_SAMPLE_PREFIX) and topic != EVENT_TOPIC
        if not sample and topic not in self.decode:
            return
        where = _Where(self.path, topic, index, msg.log_time, self.layout, at)
        if ch.message_encoding != "json":
            raise LogFileError(f"{where}: message_encoding {ch.message_encoding!r}; popup logs are JSON (docs/logging.md)")
        d = self._json(msg.data, where)
        if sample:
            self.groups.setdefault(topic, _Group()).add(d, where)
        if topic in self.decode:
            self.decoded.setdefault(topic, []).append(d)

    @staticmethod
    def _json(data: bytes, where: _Where) -> Dict[str, Any]:
        try:
            d = json.loads(data, parse_constant=_reject_constant)
        except ValueError as e:  # JSONDecodeError and UnicodeDecodeError are ValueErrors
            raise LogFileError(f"{where}: not valid JSON ({e})") from None
        if not isinstance(d, dict):
            raise LogFileError(f"{where}: expected a JSON object, got {type(d).__name__}")
        return d

    def finish(self) -> RunLog:
        layout = self.layout
        parts = {tp: g.arrays(tp, self.path) for tp, g in _topic_order(self.groups).items()}
        _check_unique_columns(parts, self.path)
        md = self.metadata
        run_end = md.get("run_end")
        return RunLog(
            path=self.path,
            table=_merge(parts),
            events=_events(self.decoded.get(EVENT_TOPIC, []), self.path),
            metadata=md,
            experiment=_experiment(md.get("experiment"), self.path),
            scenario=md.get("popup", {}).get("scenario"),
            run_end=run_end,
            topics=dict(self.topics),
            log=self.decoded.get(LOG_TOPIC, []),
            complete=layout.footer,
            lost="" if layout.footer else _lost(layout, run_end, parts),
            _parts=parts,
            _layout=layout,
        )


def _topic_order(groups: Dict[str, _Group]) -> Dict[str, _Group]:
    """The documented topics first (docs/logging.md order), then the others as met;
    within a topic the documented keys first, then the others as met."""
    names = [t for t in SAMPLE_TOPICS if t in groups] + [t for t in groups if t not in SAMPLE_TOPICS]
    out: Dict[str, _Group] = {}
    for name in names:
        g = groups[name]
        known = SAMPLE_TOPICS.get(name, ("", ()))[1]
        keys = [k for k in known if k in g.cols] + [k for k in g.cols if k not in known]
        g.cols = {k: g.cols[k] for k in keys}
        out[name] = g
    return out


def _check_unique_columns(parts: Dict[str, Tuple[np.ndarray, Dict[str, np.ndarray]]], path: Path) -> None:
    seen: Dict[str, str] = {}
    for topic, (_, cols) in parts.items():
        for k in cols:
            if k in seen:
                raise LogFileError(f"{path}: column {k!r} is in both {seen[k]} and {topic}; each column belongs to one topic")
            seen[k] = topic


def _merge(parts: Dict[str, Tuple[np.ndarray, Dict[str, np.ndarray]]]) -> "pd.DataFrame":
    """One table on the union of the topics' ``t``, NaN where a topic has no sample."""
    ts = [t for t, _ in parts.values()]
    t_all = np.unique(np.concatenate(ts)) if ts else np.empty(0, dtype=np.float64)
    out: Dict[str, np.ndarray] = {"t": t_all}
    for t, cols in parts.values():
        rows = np.searchsorted(t_all, t)
        for k, v in cols.items():
            col = np.full(t_all.shape, np.nan)
            col[rows] = v
            out[k] = col
    return _pd().DataFrame(out)


def _events(msgs: List[Dict[str, Any]], path: Path) -> "pd.DataFrame":
    t = np.empty(len(msgs), dtype=np.float64)
    text: Dict[str, List[str]] = {k: [] for k in EVENT_COLUMNS[1:]}
    for i, d in enumerate(msgs):
        v: Any = d.get("t")
        if not _is_number(v):
            raise LogFileError(f"{path}: {EVENT_TOPIC} message {i}: t = {v!r}: expected the event time [s], a number")
        t[i] = float(v)
        for k, col in text.items():
            col.append(str(d.get(k, "")))
    return _pd().DataFrame({"t": t, **{k: _pd().Series(v, dtype=object) for k, v in text.items()}})


def _experiment(md: Optional[Dict[str, str]], path: Path) -> Dict[str, Any]:
    """The ``experiment`` metadata as an experiment.toml table (see :class:`RunLog`)."""
    if md is None:
        return {}
    if "toml" in md:
        from .io import parse_toml

        return parse_toml(md["toml"], f"{path}: metadata record experiment, key toml", LogFileError)
    return {k: _toml_value(v) for k, v in md.items()}


def _toml_value(text: str) -> Any:
    """One TOML value (``2.0``, ``"popup-lab"``, ``[1.0, 2.0]``, ``true``); text that is
    not a TOML value is the string itself (``popup-lab``)."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def _lost(lay: _Layout, run_end: Optional[Dict[str, str]], parts: Dict[str, Tuple[np.ndarray, Dict[str, np.ndarray]]]) -> str:
    """What a file cut short lost: where it ends, whether the run finished, the last
    sample time [s]."""
    from mcap.opcode import Opcode

    if lay.ops and lay.ops[-1] == Opcode.FOOTER:
        run = "only the closing magic is missing"
    elif run_end is None:
        run = "the run did not finish (no run_end record)"
    else:
        run = f"the run finished (run_end status = {run_end.get('status', '?')}); only the summary and index after it are lost"
    last = [float(t[-1]) for t, _ in parts.values() if t.size]
    at = f"last sample t = {_num(max(last))} s" if last else "no sample was read"
    return f"{lay.tail}: {run}; {at}"
