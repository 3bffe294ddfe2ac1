"""Scenario files: one TOML file describing a headless run (``docs/logging.md``).

The same format ``popup run``, ``popup sweep`` and ``popup check`` read: the arm and its
payload and pressures, the controller and its task (``docs/control.md``), effects, sensor
noise, timing and what to log. :class:`Scenario` reads, checks (every problem at once,
with file, line and key), edits and writes it, and runs it in the Rust core with an
optional MCAP log::

    sc = popup.Scenario.read("examples/scenarios/pick_and_place.toml")
    res = sc.set("payload_kg", 1.5).run(out="run.mcap")   # arrays, and the log
    log = popup.read_log("run.mcap")                        # the same arrays read back
"""

from __future__ import annotations

import copy
import sys
from pathlib import Path
from typing import Any, Dict, List, Optional, Union

import tomli_w

from . import _core
from .control import ControlResult, Event
from .exceptions import ScenarioError
from .results import WrinkleAlarm

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["Scenario", "SCENARIO_FORMAT"]

#: The ``format`` value of a scenario file.
SCENARIO_FORMAT = "popup-scenario/1"

PathLike = Union[str, Path]


class Scenario:
    """A checked scenario: its TOML text, where it came from, and its values.

    Build one with :meth:`read` (a file), :meth:`from_toml` (text) or :meth:`from_dict`;
    every constructor runs the core's checks and raises :class:`popup.ScenarioError`
    listing every problem (``.problems``: ``(file, line, key, message)``).
    """

    def __init__(self, text: str, source: str = "<scenario>", base_dir: PathLike = ".") -> None:
        problems = [tuple(p) for p in _core.check_scenario(text, source, str(base_dir))]
        if problems:
            raise ScenarioError(problems)
        self.text = text
        """The TOML text."""
        self.source = source
        """File name used in messages."""
        self.base_dir = Path(base_dir)
        """Folder arm-file paths are relative to."""
        self._data: Dict[str, Any] = tomllib.loads(text)

    @classmethod
    def read(cls, path: PathLike) -> "Scenario":
        """Read and check a scenario file (arm files relative to its folder)."""
        p = Path(path)
        try:
            text = p.read_text()
        except OSError as e:
            raise ScenarioError([(str(p), 0, "", f"cannot read the scenario: {e}")]) from e
        return cls(text, str(p), p.parent)

    @classmethod
    def from_toml(cls, text: str, source: str = "<scenario>", base_dir: PathLike = ".") -> "Scenario":
        """Check a scenario given as TOML text."""
        return cls(text, source, base_dir)

    @classmethod
    def from_dict(cls, data: Dict[str, Any], source: str = "<scenario>", base_dir: PathLike = ".") -> "Scenario":
        """Check a scenario given as a dict (the parsed TOML)."""
        return cls(tomli_w.dumps(data), source, base_dir)

    def to_dict(self) -> Dict[str, Any]:
        """The scenario's values (a deep copy of the parsed TOML)."""
        return copy.deepcopy(self._data)

    def to_toml(self) -> str:
        """The TOML text (as read, comments kept)."""
        return self.text

    def write(self, path: PathLike) -> Path:
        """Write the TOML text to ``path``; returns the path."""
        p = Path(path)
        p.write_text(self.text)
        return p

    def set(self, key: str, value: float) -> "Scenario":
        """A copy with the numeric key ``key`` set (``payload_kg``, ``pressure_pa`` (every
        element), ``pressure_pa[1]``, ``controller.gains.vel_kp``, ...), checked."""
        return Scenario(_core.scenario_set_key(self.text, key, float(value)), self.source, self.base_dir)

    @property
    def duration_s(self) -> float:
        """Simulated time [s]."""
        return float(self._data["duration_s"])

    @property
    def seed(self) -> int:
        """Seed of the sensor noise."""
        return int(self._data.get("seed", 0))

    def phase_names(self) -> List[str]:
        """Names of the task's phases in order (phase code i of the results)."""
        phases = self._data.get("phases", [])
        if not phases:
            return ["Holding"]
        return [str(p.get("name", str(p.get("kind", "phase")).capitalize())) for p in phases]

    def run(self, out: Optional[PathLike] = None, *, duration: Optional[float] = None, seed: Optional[int] = None) -> ControlResult:
        """Run the scenario in the Rust core (GIL released), streamed into the MCAP log
        ``out`` when given; returns the run's arrays (sensor noise included) as a
        :class:`popup.control.ControlResult`. ``duration`` [s] and ``seed`` override the
        file's. Reading ``out`` back with :func:`popup.read_log` gives the same arrays."""
        status, data, ctrl, events, alarms, warnings, nonfinite = _core.run_scenario(
            self.text, self.source, str(self.base_dir), None if out is None else str(out), duration, seed
        )
        params: Dict[str, Any] = {"scenario": self.source, "seed": self.seed if seed is None else int(seed), "nonfinite_dropped": nonfinite}
        if out is not None:
            params["log"] = str(out)
        return ControlResult(
            data=data,
            control=ctrl,
            events=[Event(*e) for e in events],
            status=status,
            alarms=[WrinkleAlarm(*a) for a in alarms],
            phase_names=self.phase_names(),
            params=params,
            warnings=list(warnings),
        )

    def __repr__(self) -> str:
        return f"Scenario(source={self.source!r}, duration_s={self.duration_s}, phases={self.phase_names()})"

