"""Measured runs: read and write the folder format of ``measured-run.md``.

A measured run is what a lab records on the real arm: a folder with

* ``experiment.toml``: ``format = "popup-run/1"``, the arm, the declared payload [kg]
  and pressures [Pa], gravity on/off, the replay mode (``"encoder"`` or
  ``"reference"``), optional ``description``, ``[initial]`` and ``[controller]``
  tables;
* ``measurements.csv`` (or ``measurements.parquet``, read only if ``pyarrow`` is
  installed): a header row, then one row per sample; ``t`` [s] is required and strictly
  increasing; every other column is optional, an empty cell or ``nan`` is a missing
  sample. SI units: rad, rad/s, N·m, m, m/s², Pa (see :data:`UNITS`).

:func:`read_run` checks everything the spec lists and refuses bad input with a
:class:`~popup.MeasuredRunError` that names the file, the row (1-based data row, plus
the file line for CSV) or column, and what was expected. Unknown column names and
unknown ``experiment.toml`` keys are a :class:`~popup.PopupWarning` (also kept in
:attr:`MeasuredRun.warnings`), not an error.

Nothing that is read is silently changed: :attr:`MeasuredRun.data` holds the cells as
read (every column as float64, missing cells NaN, no resampling, no row dropped). The
one place rows are left out is :meth:`MeasuredRun.encoder` (and
:meth:`MeasuredRun.reference`): a replay needs all three angles of a sample, so rows
with a missing ``q1``/``q2``/``q3`` are skipped, and that is said in a warning (at read
time for ``replay = "encoder"``). Fewer than two complete rows, or an infinite angle, is
an error.

:func:`write_run` writes the folder format (CSV), :func:`from_sim` turns a simulated
run (:class:`~popup.SimResult`) into the measured-run columns so it can be written and
compared like a measured one.

A measured run may also be a single ``.mcap`` file laid out as ``docs/logging.md`` (the
log a popup run writes, or a measured run from another tool): :func:`read_run` reads it
with :func:`popup.read_log`, takes the experiment from its ``experiment`` metadata and
the measured-run columns from its ``/popup/*`` sample topics, and checks both exactly as
it checks a folder. A file cut short (a killed run) is read up to its last complete
record, with a warning saying what was lost.
"""

from __future__ import annotations

import csv
import functools
import io as _stdio
import json
import math
import numbers
import os
import re
import sys
import warnings as _warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Dict, List, Mapping, Optional, Sequence, Tuple, Type, Union

import numpy as np

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.9/3.10 (pyproject: requires-python >= 3.9)
    import tomli as tomllib

from . import _core
from .exceptions import MeasuredRunError, PopupWarning
from .results import CHANNELS, SimResult

if TYPE_CHECKING:  # pandas is imported lazily: `import popup` stays fast
    import pandas as pd

__all__ = [
    "FORMAT",
    "MEASURED_COLUMNS",
    "UNITS",
    "REPLAY_MODES",
    "EXPERIMENT_KEYS",
    "MeasuredRun",
    "read_run",
    "write_run",
    "arm_limits",
    "from_sim",
    "sim_experiment",
]

PathLike = Union[str, "os.PathLike[str]"]

FORMAT: str = "popup-run/1"
"""The only ``format`` value this reader accepts."""

MEASURED_COLUMNS: Tuple[str, ...] = (
    "t",
    "q1", "q2", "q3",
    "dq1", "dq2", "dq3",
    "tau1", "tau2", "tau3",
    "ee_x", "ee_y", "ee_z",
    "imu1_ax", "imu1_ay", "imu1_az",
    "imu2_ax", "imu2_ay", "imu2_az",
    "p1", "p2",
    "ref_q1", "ref_q2", "ref_q3",
)  # fmt: skip
"""Column names of ``measurements.csv`` (measured-run.md), in spec order."""

UNITS: Dict[str, str] = {
    "t": "s",
    **{f"q{i}": "rad" for i in (1, 2, 3)},
    **{f"dq{i}": "rad/s" for i in (1, 2, 3)},
    **{f"tau{i}": "N·m" for i in (1, 2, 3)},
    **{f"ee_{a}": "m" for a in "xyz"},
    **{f"imu{k}_a{a}": "m/s²" for k in (1, 2) for a in "xyz"},
    "p1": "Pa",
    "p2": "Pa",
    **{f"ref_q{i}": "rad" for i in (1, 2, 3)},
}
"""Unit of every measured-run column."""

REPLAY_MODES: Tuple[str, ...] = ("encoder", "reference")
"""Values of ``replay`` in ``experiment.toml``."""

EXPERIMENT_KEYS: Tuple[str, ...] = (
    "format",
    "arm",
    "payload_kg",
    "pressure_pa",
    "gravity",
    "replay",
    "description",
    "initial",
    "controller",
)
"""Top-level keys of ``experiment.toml``; others are kept but warned about."""

_REQUIRED_KEYS: Tuple[str, ...] = ("format", "arm", "payload_kg", "pressure_pa")
_ENCODER_COLS: Tuple[str, ...] = ("q1", "q2", "q3")
_REFERENCE_COLS: Tuple[str, ...] = ("ref_q1", "ref_q2", "ref_q3")
_NA_TOKENS: List[str] = ["", "nan", "NaN", "NAN", "-nan", "-NaN"]
"""Cells read as a missing sample (the spec: an empty cell or ``nan``). Nothing else:
``NA``, ``None``, ``null`` are not numbers and are reported."""

_TOML = "experiment.toml"
_CSV = "measurements.csv"
_PARQUET = "measurements.parquet"


def _pd() -> Any:
    import pandas

    return pandas


# ---------------------------------------------------------------------------- MeasuredRun


