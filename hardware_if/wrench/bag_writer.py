"""Joint logs written as a rosbag2 bag of ``/<ARM>/measured_js``, as ``ros2 bag record`` writes it.

``calibrate-wrench --record`` keeps its excitation this way, so that the fit can be repeated offline
(``calibrate-wrench --from BAG``) and the log read by any rosbag2 tool. The writer is rosbags' own (MCAP
storage), the library :mod:`~hardware_if.wrench.joint_logs` reads bags with; no ROS install is needed.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from hardware_if.wrench.joint_logs import JOINT_NAMES, JointLog

__all__ = ["write_joint_bag"]

_MSGTYPE = "sensor_msgs/msg/JointState"
#: Gap between two logs written into one bag [s].
_GAP_S = 1.0


def write_joint_bag(path: str | Path, arm: str, logs: Sequence[JointLog], start_s: float = 0.0) -> Path:
    """Write ``logs`` one after the other as ``/<arm>/measured_js`` into a new MCAP bag folder ``path``.

    Args:
        path: The bag's folder (must not exist, as ``ros2 bag record -o`` wants it).
        arm: The arm's namespace.
        logs: The joint logs, in time order; each sample's stamp is ``start_s`` plus its time, the logs
            ``_GAP_S`` apart.
        start_s: The first sample's stamp [s].
    """
    from rosbags.rosbag2 import StoragePlugin, Writer  # rosbags: imported where bags are written
    from rosbags.typesys import Stores, get_typestore

    typestore = get_typestore(Stores.ROS2_JAZZY)
    types = typestore.types
    offset = float(start_s)
    with Writer(Path(path), version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection(f"/{arm}/measured_js", _MSGTYPE, typestore=typestore)
        for log in logs:
            for k in range(len(log.t_s)):
                stamp_s = offset + float(log.t_s[k])
                nanoseconds = round(stamp_s * 1e9)
                stamp = types["builtin_interfaces/msg/Time"](
                    sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000
                )
                message = types["sensor_msgs/msg/JointState"](
                    header=types["std_msgs/msg/Header"](stamp=stamp, frame_id=""),
                    name=list(JOINT_NAMES),
                    position=np.asarray(log.q[k], dtype=np.float64),
                    velocity=np.asarray(log.qd[k], dtype=np.float64),
                    effort=np.asarray(log.effort[k], dtype=np.float64),
                )
                writer.write(connection, nanoseconds, typestore.serialize_cdr(message, _MSGTYPE))
            if len(log.t_s):
                offset += float(log.t_s[-1]) + _GAP_S
    return Path(path)
