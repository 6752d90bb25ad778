"""The dVRK's CRTK interface over ROS 2: topic names, message types, QoS, frames and tolerances.

Names and numbers are the dVRK 2.4's (``shared/facts/dvrk.md``). Periodic state topics are published
every 10 ms with QoS depth 5, reliable, volatile; event topics (``operating_state``, ``error``, ...)
use depth 100, transient-local, so a late subscriber still gets the current state. All ``*_cp``
topics are ``geometry_msgs/PoseStamped``; ``measured_cp`` is in the frame ``<arm>_base``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from psm_control.errors import ConfigurationError
from psm_control.spec import DVRK_JOINT_NAMES

__all__ = [
    "COMMAND_TOPICS",
    "CONSOLE_INPUT_TOPICS",
    "DEFAULT_ARM",
    "DEFAULT_RATE_HZ",
    "EVENT_TOPICS",
    "JAW_JOINT_NAME",
    "JOINT_NAMES",
    "MOTION_TOPICS",
    "OPERATING_STATES",
    "SERVICES",
    "STATE_COMMANDS",
    "STATE_TOPICS",
    "TRACKING_TOLERANCE",
    "ArmTopics",
    "event_qos",
    "periodic_qos",
]

#: Arm namespace used when none is given.
DEFAULT_ARM = "PSM1"
#: The dVRK's default publishing rate of periodic topics [Hz].
DEFAULT_RATE_HZ = 100.0
#: Joint names on ``measured_js``, in order.
JOINT_NAMES = DVRK_JOINT_NAMES
#: Joint name on ``jaw/measured_js``.
JAW_JOINT_NAME = "jaw"
#: Values of ``crtk_msgs/OperatingState.state``.
OPERATING_STATES = ("DISABLED", "ENABLED", "PAUSED", "FAULT")
#: Strings accepted on ``state_command``.
STATE_COMMANDS = ("enable", "disable", "home", "unhome")
#: dVRK tracking-error trip, measured vs setpoint (yaw, pitch [rad], insertion [m], roll, wrist [rad]).
TRACKING_TOLERANCE = np.array([0.5, 0.5, 0.05, 0.6, 0.6, 0.6])
#: dVRK tracking-error trip for the jaw [rad].
JAW_TRACKING_TOLERANCE = 0.6

#: Periodic topics and events, by QoS class.
PERIODIC_DEPTH = 5
EVENT_DEPTH = 100

#: Periodic state topics the arm publishes (QoS :func:`periodic_qos`).
STATE_TOPICS = (
    "measured_js",
    "setpoint_js",
    "measured_cp",
    "setpoint_cp",
    "local/measured_cp",
    "local/setpoint_cp",
    "jaw/measured_js",
    "jaw/setpoint_js",
    "body/measured_cf",
    "spatial/measured_cf",
    "measured_cv",
    "local/measured_cv",
    "body/jacobian",
    "spatial/jacobian",
)
#: Event topics the arm publishes (QoS :func:`event_qos`).
EVENT_TOPICS = ("operating_state", "error", "warning", "status", "goal_reached", "trajectory_j/ratio")
#: Motion topics a client publishes (QoS :func:`periodic_qos`).
MOTION_TOPICS = ("servo_jp", "move_jp", "servo_cp", "move_cp", "jaw/servo_jp", "jaw/move_jp")
#: Command topics a client publishes: motion and ``state_command`` (which uses :func:`event_qos`).
COMMAND_TOPICS = (*MOTION_TOPICS, "state_command")
#: The rest of the dVRK 2.4 console's inputs that its Python client publishes (``dvrk.psm``): relative and
#: effort commands, hold/free and settings. The simulated console serves them; this project's client does
#: not use them.
CONSOLE_INPUT_TOPICS = (
    "servo_jr",
    "move_jr",
    "servo_jf",
    "jaw/servo_jf",
    "body/servo_cf",
    "spatial/servo_cf",
    "hold",
    "free",
    "trajectory_j/set_ratio",
    "use_gravity_compensation",
    "body/set_cf_orientation_absolute",
    "emulate_tool_present",
)
#: The console's services (``crtk_msgs/srv``): forward kinematics (in ``<arm>_base`` and about the RCM)
#: and inverse kinematics.
SERVICES = ("forward_kinematics", "local/forward_kinematics", "inverse_kinematics")
_ALL_TOPICS = (*STATE_TOPICS, *EVENT_TOPICS, *COMMAND_TOPICS, *CONSOLE_INPUT_TOPICS, *SERVICES)

_ARM_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


def periodic_qos() -> Any:
    """QoS of the dVRK's periodic topics (state and motion commands): depth 5, reliable, volatile."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy  # the ros extra

    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=PERIODIC_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE,
    )


def event_qos() -> Any:
    """QoS of the dVRK's event topics (operating_state, error, ...): depth 100, transient-local."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy  # the ros extra

    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=EVENT_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )


@dataclass(frozen=True)
class ArmTopics:
    """Fully qualified CRTK topic names of one arm (``/PSM1/measured_js`` ...).

    Args:
        arm: Arm name, e.g. ``"PSM1"``; becomes the namespace.

    Raises:
        ConfigurationError: The arm name is not a valid ROS name token.
    """

    arm: str = DEFAULT_ARM

    def __post_init__(self) -> None:
        if not _ARM_NAME.match(self.arm):
            raise ConfigurationError("arm", self.arm, "a ROS name such as 'PSM1' (letters, digits, '_')")

    def topic(self, name: str) -> str:
        """The fully qualified name of a CRTK topic, e.g. ``topic("local/measured_cp")``.

        Raises:
            ConfigurationError: ``name`` is not one of :data:`STATE_TOPICS`, :data:`EVENT_TOPICS`,
                :data:`COMMAND_TOPICS`, :data:`CONSOLE_INPUT_TOPICS` or :data:`SERVICES` (a typo would
                otherwise listen on a topic nobody publishes).
        """
        if name not in _ALL_TOPICS:
            raise ConfigurationError("topic", name, "one of " + ", ".join(_ALL_TOPICS))
        return f"/{self.arm}/{name}"

    @property
    def base_frame_id(self) -> str:
        """``frame_id`` of ``measured_cp`` and ``setpoint_cp`` (e.g. ``PSM1_base``)."""
        return f"{self.arm}_base"

    @property
    def local_frame_id(self) -> str:
        """``frame_id`` of ``local/measured_cp``: the RCM (e.g. ``PSM1_rcm``)."""
        return f"{self.arm}_rcm"