@dataclass(eq=False)
class MeasuredRun:
    """One measured run: the experiment description and the measurements.

    Attributes
    ----------
    experiment : dict
        ``experiment.toml`` exactly as parsed (no defaults filled in).
    data : pandas.DataFrame
        The measurements as read: one column per file column, in file order, every
        column float64, missing cells NaN, a default RangeIndex (row ``i`` of the frame
        is data row ``i + 1`` of the file). SI units (:data:`UNITS`). For an MCAP run:
        ``t`` and the measured-run columns of its sample topics, merged on the union of
        their ``t`` (other channels, e.g. bending, stay in :func:`popup.read_log`).
    source : Path
        The run folder, or the ``.mcap`` file of an MCAP run.
    format : str
        ``"popup-run/1"``.
    arm : str
        As declared: a built-in arm name or a path relative to the run folder.
    payload_kg : float
        Declared payload at the tip of link 2 [kg].
    pressure_pa : (float, float)
        Declared pressure of link 1 and link 2 [Pa].
    gravity : bool
        Gravity on (default ``true``).
    replay : str
        ``"encoder"`` (default) or ``"reference"``.
    description : str
        Free text ("" when absent).
    initial, controller : dict or None
        The ``[initial]`` and ``[controller]`` tables, if given.
    warnings : list of str
        Every warning issued while reading (unknown columns or keys, rows skipped by
        the encoder replay, an MCAP file cut short).
    data_file : Path or None
        The measurements file read (``measurements.csv``/``.parquet`` or the ``.mcap``
        file).
    """

    experiment: Dict[str, Any]
    data: "pd.DataFrame"
    source: Path
    format: str
    arm: str
    payload_kg: float
    pressure_pa: Tuple[float, float]
    gravity: bool = True
    replay: str = "encoder"
    description: str = ""
    initial: Optional[Dict[str, Any]] = None
    controller: Optional[Dict[str, Any]] = None
    warnings: List[str] = field(default_factory=list)
    data_file: Optional[Path] = None
    _lines: Optional[np.ndarray] = field(default=None, repr=False)

    def __repr__(self) -> str:
        return (
            f"MeasuredRun(source={str(self.source)!r}, arm={self.arm!r}, payload_kg={self.payload_kg}, "
            f"pressure_pa={self.pressure_pa}, gravity={self.gravity}, replay={self.replay!r}, "
            f"rows={len(self)}, columns={self.columns})"
        )

    def __len__(self) -> int:
        return int(len(self.data))

    @property
    def columns(self) -> List[str]:
        """Column names of :attr:`data`, in file order."""
        return [str(c) for c in self.data.columns]

    @property
    def time(self) -> np.ndarray:
        """Sample times ``t`` [s], shape (N,), float64 (a copy)."""
        return np.array(self.data["t"].to_numpy(dtype=np.float64), copy=True)

    def channel(self, name: str) -> np.ndarray:
        """One column by its measured-run name (e.g. ``"ee_z"``) as a float64 array (a
        copy, NaN where missing), in the column's SI unit (:data:`UNITS`).

        Raises KeyError if the run has no such column.
        """
        if name not in self.data.columns:
            known = "" if name in MEASURED_COLUMNS else " (not a measured-run column either)"
            raise KeyError(f"{self._where()}: no column {name!r}{known}; this run has {self.columns}")
        return np.array(self.data[name].to_numpy(dtype=np.float64), copy=True)

    @property
    def arm_source(self) -> str:
        """What :class:`~popup.Model` gets as its arm: the built-in name, or the arm
        file's path resolved against the run folder (the ``.mcap`` file's folder)."""
        folder = self.source.parent if self.data_file == self.source else self.source
        return _resolve_arm(self.arm, folder)

    def to_pandas(self) -> "pd.DataFrame":
        """A copy of :attr:`data` indexed by ``t`` [s] (like :meth:`SimResult.to_pandas`),
        with the experiment in ``.attrs["experiment"]``."""
        df = self.data.set_index("t", drop=True)
        df.attrs["experiment"] = dict(self.experiment)
        df.attrs["source"] = str(self.source)
        return df

    def model(self, **kwargs: Any) -> Any:
        """A :class:`~popup.Model` of the declared experiment: the run's arm,
        ``payload_kg`` [kg], ``pressure_pa`` [Pa] and ``gravity``. Keyword arguments go
        to :class:`~popup.Model` (``dt``, ``integrator``, ``disable``, or a
        ``payload_kg``/``pressure_pa``/``gravity`` that overrides the declared one). For
        ``replay = "reference"`` the default ``dt`` is the controller period."""
        from .model import Model

        args: Dict[str, Any] = {
            "payload_kg": self.payload_kg,
            "pressure_pa": self.pressure_pa,
            "gravity": self.gravity,
        }
        if self.replay == "reference" and "dt" not in kwargs:
            # the controller period must be a whole multiple of the physics step
            args["dt"] = 1.0 / float((self.controller or {}).get("rate_hz", 10_000.0))
        args.update(kwargs)
        arm = args.pop("arm", self.arm_source)
        return Model(arm, **args)

    def encoder(self) -> Tuple[np.ndarray, np.ndarray]:
        """The encoder samples for a replay: ``(t [s] (M,), q [rad] (M, 3))``.

        Only rows with ``q1``, ``q2`` and ``q3`` all present are returned; skipped rows
        are named in a warning (issued once, kept in :attr:`warnings`). The replay
        interpolates between the remaining samples. Raises
        :class:`~popup.MeasuredRunError` if a q column is absent, an angle is infinite,
        or fewer than 2 complete rows remain.
        """
        return self._angles(_ENCODER_COLS, "the encoder replay")

    def reference(self) -> Tuple[np.ndarray, np.ndarray]:
        """The position reference for ``replay = "reference"``: ``(t [s] (M,), ref_q
        [rad] (M, 3))``, with the same rules as :meth:`encoder`."""
        return self._angles(_REFERENCE_COLS, "the reference replay")

    def check(self) -> None:
        """Check :attr:`data` again as :func:`read_run` did (time strictly increasing,
        plausible values per :data:`LIMITS`, gaps): raises
        :class:`~popup.MeasuredRunError` naming the row and column (data changed after
        reading is checked too). Diagnosis calls it first, so a data glitch is never
        blamed on missing physics."""
        lines = self._lines if self._lines is not None and len(self._lines) == len(self.data) else None
        _check_data(self.data, self._where(), lines, [], _run_limits(self.arm, self._folder(), self._where(), []))

    # -------------------------------------------------------------- helpers
    def _folder(self) -> Path:
        return self.source.parent if self.data_file == self.source else self.source

    def _where(self) -> str:
        return str(self.data_file if self.data_file is not None else self.source)

    def _angles(self, cols: Sequence[str], purpose: str) -> Tuple[np.ndarray, np.ndarray]:
        missing = [c for c in cols if c not in self.data.columns]
        if missing:
            raise MeasuredRunError(
                f"{self._where()}: {purpose} needs columns {', '.join(cols)}; missing {', '.join(missing)} "
                f"(columns present: {', '.join(self.columns)})"
            )
        ok, note = _complete_rows(self.data, cols, self._where(), self._lines, purpose)
        if note is not None and note not in self.warnings:
            self.warnings.append(note)
            _warnings.warn(note, PopupWarning, stacklevel=3)
        t = self.data["t"].to_numpy(dtype=np.float64)[ok]
        q = self.data[list(cols)].to_numpy(dtype=np.float64)[ok]
        return np.ascontiguousarray(t), np.ascontiguousarray(q)


