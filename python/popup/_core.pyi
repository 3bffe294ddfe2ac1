"""Type stubs of the private extension module ``popup._core`` (checked by mypy.stubtest)."""

from os import PathLike
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union, final

import numpy as np
import numpy.typing as npt

__all__ = ["Arm", "RigidArm", "Model", "_raise", "run_cli", "effect_registry", "effect_shaping", "effect_output_only", "closed_loop_rollout", "closed_loop_rollout_multi", "linearize", "controller_params", "check_control", "check_scenario", "scenario_set_key", "run_scenario", "control_channels", "gain_names", "EFFECT_NAMES", "BEAM_PRESETS", "CHANNEL_LIMITS", "GAP_WARN_STEPS", "GAP_ERROR_STEPS", "MAX_STEPS", "__version__", "BUILD_PROFILE", "BUILD_FEATURES"]

__version__: str
BUILD_PROFILE: str
BUILD_FEATURES: List[str]

_F = npt.NDArray[np.float64]

def _raise(cls: str, msg: str) -> None: ...
def run_cli(argv: Sequence[str]) -> int: ...
def effect_registry() -> List[Tuple[str, str, str, int, float, float, float, bool, bool, str]]: ...
def effect_shaping() -> List[Tuple[str, str]]: ...
def effect_output_only() -> List[Tuple[str, str, str]]: ...
def control_channels() -> List[str]: ...
def gain_names() -> List[str]: ...
def check_control(model: Model, text: str, source: str = "<control>") -> Tuple[List[float], int]: ...
def closed_loop_rollout(
    model: Model,
    text: str,
    payload_kg: npt.NDArray[np.float64],
    pressure_pa: npt.NDArray[np.float64],
    q0: npt.NDArray[np.float64],
    duration: float,
    sample_period: float,
    gains: Optional[npt.NDArray[np.float64]] = None,
    effects: Optional[npt.NDArray[np.float64]] = None,
    threads: int = 0,
    check_step: bool = True,
    source: str = "<control>",
) -> Tuple[
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    List[Optional[Tuple[str, str]]],
    List[List[Tuple[float, str, str, str, str]]],
    List[str],
    List[List[Tuple[int, float, float, float]]],
    List[List[str]],
]: ...
def closed_loop_rollout_multi(
    model: Model,
    texts: Sequence[str],
    payload_kg: npt.NDArray[np.float64],
    pressure_pa: npt.NDArray[np.float64],
    q0: npt.NDArray[np.float64],
    duration: float,
    sample_period: float,
    gains: Optional[npt.NDArray[np.float64]] = None,
    effects: Optional[npt.NDArray[np.float64]] = None,
    threads: int = 0,
    check_step: bool = True,
    source: str = "<control>",
) -> Tuple[
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    List[Optional[Tuple[str, str]]],
    List[List[Tuple[float, str, str, str, str]]],
    List[str],
    List[List[Tuple[int, float, float, float]]],
    List[List[str]],
]: ...
def linearize(
    model: Model,
    payload_kg: npt.NDArray[np.float64],
    pressure_pa: npt.NDArray[np.float64],
    q_motor: npt.NDArray[np.float64],
    input: str,
    outputs: Sequence[str],
    t: float = 0.0,
    effects: Optional[npt.NDArray[np.float64]] = None,
) -> Dict[str, Any]: ...
def controller_params(model: Model, text: str, source: str = "<control>") -> Dict[str, Any]: ...
def check_scenario(text: str, source: str = "<scenario>", base_dir: str = ".") -> List[Tuple[str, int, str, str]]: ...
def scenario_set_key(text: str, path: str, value: float) -> str: ...
def run_scenario(
    text: str,
    source: str = "<scenario>",
    base_dir: str = ".",
    out: Optional[str] = None,
    duration: Optional[float] = None,
    seed: Optional[int] = None,
) -> Tuple[
    str,
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    List[Tuple[float, str, str, str, str]],
    List[Tuple[int, float, float, float]],
    List[str],
    int,
]: ...

EFFECT_NAMES: List[str]
BEAM_PRESETS: Dict[str, Dict[str, float]]
#: (columns, unit, min, warn, error, scale, advice) per measured channel group: warn and
#: error in the unit when scale is "", else factors of the arm's number ("drive torque",
#: "arm acceleration"; Arm.channel_limits() gives the numbers).
CHANNEL_LIMITS: List[Tuple[List[str], str, float, float, float, str, str]]
GAP_WARN_STEPS: float
GAP_ERROR_STEPS: float
MAX_STEPS: float

