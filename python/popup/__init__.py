"""popup: simulation and model-validation toolkit for inflatable robot arms.

The engine is Rust (``popup._core``); this package is the user workflow: arms, models,
single and batched runs, results with ``.to_pandas()`` and ``.plot()``; measured runs,
comparison, diagnosis against the effect library (:mod:`popup.effects`), the
add-effect-and-refit loop and reports; MCAP run logs (:func:`read_log`).
"""

from __future__ import annotations

from . import _core
from . import compare, effects, io
from .exceptions import (
    ArmFileError,
    ConvergenceError,
    DivergenceError,
    InputError,
    LogFileError,
    LogWriteError,
    MeasuredRunError,
    ParameterError,
    PopupError,
    PopupWarning,
    ScenarioError,
    SingularityError,
    StepTooLargeError,
    UnknownArmError,
    UnreachableError,
)
from .model import BEAM_PRESETS, Arm, Model, RigidArm, arm_motor, arm_names, load_arm
from .compare import Comparison
from .io import MeasuredRun, read_run, write_run
from . import mcaplog
from .mcaplog import RunLog, read_log
from .results import CHANNELS, UNITS, BatchResult, SimResult, WrinkleAlarm
from . import noise, problem, estimate, smoothing
from .problem import ReplayProblem
from .diagnosis import Diagnosis, History, Suspect, diagnose, improve
from .fit import FitResult, fit_params
from . import report, synth
from . import control
from .control import Controller, ControlBatch, ControlResult, Obstacle, Phase, Task
from . import scenario
from . import frequency
from .scenario import Scenario
from . import setmembership
from . import sweep

__version__: str = _core.__version__
build_profile: str = _core.BUILD_PROFILE
build_features: list = list(_core.BUILD_FEATURES)

__all__ = [
    "Arm",
    "RigidArm",
    "Model",
    "load_arm",
    "arm_names",
    "arm_motor",
    "BEAM_PRESETS",
    "SimResult",
    "MeasuredRun",
    "read_run",
    "write_run",
    "RunLog",
    "read_log",
    "io",
    "mcaplog",
    "compare",
    "Comparison",
    "ReplayProblem",
    "problem",
    "noise",
    "estimate",
    "smoothing",
    "effects",
    "diagnose",
    "improve",
    "fit_params",
    "FitResult",
    "Diagnosis",
    "History",
    "Suspect",
    "report",
    "synth",
    "control",
    "Controller",
    "Phase",
    "Task",
    "Obstacle",
    "ControlResult",
    "ControlBatch",
    "BatchResult",
    "WrinkleAlarm",
    "CHANNELS",
    "UNITS",
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
    "Scenario",
    "scenario",
    "setmembership",
    "sweep",
    "frequency",
    "PopupWarning",
    "__version__",
    "build_profile",
    "build_features",
]