# ---------------------------------------------------------------------------- reading


def read_run(path: PathLike) -> MeasuredRun:
    """Read a measured run.

    Parameters
    ----------
    path : str or path
        The run folder (with ``experiment.toml`` and ``measurements.csv`` or
        ``measurements.parquet``), or one of those two files inside it, or a ``.mcap``
        log (``docs/logging.md``): its ``experiment`` metadata is the experiment (arm
        paths relative to the file's folder), its ``/popup/*`` sample topics give the
        measured-run columns.

    Returns
    -------
    MeasuredRun

    Raises
    ------
    popup.MeasuredRunError
        Anything the spec calls bad input (the message names the file, the row or
        column and what was expected). For a ``.mcap`` file, a
        :class:`~popup.LogFileError` (a MeasuredRunError) when the file cannot be read
        (not MCAP, a corrupted record, no ``experiment`` metadata).

    Warns
    -----
    popup.PopupWarning
        Unknown column names, unknown ``experiment.toml`` keys, encoder rows skipped for
        a missing angle, an MCAP file cut short (what was lost). The same texts are in
        :attr:`MeasuredRun.warnings`.
    """
    p = Path(os.fspath(path))
    if p.suffix.lower() == ".mcap" and not p.is_dir():
        return _read_mcap(p)
    if p.is_file():
        if p.name not in (_TOML, _CSV, _PARQUET):
            raise MeasuredRunError(f"{p}: expected a run folder (with {_TOML} and {_CSV} or {_PARQUET}), got a file")
        p = p.parent
    elif not p.exists():
        raise MeasuredRunError(f"{p}: no such run folder (expected a folder with {_TOML} and {_CSV} or {_PARQUET})")
    folder = p
    toml_path = folder / _TOML
    if not toml_path.is_file():
        raise MeasuredRunError(f"{toml_path}: missing; a run folder needs {_TOML} (format, arm, payload_kg, pressure_pa, ...)")
    warns: List[str] = []
    exp = _load_toml(toml_path)
    typed = _check_experiment(exp, str(toml_path), folder, warns)

    csv_path, pq_path = folder / _CSV, folder / _PARQUET
    if csv_path.exists() and pq_path.exists():
        raise MeasuredRunError(f"{folder}: both {_CSV} and {_PARQUET} are present; keep exactly one measurements file")
    lines: Optional[np.ndarray]
    if csv_path.is_file():
        data_path = csv_path
        df, lines = _read_csv(csv_path)
    elif pq_path.is_file():
        data_path = pq_path
        df, lines = _read_parquet(pq_path), None
    else:
        raise MeasuredRunError(f"{folder}: missing measurements file; expected {_CSV} (or {_PARQUET})")

    lim = _run_limits(typed["arm"], folder, str(toml_path), warns)
    df = _check_data(df, str(data_path), lines, warns, lim)
    _check_replay(typed, df, str(toml_path), str(data_path), lines, warns)
    for w in warns:
        _warnings.warn(w, PopupWarning, stacklevel=2)
    return MeasuredRun(
        experiment=exp,
        data=df,
        source=folder,
        warnings=warns,
        data_file=data_path,
        _lines=lines,
        **typed,
    )


def _read_mcap(p: Path) -> MeasuredRun:
    """A measured run from a ``.mcap`` log: the same checks as a run folder."""
    from .exceptions import LogFileError
    from .mcaplog import read_log

    log = read_log(p)
    where_exp = f"{p} (metadata record experiment)"
    # a file cut short says so (and where) in every error about what it lacks
    cut = "" if log.complete else f"the file was cut short ({log.lost}), and it has "
    if "experiment" not in log.metadata:
        raise LogFileError(
            f"{p}: {cut}no experiment metadata record; a measured-run MCAP needs one (key toml with a complete "
            f"{_TOML}, or one key per experiment key: {', '.join(_REQUIRED_KEYS)}, ...; docs/logging.md)"
        )
    warns: List[str] = [] if log.complete else [f"{p}: the file was cut short: {log.lost}"]
    typed = _check_experiment(log.experiment, where_exp, p.parent, warns)
    cols = [c for c in log.columns if c in MEASURED_COLUMNS and c != "t"]
    if not cols:
        raise LogFileError(
            f"{p}: {cut}no measured-run samples: none of the topics {', '.join(log.topics) or '(none)'} has a "
            f"measured-run column ({', '.join(MEASURED_COLUMNS[1:])})"
        )
    lim = _run_limits(typed["arm"], p.parent, where_exp, warns)
    df = _check_data(log._frame(cols), str(p), None, warns, lim)
    _check_replay(typed, df, where_exp, str(p), None, warns)
    for w in warns:
        _warnings.warn(w, PopupWarning, stacklevel=3)
    return MeasuredRun(experiment=log.experiment, data=df, source=p, warnings=warns, data_file=p, **typed)


def _load_toml(path: Path) -> Dict[str, Any]:
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as e:
        raise MeasuredRunError(f"{path}: not UTF-8 text (byte {e.start}); TOML files are UTF-8") from None
    except OSError as e:
        raise MeasuredRunError(f"{path}: cannot be read ({e.strerror})") from None
    return parse_toml(text, str(path))


