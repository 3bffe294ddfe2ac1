"""Matplotlib views of results (imported lazily)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Optional, Sequence

import numpy as np

if TYPE_CHECKING:
    from .results import BatchResult, SimResult

__all__ = ["plot_result", "plot_batch"]

_DEFAULT = [["q1", "q2", "q3"], ["ee_x", "ee_y", "ee_z"], ["d11", "d12", "d21", "d22"], ["m1_ratio", "m2_ratio"]]


def pyplot() -> Any:
    """``matplotlib.pyplot``, on the Agg backend where there is no display (imported on
    first use: matplotlib is needed only to plot)."""
    import matplotlib

    if matplotlib.get_backend().lower() not in ("agg", "pdf", "svg") and not _has_display():
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _has_display() -> bool:
    import os

    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY") or os.name == "nt")


def plot_result(res: "SimResult", channels: Optional[Sequence[str]] = None, *, ax: Any = None) -> Any:
    """One panel per channel group (or per channel when ``channels`` is given)."""
    from .results import UNITS

    plt = pyplot()
    groups = [[c] for c in channels] if channels else _DEFAULT
    if ax is None:
        fig, axes = plt.subplots(len(groups), 1, sharex=True, figsize=(8, 2.2 * len(groups)), squeeze=False)
        axes = axes[:, 0]
    else:
        axes = np.atleast_1d(ax)
        fig = axes[0].figure
    t = res.time
    for a, g in zip(axes, groups):
        for c in g:
            a.plot(t, res.channel(c), label=c)
        a.set_ylabel(f"[{UNITS[g[0]]}]")
        a.legend(loc="upper right", fontsize="small")
        a.grid(True, alpha=0.3)
    axes[-1].set_xlabel("t [s]")
    fig.suptitle(f"{res.params.get('arm', '')}: payload {res.params.get('payload_kg')} kg, {res.params.get('drive', '')}")
    return fig


def plot_batch(res: "BatchResult", channel: str, *, ax: Any = None) -> Any:
    """Overlay ``channel`` of every run, labelled by payload and pressures."""
    from .results import UNITS

    plt = pyplot()
    if ax is None:
        fig, ax = plt.subplots(figsize=(8, 4))
    else:
        fig = ax.figure
    pay = np.asarray(res.params["payload_kg"])
    pp = np.asarray(res.params["pressure_pa"])
    for b in range(len(res)):
        ax.plot(res.time[b], res.channel(channel)[b], label=f"{pay[b]:g} kg, {pp[b, 0] / 1e3:g}/{pp[b, 1] / 1e3:g} kPa")
    ax.set_xlabel("t [s]")
    ax.set_ylabel(f"{channel} [{UNITS[channel]}]")
    if len(res) <= 12:
        ax.legend(fontsize="small")
    ax.grid(True, alpha=0.3)
    return fig