@final
class Arm:
    @staticmethod
    def builtin(name: str) -> Arm: ...
    @staticmethod
    def builtin_names() -> List[str]: ...
    @staticmethod
    def packaged_source(name: str) -> Optional[str]: ...
    @staticmethod
    def from_toml(text: str, source: str = "<string>") -> Arm: ...
    @staticmethod
    def load(path: Union[str, PathLike[str]]) -> Arm: ...
    def save(self, path: Union[str, PathLike[str]]) -> None: ...
    def to_toml(self) -> str: ...
    def with_overrides(self, overrides: Dict[str, Any]) -> Arm: ...
    @property
    def name(self) -> str: ...
    def channel_limits(self) -> List[Tuple[List[str], str, float, float, float, str]]: ...
    def reach(self) -> Dict[str, Any]: ...
    def __eq__(self, value: object, /) -> bool: ...

@final
class RigidArm:
    def __new__(cls, arm: Arm, table: str = "as_built") -> RigidArm: ...
    @property
    def name(self) -> str: ...
    def fk(self, q: Sequence[float]) -> _F: ...
    def jacobian(self, q: Sequence[float]) -> _F: ...
    def ik(self, p: Sequence[float]) -> List[Tuple[List[float], str, str]]: ...
    def singularity(self, q: Sequence[float], tol: float = 1e-6) -> Dict[str, Any]: ...
    def manipulability(self, q: Sequence[float]) -> float: ...
    def check_reachable(self, p: Sequence[float]) -> None: ...
    def frames(self, q: Sequence[float]) -> _F: ...

@final
class Model:
    def __new__(
        cls,
        arm: Arm,
        dt: float = 1e-3,
        integrator: str = "rk4",
        gravity: Optional[Sequence[float]] = None,
        disable: Sequence[str] = ...,
    ) -> Model: ...
    @property
    def arm(self) -> Arm: ...
    @property
    def dt(self) -> float: ...
    @property
    def motion_hits(self) -> int: ...
    @property
    def integrator(self) -> str: ...
    @property
    def integrator_order(self) -> int: ...
    @property
    def disabled(self) -> List[str]: ...
    @property
    def gravity(self) -> List[float]: ...
    @property
    def joint_names(self) -> List[str]: ...
    @property
    def link_models(self) -> List[str]: ...
    @property
    def motor_index(self) -> List[int]: ...
    @property
    def bend_index(self) -> List[int]: ...
    @property
    def locked_index(self) -> List[int]: ...
    @property
    def wrinkle_coefficient(self) -> float: ...
    @staticmethod
    def channels() -> List[str]: ...
    @staticmethod
    def units() -> List[str]: ...
    @staticmethod
    def sensors() -> List[str]: ...
    def param_data(self, payload_kg: float, pressure_pa: Sequence[float]) -> Dict[str, Any]: ...
    def rest_state(self, payload_kg: float, pressure_pa: Sequence[float], q_motor: Sequence[float]) -> _F: ...
    def locked_modes(self, payload_kg: float, pressure_pa: Sequence[float], q: Sequence[float]) -> _F: ...
    def mass_matrix(self, payload_kg: float, q: Sequence[float]) -> _F: ...
    def gravity_torque(self, payload_kg: float, q: Sequence[float]) -> _F: ...
    def frames(self, q: Sequence[float]) -> _F: ...
    def end_effector(self, q: Sequence[float]) -> _F: ...
    def check_step(self, payload_kg: float, pressure_pa: Sequence[float], q: Sequence[float], replay: bool) -> None: ...
    def rollout(
        self,
        payload_kg: _F,
        pressure_pa: _F,
        drive: str,
        times: _F,
        values: _F,
        initial_q: Optional[_F] = None,
        initial_v: Optional[_F] = None,
        duration: Optional[float] = None,
        sample_period: float = 1e-3,
        threads: int = 0,
        check_step: bool = True,
        effects: Optional[_F] = None,
        log: Optional[str] = None,
        log_experiment: Optional[str] = None,
    ) -> Tuple[_F, List[Optional[Tuple[str, str]]], List[List[Tuple[int, float, float, float]]], List[List[str]]]: ...