def parse_toml(text: str, where: str, error: Type[MeasuredRunError] = MeasuredRunError) -> Dict[str, Any]:
    """Parse TOML text; a syntax error raises ``error`` naming ``where`` and the line."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        msg = str(e)
        m = re.search(r"line (\d+)", msg)
        line = ""
        if m is not None:
            n = int(m.group(1))
            src = text.splitlines()
            if 1 <= n <= len(src):
                line = f"; line {n}: {src[n - 1]!r}"
            else:
                line = f"; line {n} (end of file)"
        raise error(f"{where}: malformed TOML: {msg}{line}") from None


def _is_number(v: Any) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))


def _check_experiment(exp: Mapping[str, Any], where: str, folder: Optional[Path], warns: List[str]) -> Dict[str, Any]:
    """Validate an experiment table; return the typed fields of :class:`MeasuredRun`.

    ``folder`` is the run folder the arm path is relative to; None skips the arm-file
    existence check (writing a run whose arm file is copied in later).
    """
    if not isinstance(exp, Mapping):
        raise MeasuredRunError(f"{where}: expected a table of experiment settings, got {type(exp).__name__}")
    for k in exp:
        if not isinstance(k, str):
            raise MeasuredRunError(f"{where}: key {k!r} is not a string")
    if "format" not in exp:
        raise MeasuredRunError(f'{where}: missing key format; expected format = "{FORMAT}" as the first line')
    fmt = exp["format"]
    if fmt != FORMAT:
        raise MeasuredRunError(f'{where}: format = {fmt!r} is not supported; expected format = "{FORMAT}"')
    for k in _REQUIRED_KEYS:
        if k not in exp:
            raise MeasuredRunError(f"{where}: missing key {k}; required keys are {', '.join(_REQUIRED_KEYS)}")
    unknown = [k for k in exp if k not in EXPERIMENT_KEYS]
    if unknown:
        warns.append(
            f"{where}: unknown key{'s' if len(unknown) > 1 else ''} {', '.join(repr(k) for k in unknown)} "
            f"(known keys: {', '.join(EXPERIMENT_KEYS)}); kept in .experiment, not used"
        )

    arm = exp["arm"]
    if not isinstance(arm, str) or not arm.strip():
        raise MeasuredRunError(f"{where}: arm = {arm!r}: expected a built-in arm name or a path to an arm file (a string)")
    if folder is not None and arm not in _builtin_arms():
        cand = Path(_resolve_arm(arm, folder))
        if not cand.is_file():
            raise MeasuredRunError(
                f"{where}: unknown arm {arm!r}: not a built-in arm (built-ins: {', '.join(_builtin_arms())}) "
                f"and no arm file {cand}"
            )

    pay = exp["payload_kg"]
    if not _is_number(pay) or not math.isfinite(float(pay)) or float(pay) < 0:
        raise MeasuredRunError(f"{where}: payload_kg = {pay!r}: expected a finite number >= 0 [kg]")

    pres = exp["pressure_pa"]
    if not isinstance(pres, (list, tuple)) or len(pres) != 2:
        raise MeasuredRunError(
            f"{where}: pressure_pa = {pres!r}: expected a list of 2 numbers [Pa] (link 1, link 2), e.g. [30000.0, 30000.0]"
        )
    for i, v in enumerate(pres):
        if not _is_number(v) or not math.isfinite(float(v)) or float(v) < 0:
            raise MeasuredRunError(f"{where}: pressure_pa[{i}] (link {i + 1}) = {v!r}: expected a finite number >= 0 [Pa]")

    grav = exp.get("gravity", True)
    if not isinstance(grav, (bool, np.bool_)):
        raise MeasuredRunError(f"{where}: gravity = {grav!r}: expected true or false")

    replay = exp.get("replay", "encoder")
    if replay not in REPLAY_MODES:
        raise MeasuredRunError(f"{where}: replay = {replay!r}: expected one of {', '.join(repr(m) for m in REPLAY_MODES)}")

    desc = exp.get("description", "")
    if not isinstance(desc, str):
        raise MeasuredRunError(f"{where}: description = {desc!r}: expected a string")

    tables: Dict[str, Optional[Dict[str, Any]]] = {}
    for k in ("initial", "controller"):
        v = exp.get(k)
        if v is not None and not isinstance(v, Mapping):
            raise MeasuredRunError(f"{where}: {k} = {v!r}: expected a [{k}] table")
        tables[k] = None if v is None else dict(v)
    if replay == "reference" and tables["controller"] is None:
        raise MeasuredRunError(f'{where}: replay = "reference" needs a [controller] table with the controller settings')

    return {
        "format": str(fmt),
        "arm": arm,
        "payload_kg": float(pay),
        "pressure_pa": (float(pres[0]), float(pres[1])),
        "gravity": bool(grav),
        "replay": str(replay),
        "description": desc,
        "initial": tables["initial"],
        "controller": tables["controller"],
    }


def _builtin_arms() -> List[str]:
    return list(_core.Arm.builtin_names())


def _resolve_arm(arm: str, folder: Path) -> str:
    if arm in _builtin_arms():
        return arm
    p = Path(arm).expanduser()
    return str(p if p.is_absolute() else folder / p)


def _read_csv(path: Path) -> Tuple["pd.DataFrame", np.ndarray]:
    """Read measurements.csv: a structural pass with :mod:`csv` (header, ragged rows,
    file line of every data row), then pandas for the values."""
    pd = _pd()
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise MeasuredRunError(f"{path}: not UTF-8 text (byte {e.start}); expected a UTF-8 CSV file") from None
    except OSError as e:
        raise MeasuredRunError(f"{path}: cannot be read ({e.strerror})") from None
    if not text.strip():
        raise MeasuredRunError(f"{path}: the file is empty; expected a header row (t, q1, q2, q3, ...) and one row per sample")

    header: Optional[List[str]] = None
    lines: List[int] = []
    reader = csv.reader(_stdio.StringIO(text), skipinitialspace=True)
    prev = 0
    try:
        for row in reader:
            start, prev = prev + 1, reader.line_num
            if not row or (len(row) == 1 and not row[0].strip()):
                continue  # blank line: pandas skips it too
            if header is None:
                header = row
                _check_header(header, str(path), f"line {start} (header)")
                continue
            if len(row) != len(header):
                raise MeasuredRunError(
                    f"{path}: row {len(lines) + 1} (line {start}) has {len(row)} field{'s' if len(row) != 1 else ''}, "
                    f"but the header has {len(header)} columns ({', '.join(header)}); every row needs one value "
                    f"per column (an empty cell for a missing sample)"
                )
            lines.append(start)
    except csv.Error as e:
        raise MeasuredRunError(f"{path}: line {reader.line_num}: not valid CSV ({e})") from None
    if header is None:  # pragma: no cover - text.strip() was non-empty
        raise MeasuredRunError(f"{path}: no header row")
    if not lines:
        raise MeasuredRunError(f"{path}: no data rows after the header; expected one row per sample")

    kw: Dict[str, Any] = dict(
        sep=",",
        header=0,
        index_col=False,
        keep_default_na=False,
        na_values=_NA_TOKENS,
        skipinitialspace=True,
        skip_blank_lines=True,
        low_memory=False,
    )
    if int(pd.__version__.split(".")[0]) < 3:
        kw["float_precision"] = "round_trip"  # pandas >= 3 round-trips by default (and deprecates this)
    try:
        df = pd.read_csv(_stdio.StringIO(text), **kw)
    except (ValueError, pd.errors.ParserError) as e:
        raise MeasuredRunError(f"{path}: cannot be parsed as CSV ({e})") from None
    if len(df) != len(lines) or [str(c) for c in df.columns] != header:
        raise MeasuredRunError(  # pragma: no cover - defensive: the two passes disagree
            f"{path}: the CSV layout is ambiguous (pandas read {len(df)} rows and columns {list(df.columns)}, "
            f"the file has {len(lines)} data rows and columns {header})"
        )
    bad = [c for c in df.columns if not _numeric_ok(df[c])]
    if bad:
        # error path: re-read the offending columns as text to quote the cell exactly
        raw = pd.read_csv(_stdio.StringIO(text), **{**kw, "dtype": str, "usecols": bad})
        _raise_first_bad_cell(raw, bad, str(path), np.asarray(lines))
    return df, np.asarray(lines, dtype=np.int64)


def _check_header(header: Sequence[str], where: str, label: str) -> None:
    seen: Dict[str, int] = {}
    for j, name in enumerate(header):
        if not name.strip():
            raise MeasuredRunError(
                f"{where}: {label}: column {j + 1} has an empty name (a trailing comma?); "
                f"every column needs a name such as t, q1, ee_z"
            )
        if name in seen:
            raise MeasuredRunError(
                f"{where}: {label}: column name {name!r} appears twice (columns {seen[name] + 1} and {j + 1})"
            )
        seen[name] = j


def _read_parquet(path: Path) -> "pd.DataFrame":
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        raise MeasuredRunError(
            f"{path}: reading {_PARQUET} needs pyarrow, which is not installed; "
            f"install it (pip install pyarrow) or store the measurements as {_CSV}"
        ) from None
    pd = _pd()
    try:
        df = pd.read_parquet(path, engine="pyarrow")
    except Exception as e:  # pyarrow raises its own error types
        raise MeasuredRunError(f"{path}: cannot be read as Parquet ({type(e).__name__}: {e})") from None
    if not isinstance(df.index, pd.RangeIndex) or df.index.name is not None:
        df = df.reset_index()  # an index stored with the table (e.g. t) is a column of the file
    if len(df.columns) == 0:
        raise MeasuredRunError(f"{path}: the file has no columns; expected t and the measured channels")
    _check_header([str(c) for c in df.columns], str(path), "header")
    return df


def _numeric_ok(s: Any) -> bool:
    pd = _pd()
    t = pd.api.types
    return bool(t.is_numeric_dtype(s) and not t.is_bool_dtype(s) and not t.is_complex_dtype(s))


def _num(x: Any) -> str:
    """A float as Python writes it (shortest round-trip text, not np.float64(...))."""
    return repr(float(x))


def _row(i: int, lines: Optional[np.ndarray]) -> str:
    """Data row ``i`` (0-based) as text: 1-based, plus the file line when known."""
    return f"row {i + 1}" if lines is None else f"row {i + 1} (line {int(lines[i])})"


def _raise_first_bad_cell(df: "pd.DataFrame", cols: Sequence[Any], where: str, lines: Optional[np.ndarray]) -> None:
    """Raise naming the first non-numeric cell (in row order) of ``cols``."""
    pd = _pd()
    best: Optional[Tuple[int, int, str]] = None
    for j, c in enumerate(cols):
        s = df[c]
        if pd.api.types.is_bool_dtype(s) or pd.api.types.is_complex_dtype(s):
            cand: Optional[int] = 0
        else:
            try:
                num = pd.to_numeric(s, errors="coerce")
                bad = num.isna().to_numpy() & s.notna().to_numpy()
                if s.dtype == object:  # True/False in an object column: not a number either
                    bad |= s.map(lambda v: isinstance(v, (bool, np.bool_))).to_numpy(dtype=bool)
                idx = np.flatnonzero(bad)
                cand = int(idx[0]) if idx.size else None
            except (TypeError, ValueError):
                cand = 0
        if cand is not None and (best is None or cand < best[0]):
            best = (cand, j, str(s.iloc[cand]))
    if best is None:
        c = cols[0]
        raise MeasuredRunError(f"{where}: column {c!r} has dtype {df[c].dtype}; expected numbers in SI units ({UNITS.get(str(c), 'SI')})")
    i, j, text = best
    raise MeasuredRunError(
        f"{where}: {_row(i, lines)}, column {cols[j]!r}: {text!r} is not a number; expected a number "
        f"in {UNITS.get(str(cols[j]), 'SI units')}, or an empty cell / nan for a missing sample"
    )


def _check_data(df: "pd.DataFrame", where: str, lines: Optional[np.ndarray], warns: List[str], limits: Optional[_Limits] = None) -> "pd.DataFrame":
    """Validate the measurements (plausibility per ``limits``, default :data:`LIMITS`);
    return them with every column as float64 (values unchanged: integers are exact in
    float64 up to 2**53)."""
    pd = _pd()
    names = list(df.columns)
    for j, c in enumerate(names):
        if not isinstance(c, str):
            raise MeasuredRunError(f"{where}: column {j + 1} name {c!r} is not a string")
    if lines is None:  # the CSV header was checked with its line number
        _check_header([str(c) for c in names], where, "header")
    if len(names) == 0:
        raise MeasuredRunError(f"{where}: no columns; expected at least t [s]")
    if "t" not in names:
        raise MeasuredRunError(f"{where}: missing column t (time since the start of the run [s]); columns are {', '.join(names)}")
    if len(df) == 0:
        raise MeasuredRunError(f"{where}: no data rows; expected one row per sample")
    bad = [c for c in names if not _numeric_ok(df[c])]
    if bad:
        _raise_first_bad_cell(df, bad, where, lines)
    out = pd.DataFrame({c: df[c].to_numpy(dtype=np.float64, na_value=np.nan) for c in names})

    t = out["t"].to_numpy()
    nan = np.flatnonzero(~np.isfinite(t))
    if nan.size:
        i = int(nan[0])
        what = "missing" if np.isnan(t[i]) else _num(t[i])
        raise MeasuredRunError(f"{where}: {_row(i, lines)}, column t: {what}; every row needs a finite time t [s]")
    d = np.diff(t)
    bad_t = np.flatnonzero(~(d > 0))
    if bad_t.size:
        i = int(bad_t[0]) + 1
        raise MeasuredRunError(
            f"{where}: column t must be strictly increasing, but {_row(i, lines)} has t = {_num(t[i])} s, "
            f"not after {_row(i - 1, lines)} (t = {_num(t[i - 1])} s)"
        )

    _check_plausible(out, where, lines, warns, LIMITS if limits is None else limits)

    unknown = [c for c in names if c not in MEASURED_COLUMNS]
    if unknown:
        hints = [f"{c!r} (did you mean {c.strip()!r}?)" if c.strip() in MEASURED_COLUMNS else repr(c) for c in unknown]
        warns.append(
            f"{where}: unknown column{'s' if len(unknown) > 1 else ''} {', '.join(hints)}; kept in .data but not "
            f"used (measured-run columns: {', '.join(MEASURED_COLUMNS)})"
        )
    return out


_Limits = Dict[str, Tuple[str, float, float, float, str]]


@functools.lru_cache(maxsize=16)
def _limits_of(arm_toml: str) -> Tuple[Tuple[str, Tuple[str, float, float, float, str]], ...]:
    rows = _core.Arm.from_toml(arm_toml, "<arm>").channel_limits()
    return tuple((c, (unit, lo, warn, err, advice)) for cols, unit, lo, warn, err, advice in rows for c in cols)


def arm_limits(arm: Any = "popup-lab") -> _Limits:
    """Plausibility limits of the measured-run columns for ``arm`` (an :class:`~popup.Arm`,
    a name or an arm file, as :func:`~popup.load_arm` takes): ``column -> (unit, min,
    warn_abs, error_abs, advice)``. The factors are the engine's one registry
    (``popup_core::limits``, exposed as ``popup._core.CHANNEL_LIMITS``); torque limits are
    factors of the arm's drive limits (``motors.tau_max_nm``), IMU limits factors of the
    specific force the arm can reach (``Arm.reach()``: drive torques and link collapse
    moments through its mass matrix, plus gravity). :func:`read_run` refuses values beyond
    ``error_abs`` (or below ``min``) and warns about values beyond ``warn_abs``."""
    from .model import load_arm

    return dict(_limits_of(load_arm(arm).to_toml()))


LIMITS: _Limits = arm_limits("popup-lab")
"""Plausibility limits of the measured-run columns for the built-in ``popup-lab`` arm
(:func:`arm_limits`); a run is checked against the limits of its own arm."""


def _run_limits(arm: str, folder: Optional[Path], where: str, warns: List[str]) -> _Limits:
    """The limits of a run's arm (its path resolved against ``folder``); an arm that cannot
    be loaded (its error comes when a model is built) gives popup-lab's, with a warning."""
    from .exceptions import PopupError

    err: Optional[BaseException] = None
    for cand in ([_resolve_arm(arm, folder)] if folder is not None else []) + [arm]:
        try:
            return arm_limits(cand)
        except (PopupError, OSError, ValueError) as e:
            err = err or e
    warns.append(
        f"{where}: arm {arm!r} could not be loaded ({err}); the measurements were checked against the plausibility "
        f"limits of popup-lab"
    )
    return LIMITS


