"""Conversions between ROS 2 messages and the project's values (arrays, 4x4 poses, typed states).

Joint vectors follow the dVRK order of :data:`hardware_if.common.crtk.JOINT_NAMES`; a ``JointState`` whose
names are in another order is reordered by name, and one that lacks a joint is rejected. Poses are 4x4
homogeneous transforms [m]; ROS quaternions are (x, y, z, w).
"""

from __future__ import annotations

import array
import math
from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time  # type: ignore[import-untyped]
from geometry_msgs.msg import PoseStamped, WrenchStamped  # type: ignore[import-untyped]
from sensor_msgs.msg import JointState  # type: ignore[import-untyped]

from hardware_if.common.crtk import JOINT_NAMES
from psm_control.errors import JointVectorError

__all__ = [
    "joint_state",
    "joint_state_positions",
    "joint_state_velocities",
    "matrix_to_quaternion",
    "pose_matrix",
    "pose_stamped",
    "quaternion_to_matrix",
    "seconds_to_time",
    "time_to_seconds",
    "wrench_force",
    "wrench_stamped",
]


def seconds_to_time(stamp_s: float) -> Time:
    """A ``builtin_interfaces/Time`` from seconds."""
    sec = math.floor(stamp_s)
    return Time(sec=sec, nanosec=min(round((stamp_s - sec) * 1e9), 999_999_999))


def time_to_seconds(stamp: Time) -> float:
    """Seconds from a ``builtin_interfaces/Time``."""
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def joint_state(
    names: Sequence[str],
    position: Sequence[float] | np.ndarray,
    velocity: Sequence[float] | np.ndarray | None = None,
    effort: Sequence[float] | np.ndarray | None = None,
    stamp_s: float = 0.0,
) -> JointState:
    """A ``sensor_msgs/JointState`` with the given names and vectors (velocity/effort may be empty)."""
    message = JointState()
    message.header.stamp = seconds_to_time(stamp_s)
    message.name = list(names)
    message.position = _doubles(position, "position")
    if velocity is not None:
        message.velocity = _doubles(velocity, "velocity")
    if effort is not None:
        message.effort = _doubles(effort, "effort")
    return message


def _doubles(values: Sequence[float] | np.ndarray, what: str) -> array.array[float]:
    """A ``float64[]`` field's value: the message keeps an ``array.array('d')`` as it is, without a copy."""
    vector = np.asarray(values, dtype=float)
    if vector.ndim != 1:
        raise JointVectorError(f"JointState {what} must be a vector, got shape {vector.shape}")
    return array.array("d", vector.tobytes())


def _field(message: JointState, values: Sequence[float], names: Sequence[str], what: str) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if not message.name or list(message.name) == list(names):
        if array.shape != (len(names),):
            raise JointVectorError(f"JointState {what} has {array.shape[0]} values, expected {len(names)}")
        return array
    index = {name: i for i, name in enumerate(message.name)}
    missing = [name for name in names if name not in index]
    if missing:
        raise JointVectorError(f"JointState lacks joints {missing}; it has {list(message.name)}")
    if array.shape != (len(message.name),):
        raise JointVectorError(f"JointState {what} has {array.shape[0]} values for {len(message.name)} names")
    return array[[index[name] for name in names]]


def joint_state_positions(message: JointState, names: Sequence[str] = JOINT_NAMES) -> np.ndarray:
    """Positions of ``names`` (default: the arm's six joints) from a ``JointState``.

    Raises:
        JointVectorError: A joint is missing or the vector's length does not match.
    """
    return _field(message, message.position, names, "position")


def joint_state_velocities(message: JointState, names: Sequence[str] = JOINT_NAMES) -> np.ndarray:
    """Velocities of ``names`` from a ``JointState``; zeros when the message carries none."""
    if len(message.velocity) == 0:
        return np.zeros(len(names))
    return _field(message, message.velocity, names, "velocity")


def quaternion_to_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    """3x3 rotation matrix of a (normalised here) quaternion."""
    x, y, z, w = float(x), float(y), float(z), float(w)
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if not math.isfinite(norm) or norm < 1e-12:
        raise JointVectorError(f"quaternion {[x, y, z, w]} has no orientation")
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_to_quaternion(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """Quaternion (x, y, z, w), w >= 0, of a 3x3 rotation matrix."""
    # Plain floats: numpy's per-element overhead made this most of a pose message's cost.
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = np.asarray(rotation, dtype=float)[:3, :3].tolist()
    trace = r00 + r11 + r22
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        x, y, z, w = (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s, 0.25 * s
    elif r00 > r11 and r00 > r22:
        s = 2.0 * math.sqrt(1.0 + r00 - r11 - r22)
        x, y, z, w = 0.25 * s, (r01 + r10) / s, (r02 + r20) / s, (r21 - r12) / s
    elif r11 > r22:
        s = 2.0 * math.sqrt(1.0 + r11 - r00 - r22)
        x, y, z, w = (r01 + r10) / s, 0.25 * s, (r12 + r21) / s, (r02 - r20) / s
    else:
        s = 2.0 * math.sqrt(1.0 + r22 - r00 - r11)
        x, y, z, w = (r02 + r20) / s, (r12 + r21) / s, 0.25 * s, (r10 - r01) / s
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if w < 0.0:
        norm = -norm
    return x / norm, y / norm, z / norm, w / norm


def pose_stamped(transform: np.ndarray, frame_id: str, stamp_s: float = 0.0) -> PoseStamped:
    """A ``geometry_msgs/PoseStamped`` from a 4x4 transform [m]."""
    T = np.asarray(transform, dtype=float)
    message = PoseStamped()
    message.header.stamp = seconds_to_time(stamp_s)
    message.header.frame_id = frame_id
    message.pose.position.x, message.pose.position.y, message.pose.position.z = T[:3, 3].tolist()
    o = message.pose.orientation
    o.x, o.y, o.z, o.w = matrix_to_quaternion(T[:3, :3])
    return message


def pose_matrix(message: PoseStamped) -> np.ndarray:
    """The 4x4 transform [m] of a ``geometry_msgs/PoseStamped``."""
    p, o = message.pose.position, message.pose.orientation
    T = np.eye(4)
    T[:3, :3] = quaternion_to_matrix(o.x, o.y, o.z, o.w)
    T[:3, 3] = (p.x, p.y, p.z)
    return T


def wrench_stamped(
    force_n: np.ndarray, torque_nm: np.ndarray | None = None, frame_id: str = "", stamp_s: float = 0.0
) -> WrenchStamped:
    """A ``geometry_msgs/WrenchStamped`` from a force [N] (and torque [N m])."""
    message = WrenchStamped()
    message.header.stamp = seconds_to_time(stamp_s)
    message.header.frame_id = frame_id
    f = message.wrench.force
    f.x, f.y, f.z = np.asarray(force_n, dtype=float).tolist()
    if torque_nm is not None:
        t = message.wrench.torque
        t.x, t.y, t.z = np.asarray(torque_nm, dtype=float).tolist()
    return message


def wrench_force(message: WrenchStamped) -> np.ndarray:
    """The force (3,) [N] of a ``geometry_msgs/WrenchStamped``."""
    f = message.wrench.force
    return np.array([f.x, f.y, f.z], dtype=float)
