"""Result objects: named arrays with ``.to_pandas()`` and ``.plot()``.

Columns follow the measured-run format (``measured-run.md``); units are SI and listed in
:attr:`SimResult.units`. Frames: ``ee`` is the origin of DH frame 7 in the base frame W;
``imu1``/``imu2`` are specific forces (a − g) in the axes of frames 4 and 7.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, List, NamedTuple, Optional, Sequence

import numpy as np

from . import _core

__all__ = ["SimResult", "BatchResult", "WrinkleAlarm", "CHANNELS", "UNITS", "SENSORS"]

CHANNELS: List[str] = list(_core.Model.channels())
UNITS: Dict[str, str] = dict(zip(CHANNELS, _core.Model.units()))
#: The kind of sensor that records each channel (``clock``, ``encoder``, ``drive``, ``mocap``,
#: ``imu``, ``pressure``; ``model`` for what no lab measures), from the core.
SENSORS: Dict[str, str] = dict(zip(CHANNELS, _core.Model.sensors()))
_IDX = {c: i for i, c in enumerate(CHANNELS)}

# named groups of channels -> attribute names
_GROUPS: Dict[str, List[str]] = {
    "q": ["q1", "q2", "q3"],
    "dq": ["dq1", "dq2", "dq3"],
    "tau": ["tau1", "tau2", "tau3"],
    "ee": ["ee_x", "ee_y", "ee_z"],
    "imu1": ["imu1_ax", "imu1_ay", "imu1_az"],
    "imu2": ["imu2_ax", "imu2_ay", "imu2_az"],
    "pressure": ["p1", "p2"],
    "bending": ["d11", "d12", "d21", "d22"],
    "bending_rate": ["dd11", "dd12", "dd21", "dd22"],
    "bending_moment": ["m11", "m12", "m21", "m22"],
    "moment_ratio": ["m1_ratio", "m2_ratio"],
}


class WrinkleAlarm(NamedTuple):
    """One episode of a link's bending moment above its wrinkling moment M_w."""

    link: int
    """Link number (1 or 2)."""
    t_start: float
    """Time |M| first exceeded M_w [s]."""
    t_end: float
    """Time it fell back below M_w [s] (NaN: still above at the end of the run)."""
    peak_ratio: float
    """Peak |M|/M_w during the episode."""


class ChannelTable:
    """Named access to a ``data`` array whose last axis is the measured-run channels
    (:data:`CHANNELS`): the base of :class:`SimResult` and the controller's results."""

    data: np.ndarray

    def _cols(self, names: Sequence[str]) -> np.ndarray:
        return self.data[..., [_IDX[n] for n in names]]

    def channel(self, name: str) -> np.ndarray:
        """One channel by its measured-run name (e.g. ``"ee_z"``)."""
        if name not in _IDX:
            raise KeyError(f"unknown channel {name!r}; channels are {CHANNELS}")
        return self.data[..., _IDX[name]]

    @property
    def time(self) -> np.ndarray:
        """Sample times [s]."""
        return self.data[..., _IDX["t"]]

    @property
    def q(self) -> np.ndarray:
        """Motor joint angles q1..q3 [rad], (..., 3)."""
        return self._cols(_GROUPS["q"])

    @property
    def dq(self) -> np.ndarray:
        """Motor joint rates [rad/s], (..., 3)."""
        return self._cols(_GROUPS["dq"])

    @property
    def tau(self) -> np.ndarray:
        """Motor torques at the joint outputs (link side, armature excluded) [N·m], (..., 3)."""
        return self._cols(_GROUPS["tau"])

    @property
    def ee(self) -> np.ndarray:
        """End-effector position p_WE [m], (..., 3)."""
        return self._cols(_GROUPS["ee"])

    @property
    def imu1(self) -> np.ndarray:
        """Specific force at the tip of link 1, frame-4 axes [m/s²], (..., 3)."""
        return self._cols(_GROUPS["imu1"])

    @property
    def imu2(self) -> np.ndarray:
        """Specific force at the tip of link 2, frame-7 axes [m/s²], (..., 3)."""
        return self._cols(_GROUPS["imu2"])

    @property
    def pressure(self) -> np.ndarray:
        """Link pressures [Pa], (..., 2)."""
        return self._cols(_GROUPS["pressure"])

    @property
    def bending(self) -> np.ndarray:
        """Bending angles δ11, δ12, δ21, δ22 [rad], (..., 4)."""
        return self._cols(_GROUPS["bending"])

    @property
    def bending_rate(self) -> np.ndarray:
        """Bending rates [rad/s], (..., 4)."""
        return self._cols(_GROUPS["bending_rate"])

    @property
    def bending_moment(self) -> np.ndarray:
        """Bending moments k δ + c δ̇ [N·m], (..., 4)."""
        return self._cols(_GROUPS["bending_moment"])

    @property
    def moment_ratio(self) -> np.ndarray:
        """|M|/M_w of each link's universal joint, (..., 2); above 1 = wrinkling."""
        return self._cols(_GROUPS["moment_ratio"])

    @property
    def energy(self) -> np.ndarray:
        """Mechanical energy (kinetic + gravity + spring) [J]."""
        return self.data[..., _IDX["energy"]]