def _check_plausible(df: "pd.DataFrame", where: str, lines: Optional[np.ndarray], warns: List[str], limits: _Limits) -> None:
    """Refuse values no arm produces, warn about values that look wrong (time gaps far
    beyond the median step, angles that look like degrees, ...), each naming the row and
    column and saying what to do. Limits: ``limits`` (:func:`arm_limits`) and
    ``_core.GAP_*_STEPS``."""
    for c in df.columns:
        lim = limits.get(str(c))
        if lim is None:
            continue
        unit, lo, warn, err, advice = lim
        x = df[c].to_numpy(dtype=np.float64)
        with np.errstate(invalid="ignore"):
            bad = np.flatnonzero(np.isinf(x) | (np.abs(x) > err) | (x < lo))
        if bad.size:
            i = int(bad[0])
            more = f" (and {bad.size - 1} more row{'s' if bad.size > 2 else ''})" if bad.size > 1 else ""
            if np.isinf(x[i]):
                raise MeasuredRunError(
                    f"{where}: {_row(i, lines)}, column {c}: {_num(x[i])} is not finite{more}; a measured value is a finite "
                    f"number in {unit}, or an empty cell / nan for a missing sample"
                )
            raise MeasuredRunError(
                f"{where}: {_row(i, lines)}, column {c}: {_num(x[i])} {unit} is not plausible{more}; the limit is "
                f"{err:.4g} {unit} in magnitude{'' if lo == -math.inf else f' and at least {lo:.4g} {unit}'}: {advice}"
            )
        with np.errstate(invalid="ignore"):
            odd = np.flatnonzero(np.abs(x) > warn)
        if odd.size:
            i = int(odd[0])
            warns.append(
                f"{where}: column {c}: {odd.size} value{'s' if odd.size > 1 else ''} beyond {warn:.4g} {unit} in "
                f"magnitude (first: {_row(i, lines)}, {_num(x[i])} {unit}): {advice}"
            )
    t = df["t"].to_numpy(dtype=np.float64)
    if t.size >= 3:
        d = np.diff(t)
        med = float(np.median(d))
        worst = int(np.argmax(d))
        if med > 0 and d[worst] > _core.GAP_ERROR_STEPS * med:
            raise MeasuredRunError(
                f"{where}: {_row(worst + 1, lines)}, column t: {_num(t[worst + 1])} s comes {_num(float(d[worst]))} s after "
                f"{_row(worst, lines)} (t = {_num(t[worst])} s), {d[worst] / med:.3g} times the median step "
                f"{_num(med)} s (the limit is {_core.GAP_ERROR_STEPS:g} times): a time stamp glitch or a gap no replay can "
                f"bridge; fix the time stamp, or split the run at the gap"
            )
        gaps = np.flatnonzero(d > _core.GAP_WARN_STEPS * med) if med > 0 else np.zeros(0, dtype=int)
        if gaps.size:
            i = int(gaps[0])
            warns.append(
                f"{where}: column t: {gaps.size} gap{'s' if gaps.size > 1 else ''} longer than {_core.GAP_WARN_STEPS:g} median "
                f"steps ({_num(med)} s), the first before {_ranges(gaps + 1, lines, limit=3).split(',')[0]} "
                f"({_num(float(d[i]))} s); samples were lost there and the replay interpolates across the gap"
            )


