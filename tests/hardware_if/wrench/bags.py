"""Bags written as ``ros2 bag record`` writes them, with rosbags' own writer (for the joint-log tests)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from hardware_if.wrench.joint_logs import JOINT_NAMES

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def _joint_state(
    t_s: float, names: list[str], position: np.ndarray, velocity: np.ndarray, effort: np.ndarray
) -> object:
    types = TYPESTORE.types
    stamp = types["builtin_interfaces/msg/Time"](sec=int(t_s), nanosec=round((t_s % 1.0) * 1e9))
    header = types["std_msgs/msg/Header"](stamp=stamp, frame_id="")
    return types["sensor_msgs/msg/JointState"](
        header=header,
        name=names,
        position=np.asarray(position, dtype=np.float64),
        velocity=np.asarray(velocity, dtype=np.float64),
        effort=np.asarray(effort, dtype=np.float64),
    )


def write_bag(
    path: Path,
    q: np.ndarray,
    qd: np.ndarray,
    effort: np.ndarray,
    *,
    topic: str = "/PSM1/measured_js",
    rate_hz: float = 100.0,
    storage: StoragePlugin = StoragePlugin.MCAP,
    names: list[str] | None = None,
) -> Path:
    """Write joint states as ``ros2 bag record`` would, with rosbags' writer (names in ``names`` order)."""
    order = names if names is not None else list(JOINT_NAMES)
    index = [JOINT_NAMES.index(name) for name in order]
    msgtype = "sensor_msgs/msg/JointState"
    with Writer(path, version=9, storage_plugin=storage) as writer:
        connection = writer.add_connection(topic, msgtype, typestore=TYPESTORE)
        for k in range(len(q)):
            t_s = 100.0 + k / rate_hz
            message = _joint_state(
                t_s, order, q[k][index], qd[k][index], effort[k][index] if effort.shape[1] else effort[k]
            )
            writer.write(connection, int(t_s * 1e9), TYPESTORE.serialize_cdr(message, msgtype))
    return path
