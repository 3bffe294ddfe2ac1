"""Exceptions of popup.

Every error raised by popup derives from :class:`PopupError` and from the built-in
exception that matches it, so ``except ValueError`` keeps working for bad input.
"""

from __future__ import annotations

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
    """The time step is outside the integrator's stability region."""


class DivergenceError(PopupError, RuntimeError):
    """The simulation became non-finite or unbounded."""


class ConvergenceError(PopupError, RuntimeError):
    """A solver (static equilibrium, fit) did not converge."""


class MeasuredRunError(PopupError, ValueError):
    """A measured run (experiment.toml + measurements) is malformed."""


class PopupWarning(UserWarning):
    """A condition the run survived but the user should know (pressure outside the
    stiffness table, wrinkling alarm, ...)."""


__all__.append("PopupWarning")