def _ranges(idx: np.ndarray, lines: Optional[np.ndarray], limit: int = 5) -> str:
    """0-based row indices as '3, 7-9 (lines 8-10), ...' (1-based rows)."""
    parts: List[str] = []
    start = prev = int(idx[0])
    groups: List[Tuple[int, int]] = []
    for k in idx[1:]:
        k = int(k)
        if k == prev + 1:
            prev = k
            continue
        groups.append((start, prev))
        start = prev = k
    groups.append((start, prev))
    for a, b in groups[:limit]:
        s = f"{a + 1}" if a == b else f"{a + 1}-{b + 1}"
        if lines is not None:
            s += f" (line {int(lines[a])})" if a == b else f" (lines {int(lines[a])}-{int(lines[b])})"
        parts.append(s)
    more = "" if len(groups) <= limit else f", ... ({len(groups) - limit} more gaps)"
    return ", ".join(parts) + more


def _complete_rows(
    df: "pd.DataFrame", cols: Sequence[str], where: str, lines: Optional[np.ndarray], purpose: str
) -> Tuple[np.ndarray, Optional[str]]:
    """Rows with all of ``cols`` present: (mask, warning text or None). Raises if an
    angle is infinite or fewer than 2 rows are complete."""
    block = df[list(cols)].to_numpy(dtype=np.float64)
    inf = np.argwhere(np.isinf(block))
    if inf.size:
        i, j = (int(x) for x in inf[0])
        raise MeasuredRunError(f"{where}: {_row(i, lines)}, column {cols[j]}: {_num(block[i, j])} is not finite; {purpose} needs finite angles [rad]")
    ok = ~np.isnan(block).any(axis=1)
    n, n_ok = len(ok), int(ok.sum())
    per_col = ", ".join(f"{c} in {int(np.isnan(block[:, j]).sum())}" for j, c in enumerate(cols) if np.isnan(block[:, j]).any())
    if n_ok < 2:
        raise MeasuredRunError(
            f"{where}: {purpose} needs at least 2 rows with {', '.join(cols)} all present; found {n_ok} of {n} "
            f"rows (missing: {per_col} rows)"
        )
    if n_ok == n:
        return ok, None
    gaps = _ranges(np.flatnonzero(~ok), lines)
    t = df["t"].to_numpy(dtype=np.float64)
    first = int(np.flatnonzero(ok)[0])
    last = int(np.flatnonzero(ok)[-1])
    span = ""
    if first > 0 or last < n - 1:
        span = f"; the replay covers t = {_num(t[first])} to {_num(t[last])} s, not the whole run ({_num(t[0])} to {_num(t[-1])} s)"
    note = (
        f"{where}: {n - n_ok} of {n} rows have a missing {'/'.join(cols)} (missing: {per_col} rows; rows {gaps}); "
        f"{purpose} skips them and interpolates between the {n_ok} complete rows{span}"
    )
    return ok, note


