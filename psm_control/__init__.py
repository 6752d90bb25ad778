"""PSM kinematics and control for tissue-retract: the robot model every other package shares."""

from importlib.metadata import PackageNotFoundError, version

from psm_control.errors import (
    ConfigurationError,
    JointLimitError,
    JointVectorError,
    NotBuiltError,
    TissueRetractError,
    UnknownVariantError,
)
from psm_control.robot import PsmConfiguration, PsmModel
from psm_control.spec import DVRK_JOINT_NAMES, JointSpec, PsmSpec, psm_spec

try:
    __version__ = version("tissue-retract")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

__all__ = [
    "DVRK_JOINT_NAMES",
    "ConfigurationError",
    "JointLimitError",
    "JointSpec",
    "JointVectorError",
    "NotBuiltError",
    "PsmConfiguration",
    "PsmModel",
    "PsmSpec",
    "TissueRetractError",
    "UnknownVariantError",
    "__version__",
    "psm_spec",
]
