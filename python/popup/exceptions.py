"""Exceptions of popup.

Every error raised by popup derives from :class:`PopupError` and from the built-in
exception that matches it, so ``except ValueError`` keeps working for bad input.
"""

from __future__ import annotations

from typing import Optional

__all__ = [
    "PopupError",
    "ParameterError",
    "ArmFileError",
    "UnknownArmError",
    "UnreachableError",
    "SingularityError",
    "InputError",
    "StepTooLargeError",
    "DivergenceError",
    "ConvergenceError",
    "MeasuredRunError",
    "LogFileError",
    "LogWriteError",
    "ScenarioError",
]


class PopupError(Exception):
    """Base class of every popup error."""


class ParameterError(PopupError, ValueError):
    """A parameter (arm file, options, payload, pressure) is outside its valid range."""


class ArmFileError(PopupError, ValueError):
    """An arm file cannot be read or does not describe a valid arm."""


class UnknownArmError(PopupError, LookupError):
    """A built-in arm name that does not exist."""


class UnreachableError(PopupError, ValueError):
    """A Cartesian target outside the workspace of the arm."""


class SingularityError(PopupError, ValueError):
    """The configuration is singular for the requested operation."""


class InputError(PopupError, ValueError):
    """An input array has the wrong shape or content."""


class StepTooLargeError(PopupError, ValueError):
    """The time step is outside the integrator's stability region. Raised by the engine's
    step check, it carries ``dt`` (the step asked for [s]) and ``dt_max`` (the largest
    stable step [s]); both are ``None`` when the error was re-raised from a batch's
    message."""

    dt: Optional[float] = None
    dt_max: Optional[float] = None


class DivergenceError(PopupError, RuntimeError):
    """The simulation became non-finite or unbounded."""


class ConvergenceError(PopupError, RuntimeError):
    """A solver (static equilibrium, fit) did not converge."""


class MeasuredRunError(PopupError, ValueError):
    """A measured run (experiment.toml + measurements) is malformed."""


class LogFileError(MeasuredRunError):
    """An MCAP log (:func:`popup.read_log`, or a measured run given as a ``.mcap`` file)
    cannot be read: not an MCAP file, a corrupted record (CRC mismatch), or a layout
    other than ``docs/logging.md``. A :class:`MeasuredRunError` (so also a
    :class:`PopupError` and a ``ValueError``), because an MCAP log is also the
    measured-run container."""


class LogWriteError(PopupError, OSError):
    """Writing an MCAP log failed (the file cannot be created, a write failed)."""


class ScenarioError(PopupError, ValueError):
    """A scenario file is invalid. ``problems`` lists every problem found as
    ``(file, line, key, message)`` (line 1-based, 0 when unknown)."""

    def __init__(self, problems: "object") -> None:
        if isinstance(problems, str):
            self.problems: list = []
            msg = problems
        else:
            self.problems = [tuple(p) for p in problems]  # type: ignore[attr-defined]
            lines = [f"{f}:{ln}: {k}: {m}" if k else f"{f}:{ln}: {m}" for f, ln, k, m in self.problems]
            n = len(self.problems)
            msg = f"{n} problem{'s' if n != 1 else ''} in the scenario:\n" + "\n".join(lines)
        super().__init__(msg)


class PopupWarning(UserWarning):
    """A condition the run survived but the user should know (pressure outside the
    stiffness table, wrinkling alarm, ...)."""


__all__.append("PopupWarning")