def _check_replay(
    typed: Mapping[str, Any], df: "pd.DataFrame", where_toml: str, where_data: str, lines: Optional[np.ndarray], warns: List[str]
) -> None:
    mode = typed["replay"]
    cols = _ENCODER_COLS if mode == "encoder" else _REFERENCE_COLS
    missing = [c for c in cols if c not in df.columns]
    if missing:
        raise MeasuredRunError(
            f'{where_data}: replay = "{mode}" (in {where_toml}) needs columns {", ".join(cols)}; '
            f"missing {', '.join(missing)} (columns present: {', '.join(map(str, df.columns))})"
        )
    purpose = "the encoder replay" if mode == "encoder" else "the reference replay"
    _, note = _complete_rows(df, cols, where_data, lines, purpose)
    if note is not None:
        warns.append(note)


# ---------------------------------------------------------------------------- writing


def write_run(
    path: PathLike,
    experiment: Mapping[str, Any],
    data: Union["pd.DataFrame", Mapping[str, Any]],
    *,
    overwrite: bool = False,
) -> Path:
    """Write a measured run as a folder with ``experiment.toml`` and ``measurements.csv``.

    Parameters
    ----------
    path : str or path
        The run folder (created with its parents if needed).
    experiment : mapping
        The ``experiment.toml`` content (``format``, ``arm``, ``payload_kg`` [kg],
        ``pressure_pa`` [Pa] (2 values), optional ``gravity``, ``replay``,
        ``description``, ``[initial]``, ``[controller]``). Tuples and numpy scalars are
        written as TOML arrays and numbers.
    data : DataFrame or mapping of 1-D arrays
        The measurements, one column per channel (SI units, :data:`UNITS`), ``t`` [s]
        required; NaN is written as an empty cell. A DataFrame indexed by ``t`` (as
        :meth:`SimResult.to_pandas` gives) has its index written as the ``t`` column;
        any other index is not written.
        Floats are written with full precision, so :func:`read_run` gives back the same
        values.
    overwrite : bool
        Replace an existing run in ``path`` (default: refuse with FileExistsError).

    Returns
    -------
    Path
        The run folder.

    The experiment and the data are checked as :func:`read_run` checks them (except
    that an arm file need not exist yet) before anything is written, so a bad run
    raises :class:`~popup.MeasuredRunError` and leaves no files behind.
    """
    pd = _pd()
    folder = Path(os.fspath(path))
    exp = _plain(dict(experiment), "experiment")
    df = _as_frame(data)
    warns: List[str] = []
    typed = _check_experiment(exp, "write_run experiment", None, warns)
    _check_data(df, "write_run data", None, warns, _run_limits(typed["arm"], None, "write_run experiment", warns))
    _check_replay(typed, df, "write_run experiment", "write_run data", None, warns)
    for w in warns:
        _warnings.warn(w, PopupWarning, stacklevel=2)

    existing = [folder / n for n in (_TOML, _CSV, _PARQUET) if (folder / n).exists()]
    if existing and not overwrite:
        raise FileExistsError(f"{folder}: already holds a run ({', '.join(p.name for p in existing)}); pass overwrite=True to replace it")
    folder.mkdir(parents=True, exist_ok=True)
    for p in existing:
        p.unlink()
    (folder / _TOML).write_text(_toml_dumps(exp), encoding="utf-8")
    out = pd.DataFrame({c: df[c].to_numpy() for c in df.columns})
    out.to_csv(folder / _CSV, index=False, na_rep="", lineterminator="\n")
    return folder


