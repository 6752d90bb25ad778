"""The dVRK PSM's kinematic specification: modified DH table, limits, jaw range and tool-tip offset.

This is the single source of the robot's numbers. The URDF generator, the Pinocchio model, the
PyBullet scene and the safety limits all read them from here. Values are the dVRK 2.4 configuration
files' (SI units: metres, radians, seconds); the published dvrk_model URDF carries placeholder limits
and is deliberately not used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from psm_control.errors import ConfigurationError, UnknownVariantError

__all__ = [
    "ARMS",
    "DVRK_JOINT_NAMES",
    "TOOLS",
    "JointSpec",
    "PsmSpec",
    "RcmConstants",
    "psm_spec",
]

JointKind = Literal["revolute", "prismatic"]

#: Joint names in the order the dVRK publishes them on ``measured_js``.
DVRK_JOINT_NAMES = ("yaw", "pitch", "insertion", "roll", "wrist_pitch", "wrist_yaw")

_DEG = math.pi / 180.0
# dVRK move_jp trajectory limits (the dVRK sets no hard servo velocity limit, so these are the
# conservative defaults our limits start from).
_V_YAW_PITCH = 90 * _DEG
_A_YAW_PITCH = 90 * _DEG
_V_INSERTION = 0.2
_A_INSERTION = 0.2
_V_WRIST = 1080 * _DEG
_A_WRIST = 720 * _DEG

#: dVRK ``tooltip_offset``: a pure rotation after joint 6, so measured_cp sits at the jaw pivot.
TOOLTIP_OFFSET = (
    (0.0, -1.0, 0.0, 0.0),
    (0.0, 0.0, 1.0, 0.0),
    (-1.0, 0.0, 0.0, 0.0),
    (0.0, 0.0, 0.0, 1.0),
)


@dataclass(frozen=True)
class JointSpec:
    """One joint of the modified DH (Craig) chain.

    The link transform is ``RotX(alpha) TransX(a) RotZ(theta) TransZ(d)`` with ``theta = q + offset``
    for a revolute joint and ``d = q + offset`` for a prismatic one.

    Attributes:
        name: URDF joint name (``outer_yaw`` ...).
        dvrk_name: Name on the dVRK's ``measured_js`` (``yaw`` ...).
        kind: ``"revolute"`` [rad] or ``"prismatic"`` [m].
        alpha: Twist about the previous x axis [rad].
        a: Length along the previous x axis [m].
        d: Offset along z for a revolute joint [m] (unused for a prismatic joint).
        theta: Angle about z for a prismatic joint [rad] (unused for a revolute joint).
        offset: Constant added to q (angle or length).
        lower: Lower position limit [rad or m].
        upper: Upper position limit [rad or m].
        velocity_limit: Maximum speed [rad/s or m/s].
        acceleration_limit: Maximum acceleration [rad/s^2 or m/s^2].
    """

    name: str
    dvrk_name: str
    kind: JointKind
    alpha: float
    a: float
    d: float
    offset: float
    lower: float
    upper: float
    velocity_limit: float
    acceleration_limit: float
    theta: float = 0.0

    def validate(self) -> None:
        """Raise :class:`ConfigurationError` if any number is non-finite or inconsistent."""
        for name in ("alpha", "a", "d", "offset", "lower", "upper", "theta"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise ConfigurationError(f"{self.name}.{name}", value, "a finite number")
        if self.kind not in ("revolute", "prismatic"):
            raise ConfigurationError(f"{self.name}.kind", self.kind, "'revolute' or 'prismatic'")
        if not self.lower < self.upper:
            raise ConfigurationError(f"{self.name}.lower", self.lower, f"a value below upper={self.upper}")
        for name in ("velocity_limit", "acceleration_limit"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigurationError(f"{self.name}.{name}", value, "a finite number > 0")


@dataclass(frozen=True)
class RcmConstants:
    """Remote-centre-of-motion rules the dVRK enforces.

    Attributes:
        min_insertion_m: Cartesian control is refused below this insertion (SafeDistanceFromRCM).
        insertion_buffer_m: Hysteresis the dVRK adds to that distance.
        min_goal_distance_m: IK fails for goals closer than this to the RCM.
        cannula_engage_depth_m: Depth at which the cannula engages the instrument.
        cartesian_start_insertion_m: Insertion the dVRK's test scripts move to before Cartesian moves.
    """

    min_insertion_m: float = 0.045
    insertion_buffer_m: float = 0.002
    min_goal_distance_m: float = 0.001
    cannula_engage_depth_m: float = 0.025
    cartesian_start_insertion_m: float = 0.12


@dataclass(frozen=True)
class ToolGeometry:
    """Primitive geometry of the instrument for visuals and collisions [m].

    These are approximate outer dimensions of an 8 mm large needle driver; they are not kinematic
    parameters and nothing in the control chain depends on them beyond collision shapes.
    """

    shaft_radius: float = 0.0042
    wrist_radius: float = 0.0040
    jaw_length: float = 0.0100
    jaw_width: float = 0.0030
    jaw_thickness: float = 0.0015


@dataclass(frozen=True)
class PsmSpec:
    """A complete PSM + instrument variant.

    Attributes:
        arm: Arm generation, ``"classic"`` or ``"si"``.
        tool: Instrument part number, ``"400006"`` or ``"420006"`` (large needle drivers).
        joints: The six arm joints, in dVRK order.
        jaw_lower: Jaw opening lower limit [rad] (negative squeezes).
        jaw_upper: Jaw opening upper limit [rad].
        jaw_velocity_limit: [rad/s].
        jaw_acceleration_limit: [rad/s^2].
        tooltip_offset: 4x4 homogeneous transform appended after joint 6.
        rcm: RCM rules.
        geometry: Instrument geometry.
    """

    arm: str
    tool: str
    joints: tuple[JointSpec, ...]
    jaw_lower: float
    jaw_upper: float
    jaw_velocity_limit: float = _V_WRIST
    jaw_acceleration_limit: float = _A_WRIST
    tooltip_offset: tuple[tuple[float, ...], ...] = TOOLTIP_OFFSET
    rcm: RcmConstants = field(default_factory=RcmConstants)
    geometry: ToolGeometry = field(default_factory=ToolGeometry)

    def __post_init__(self) -> None:
        self.validate()

    @property
    def name(self) -> str:
        """Variant name, e.g. ``psm_classic_400006``."""
        return f"psm_{self.arm}_{self.tool}"

    @property
    def dof(self) -> int:
        """Number of arm joints (6)."""
        return len(self.joints)

    @property
    def joint_names(self) -> tuple[str, ...]:
        """URDF joint names in dVRK order."""
        return tuple(j.name for j in self.joints)

    @property
    def lower(self) -> np.ndarray:
        """Lower position limits [rad or m], shape (6,)."""
        return np.array([j.lower for j in self.joints])

    @property
    def upper(self) -> np.ndarray:
        """Upper position limits [rad or m], shape (6,)."""
        return np.array([j.upper for j in self.joints])

    @property
    def velocity_limit(self) -> np.ndarray:
        """Velocity limits, shape (6,)."""
        return np.array([j.velocity_limit for j in self.joints])

    @property
    def acceleration_limit(self) -> np.ndarray:
        """Acceleration limits, shape (6,)."""
        return np.array([j.acceleration_limit for j in self.joints])

    @property
    def tooltip_offset_matrix(self) -> np.ndarray:
        """The tool-tip offset as a 4x4 array."""
        return np.array(self.tooltip_offset, dtype=float)

    def validate(self) -> None:
        """Raise :class:`ConfigurationError` naming the first inconsistent number."""
        if len(self.joints) != 6:
            raise ConfigurationError("joints", len(self.joints), "exactly 6 arm joints")
        for joint in self.joints:
            joint.validate()
        if self.joints[2].kind != "prismatic":
            raise ConfigurationError("joints[2].kind", self.joints[2].kind, "'prismatic' (insertion)")
        if not self.jaw_lower < self.jaw_upper:
            raise ConfigurationError("jaw_lower", self.jaw_lower, f"a value below jaw_upper={self.jaw_upper}")
        for name in ("jaw_velocity_limit", "jaw_acceleration_limit"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigurationError(name, value, "a finite number > 0")
        offset = self.tooltip_offset_matrix
        if offset.shape != (4, 4) or not np.allclose(offset[:3, :3] @ offset[:3, :3].T, np.eye(3)):
            raise ConfigurationError("tooltip_offset", self.tooltip_offset, "a 4x4 rigid transform")
        if not 0.0 <= self.rcm.min_insertion_m < self.joints[2].upper:
            raise ConfigurationError(
                "rcm.min_insertion_m", self.rcm.min_insertion_m, f"0 <= value < {self.joints[2].upper}"
            )


def _classic_joints() -> tuple[JointSpec, ...]:
    half_pi = math.pi / 2
    return (
        JointSpec(
            "outer_yaw", "yaw", "revolute", half_pi, 0.0, 0.0, half_pi, -1.588, 1.588, _V_YAW_PITCH, _A_YAW_PITCH
        ),
        JointSpec(
            "outer_pitch",
            "pitch",
            "revolute",
            -half_pi,
            0.0,
            0.0,
            -half_pi,
            -0.925025,
            0.925025,
            _V_YAW_PITCH,
            _A_YAW_PITCH,
        ),
        JointSpec(
            "outer_insertion",
            "insertion",
            "prismatic",
            half_pi,
            0.0,
            0.0,
            -0.4318,
            0.0,
            0.24,
            _V_INSERTION,
            _A_INSERTION,
        ),
        JointSpec("outer_roll", "roll", "revolute", 0.0, 0.0, 0.4162, 0.0, -4.53786, 4.53786, _V_WRIST, _A_WRIST),
        JointSpec(
            "outer_wrist_pitch",
            "wrist_pitch",
            "revolute",
            -half_pi,
            0.0,
            0.0,
            -half_pi,
            -1.39626,
            1.39626,
            _V_WRIST,
            _A_WRIST,
        ),
        JointSpec(
            "outer_wrist_yaw",
            "wrist_yaw",
            "revolute",
            -half_pi,
            0.0091,
            0.0,
            -half_pi,
            -1.39626,
            1.39626,
            _V_WRIST,
            _A_WRIST,
        ),
    )


def _classic_400006() -> PsmSpec:
    return PsmSpec(arm="classic", tool="400006", joints=_classic_joints(), jaw_lower=-0.698132, jaw_upper=1.39626)


def _si_420006() -> PsmSpec:
    j = list(_classic_joints())
    j[0] = replace(j[0], lower=-2.964, upper=2.964)
    j[1] = replace(j[1], lower=-1.265, upper=1.301)
    j[2] = replace(j[2], lower=0.0, upper=0.29, offset=-0.4826)
    j[3] = replace(j[3], d=0.4670)
    return PsmSpec(arm="si", tool="420006", joints=tuple(j), jaw_lower=-0.349066, jaw_upper=1.39626)


_VARIANTS = {("classic", "400006"): _classic_400006, ("si", "420006"): _si_420006}
#: Known arm generations.
ARMS = ("classic", "si")
#: Known instruments.
TOOLS = ("400006", "420006")


def psm_spec(arm: str = "classic", tool: str | None = None) -> PsmSpec:
    """Return the specification of a PSM variant.

    Args:
        arm: ``"classic"`` (dVRK Classic PSM) or ``"si"`` (da Vinci Si PSM).
        tool: Instrument part number; defaults to the arm's large needle driver
            (``"400006"`` for classic, ``"420006"`` for si).

    Raises:
        UnknownVariantError: For an unknown arm, tool, or an arm/tool pair that does not mount.
    """
    if arm not in ARMS:
        raise UnknownVariantError("arm", arm, ARMS)
    if tool is None:
        tool = "400006" if arm == "classic" else "420006"
    if tool not in TOOLS:
        raise UnknownVariantError("tool", tool, TOOLS)
    try:
        return _VARIANTS[(arm, tool)]()
    except KeyError:
        pairs = [f"{a}/{t}" for a, t in _VARIANTS]
        raise UnknownVariantError("arm/tool", f"{arm}/{tool}", pairs) from None