@dataclass
class SimResult(ChannelTable):
    """One simulated run.

    Attributes
    ----------
    data : ndarray, shape (nsample, nchannel)
        All channels, columns as :data:`CHANNELS`.
    params : dict
        Everything needed to reproduce the run (arm, payload, pressures, dt, integrator,
        drive, wrinkling coefficient, build).
    alarms : list of WrinkleAlarm
    warnings : list of str
    """

    data: np.ndarray
    params: Dict[str, Any]
    alarms: List[WrinkleAlarm] = field(default_factory=list)
    warnings: List[str] = field(default_factory=list)

    @property
    def channels(self) -> List[str]:
        """Column names of :attr:`data`."""
        return list(CHANNELS)

    @property
    def units(self) -> Dict[str, str]:
        """Unit of every channel."""
        return dict(UNITS)

    def __len__(self) -> int:
        return int(self.data.shape[0])

    def to_pandas(self) -> Any:
        """A DataFrame with one column per channel (measured-run names), indexed by ``t``."""
        import pandas as pd

        df = pd.DataFrame(self.data, columns=CHANNELS).set_index("t")
        df.attrs.update(self.params)
        return df

    def plot(self, channels: Optional[Sequence[str]] = None, *, ax: Any = None) -> Any:
        """Plot channels vs time (default: q, ee, bending, moment ratio). Returns the figure."""
        from .plot import plot_result

        return plot_result(self, channels, ax=ax)


@dataclass
class BatchResult(ChannelTable):
    """A batch of runs with stacked arrays: every named array has a leading batch axis.

    ``errors[b]`` is None for a successful run or the message of its failure (its rows are
    NaN). ``params`` holds the per-run payload and pressures.
    """

    data: np.ndarray
    params: Dict[str, Any]
    errors: List[Optional[str]]
    alarms: List[List[WrinkleAlarm]]
    warnings: List[List[str]]

    def __len__(self) -> int:
        return int(self.data.shape[0])

    def __getitem__(self, b: int) -> SimResult:
        p = dict(self.params)
        p["payload_kg"] = float(self.params["payload_kg"][b])
        p["pressure_pa"] = tuple(float(x) for x in self.params["pressure_pa"][b])
        return SimResult(self.data[b], p, list(self.alarms[b]), list(self.warnings[b]))

    @property
    def ok(self) -> np.ndarray:
        """Boolean mask of successful runs."""
        return np.array([e is None for e in self.errors])

    def to_pandas(self) -> Any:
        """Long-form DataFrame: one row per (run, sample), with ``run``, ``payload_kg``,
        ``p1_set``, ``p2_set`` columns."""
        import pandas as pd

        b, s, c = self.data.shape
        df = pd.DataFrame(self.data.reshape(b * s, c), columns=CHANNELS)
        df.insert(0, "run", np.repeat(np.arange(b), s))
        df.insert(1, "payload_kg", np.repeat(np.asarray(self.params["payload_kg"]), s))
        pp = np.asarray(self.params["pressure_pa"])
        df.insert(2, "p1_set", np.repeat(pp[:, 0], s))
        df.insert(3, "p2_set", np.repeat(pp[:, 1], s))
        return df

    def plot(self, channel: str = "ee_z", *, ax: Any = None) -> Any:
        """Overlay one channel of every run. Returns the figure."""
        from .plot import plot_batch

        return plot_batch(self, channel, ax=ax)