def _as_frame(data: Any) -> "pd.DataFrame":
    pd = _pd()
    if isinstance(data, pd.DataFrame):
        df = data
        if "t" not in df.columns and df.index.name == "t":
            df = df.reset_index()
        return df
    if not isinstance(data, Mapping):
        raise TypeError(f"write_run data: expected a DataFrame or a mapping of 1-D arrays, got {type(data).__name__}")
    cols: Dict[str, np.ndarray] = {}
    n0: Optional[Tuple[str, int]] = None
    for k, v in data.items():
        a = np.asarray(v)
        if a.ndim != 1:
            raise MeasuredRunError(f"write_run data: column {k!r} has shape {a.shape}; expected a 1-D array (one value per sample)")
        if n0 is None:
            n0 = (str(k), a.shape[0])
        elif a.shape[0] != n0[1]:
            raise MeasuredRunError(
                f"write_run data: mismatched array lengths: column {k!r} has {a.shape[0]} samples, "
                f"column {n0[0]!r} has {n0[1]}; every column needs one value per sample"
            )
        cols[k] = a
    return pd.DataFrame(cols)


def _plain(v: Any, where: str) -> Any:
    """Numpy scalars -> Python, tuples/arrays -> lists, mappings -> dicts (for TOML)."""
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, Mapping):
        return {str(k): _plain(x, f"{where}.{k}") for k, x in v.items()}
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_plain(x, f"{where}[{i}]") for i, x in enumerate(list(v))]
    if v is None or isinstance(v, (str, bool, int, float)):
        return v
    raise MeasuredRunError(f"{where} = {v!r}: a {type(v).__name__} cannot be written to TOML (use str, number, bool, list, table)")


_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def _toml_key(k: str) -> str:
    return k if _BARE_KEY.fullmatch(k) else _toml_str(k)


def _toml_str(s: str) -> str:
    return json.dumps(s, ensure_ascii=False).replace("\x7f", "\\u007f")


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return _toml_str(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}" for k, x in v.items() if x is not None) + "}"
    raise MeasuredRunError(f"experiment value {v!r} cannot be written to TOML")


def _toml_dumps(d: Mapping[str, Any]) -> str:
    out: List[str] = [f"# popup measured run (measured-run.md), written by popup {_core.__version__}"]

    def table(t: Mapping[str, Any], prefix: str) -> None:
        for k, v in t.items():
            if v is not None and not isinstance(v, dict):
                out.append(f"{_toml_key(k)} = {_toml_value(v)}")
        for k, v in t.items():
            if isinstance(v, dict):
                name = f"{prefix}{_toml_key(k)}"
                out.append("")
                out.append(f"[{name}]")
                table(v, name + ".")

    table(d, "")
    return "\n".join(out) + "\n"


# ---------------------------------------------------------------------------- simulated runs


def sim_experiment(result: SimResult, **overrides: Any) -> Dict[str, Any]:
    """The ``experiment.toml`` content of a simulated run: ``format``, ``arm`` (the arm's
    name), ``payload_kg`` [kg], ``pressure_pa`` [Pa], ``gravity``, ``replay =
    "encoder"`` and a ``description`` of the simulation; ``overrides`` replace or add
    keys (e.g. ``arm="arms/my-arm.toml"`` for an arm loaded from a file)."""
    p = result.params
    pres = p.get("pressure_pa", (math.nan, math.nan))
    exp: Dict[str, Any] = {
        "format": FORMAT,
        "arm": str(p.get("arm", "popup-lab")),
        "payload_kg": float(p.get("payload_kg", math.nan)),
        "pressure_pa": [float(pres[0]), float(pres[1])],
        "gravity": "gravity" not in list(p.get("disabled", [])),
        "replay": "encoder",
        "description": (
            f"simulated by popup {p.get('popup_version', _core.__version__)}: {p.get('drive', '?')} drive, "
            f"dt = {p.get('dt', '?')} s, integrator {p.get('integrator', '?')}, "
            f"sampled at {p.get('sample_rate_hz', '?')} Hz"
        ),
    }
    exp.update(overrides)
    return exp


def from_sim(result: SimResult, **experiment_overrides: Any) -> "pd.DataFrame":
    """The measured-run columns of a simulated run, so it can be written with
    :func:`write_run` and compared like a measured one.

    Returns a DataFrame with the columns ``t, q1..q3, dq1..dq3, tau1..tau3, ee_x..ee_z,
    imu1_a*, imu2_a*, p1, p2`` (SI units, :data:`UNITS`; the model-only channels such
    as bending angles are left out) and a default RangeIndex. ``.attrs["experiment"]``
    holds :func:`sim_experiment` ``(result, **experiment_overrides)``::

        df = popup.io.from_sim(res, description="step test")
        popup.io.write_run("runs/step", df.attrs["experiment"], df)
    """
    pd = _pd()
    from .control import ControlResult

    data = np.asarray(getattr(result, "data", None))
    closed = isinstance(result, ControlResult)
    if not (isinstance(result, SimResult) or closed) or data.ndim != 2:
        raise TypeError(f"from_sim: expected one simulated run (popup.SimResult or popup.ControlResult), got {type(result).__name__}; for a batch use batch[b]")
    cols = [c for c in MEASURED_COLUMNS if c in CHANNELS]
    df = pd.DataFrame({c: np.array(result.channel(c), dtype=np.float64) for c in cols})
    if closed:
        for j in range(3):
            df[f"ref_q{j + 1}"] = np.array(result.ref_q[:, j], dtype=np.float64)  # type: ignore[attr-defined]
        experiment_overrides = {"replay": "reference", **experiment_overrides}
    df.attrs["experiment"] = sim_experiment(result, **experiment_overrides)
    return df
