"""Free-space joint logs of a PSM (positions, velocities, efforts), read from the files dVRK users keep.

Layouts read by :func:`read_joint_log`:

* **rosbag2** (``ros2 bag record``), MCAP or sqlite3 storage, a bag folder or its storage file: the arm's
  ``/<ARM>/measured_js`` (``sensor_msgs/msg/JointState`` with efforts), read with the ``rosbags`` library
  (no ROS install). Joints are taken by name when the message names them (the dVRK's ``yaw``, ``pitch``,
  ``insertion``, ``roll``, ``wrist_pitch``, ``wrist_yaw``), else in that order; the time is the header's
  stamp (the bag's receive time when the stamp is zero). ``calibrate-wrench --record`` writes such a bag.
* **this project's deploy recordings** (MCAP, ``/deploy/measured``), when their measurements carry
  ``effort``.
* **WPI-AIM/dvrk_dynamics_identification** CSVs: 200 Hz, no header, 21 columns ``q[0:7], qd[7:14],
  tau[14:21]``, the wrist's two joints and the jaw in motor space: undone here with the large needle
  driver's coupling (positions ``q_joint = C q_motor``, efforts ``tau_joint = C^-T tau_motor``).
* **radiang/dvrk_parameter_identification**: a folder with ``data_position.csv``, ``data_velocity.csv`` and
  ``data_torque.csv`` (seven columns each, six joints and the jaw, joint space; a file with an eighth, leading
  column has the sample time in it), or a 9-column
  ``*_results.csv`` of its three-joint scripts (``q, qd, effort`` of yaw, pitch, insertion, 200 Hz). Files
  without a time column: the rate is 250 Hz for a folder whose name says ``250``, else 200 Hz, or ``rate_hz``.

Bad logs raise a :class:`JointLogError` subclass that names the file and what is wrong.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from psm_control.errors import InputFileError

__all__ = [
    "JOINT_NAMES",
    "LND_COUPLING",
    "JointLog",
    "JointLogError",
    "LogLayoutError",
    "MissingTopicError",
    "NoEffortsError",
    "NonFiniteLogError",
    "TruncatedLogError",
    "joint_log_from_ticks",
    "read_joint_log",
]

#: The dVRK's joint names on ``measured_js``, in order.
JOINT_NAMES = ("yaw", "pitch", "insertion", "roll", "wrist_pitch", "wrist_yaw")
#: The large needle driver's actuator-to-joint coupling of the wrist pitch, wrist yaw and jaw
#: (WPI-AIM/dvrk_dynamics_identification, ``M_motor2dvrk_q``, the dVRK's 400006 instrument).
LND_COUPLING = np.array([[1.0186, 0.0, 0.0], [-0.8306, 0.6089, 0.6089], [0.0, -1.2177, 1.2177]])
_MIN_SAMPLES = 10


class JointLogError(InputFileError):
    """A joint log cannot be used: the file and the reason are named.

    Attributes:
        path: The log, as given.
        reason: What is wrong.
    """

    def __init__(self, path: object, reason: str) -> None:
        self.reason = reason
        super().__init__("--from", path, reason)


class LogLayoutError(JointLogError):
    """Not a layout :func:`read_joint_log` reads (or unreadable as one)."""


class MissingTopicError(JointLogError):
    """A bag without the arm's ``measured_js`` (the topics it has are named)."""


class NoEffortsError(JointLogError):
    """Joint states without efforts (six per message are needed)."""


class NonFiniteLogError(JointLogError):
    """A NaN or infinite position, velocity or effort (the first sample and joint are named)."""


class TruncatedLogError(JointLogError):
    """A storage file that ends early (a recording cut off) and cannot be read."""


@dataclass(frozen=True)
class JointLog:
    """One free-space joint log: N samples of the six arm joints, in the dVRK's joint space.

    Attributes:
        source: Where it was read from.
        layout: ``rosbag2``, ``recording``, ``wpi`` or ``radiang``.
        t_s: Sample times (N,) [s], from 0.
        q: Joint positions (N, 6) [rad, m].
        qd: Joint velocities (N, 6).
        effort: Joint efforts (N, 6) [N m, N].
        joints: How many joints the log carries (3: yaw, pitch, insertion; the rest zero).
    """

    source: str
    layout: str
    t_s: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    effort: np.ndarray
    joints: int = 6

    @property
    def rate_hz(self) -> float:
        """The median sample rate [Hz]."""
        return float(1.0 / np.median(np.diff(self.t_s)))


def _checked(log: JointLog) -> JointLog:
    if len(log.t_s) < _MIN_SAMPLES:
        raise TruncatedLogError(log.source, f"{len(log.t_s)} samples; at least {_MIN_SAMPLES} are needed")
    for name in ("q", "qd", "effort"):
        values = getattr(log, name)
        bad = np.argwhere(~np.isfinite(values))
        if len(bad):
            sample, joint = (int(i) for i in bad[0])
            raise NonFiniteLogError(
                log.source, f"{name} of joint {JOINT_NAMES[joint]} is {values[sample, joint]} at sample {sample}"
            )
    if not np.all(np.diff(log.t_s) > 0.0):
        raise LogLayoutError(log.source, "sample times that increase")
    return log


def _from_motor_space(q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, ...]:
    """The WPI logs' wrist pitch, wrist yaw and jaw from motor space to the dVRK's joints."""
    q, qd, tau = q.copy(), qd.copy(), tau.copy()
    q[:, 4:7] = q[:, 4:7] @ LND_COUPLING.T
    qd[:, 4:7] = qd[:, 4:7] @ LND_COUPLING.T
    tau[:, 4:7] = tau[:, 4:7] @ np.linalg.inv(LND_COUPLING)  # tau_motor = C^T tau_joint
    return q, qd, tau


def _load_csv(path: Path) -> np.ndarray:
    try:
        values = np.loadtxt(path, delimiter=",", ndmin=2)
    except (OSError, ValueError) as e:
        raise LogLayoutError(path, f"comma-separated numbers ({e})") from e
    return values


def _rate(path: Path, rate_hz: float | None) -> float:
    if rate_hz is not None:
        return float(rate_hz)
    return 250.0 if "250" in path.name else 200.0


def _read_csv(path: Path, rate_hz: float | None) -> JointLog:
    values = _load_csv(path)
    n = len(values)
    t_s = np.arange(n) / (rate_hz if rate_hz is not None else 200.0)
    if values.shape[1] == 21:
        q, qd, tau = _from_motor_space(values[:, 0:7], values[:, 7:14], values[:, 14:21])
        return _checked(JointLog(str(path), "wpi", t_s, q[:, :6], qd[:, :6], tau[:, :6]))
    if values.shape[1] == 9:
        pad = np.zeros((n, 3))
        return _checked(
            JointLog(
                str(path),
                "radiang",
                t_s,
                np.hstack([values[:, 0:3], pad]),
                np.hstack([values[:, 3:6], pad]),
                np.hstack([values[:, 6:9], pad]),
                joints=3,
            )
        )
    raise LogLayoutError(
        path, f"{values.shape[1]} columns: a WPI log has 21 (q, qd, tau x 7), a three-joint radiang log 9"
    )


def _read_radiang_folder(path: Path, rate_hz: float | None) -> JointLog:
    parts = [_load_csv(path / f"data_{name}.csv") for name in ("position", "velocity", "torque")]
    n = min(len(p) for p in parts)
    times = [p[:n, 0] for p in parts if p.shape[1] == 8 and np.all(np.diff(p[:n, 0]) > 0.0)]
    # Some of its folders (Data_Pos_6.19.2017) lead a file with the sample time [s]: seven joints after it.
    parts = [p[:, 1:] if p.shape[1] == 8 else p for p in parts]
    if any(p.shape[1] < 6 for p in parts):
        raise LogLayoutError(path, "data_position/velocity/torque.csv with six joint columns at least")
    q, qd, tau = (p[:n, :6] for p in parts)
    t_s = times[0] if times and rate_hz is None else np.arange(n) / _rate(path, rate_hz)
    return _checked(JointLog(str(path), "radiang", t_s, q, qd, tau))


def _reorder(names: list[str], values: np.ndarray) -> np.ndarray:
    if len(names) >= 6 and all(name in names for name in JOINT_NAMES):
        return np.array([values[names.index(name)] for name in JOINT_NAMES])
    return values[:6]


def _read_bag(path: Path, arm: str) -> JointLog:
    from rosbags.rosbag2 import Reader  # rosbags, a package dependency: imported where a bag is read
    from rosbags.typesys import Stores, get_typestore

    from hardware_if.wrench.bag_files import check_bag_files  # rosbags decompresses without bounds: checked first

    try:
        check_bag_files(path, field="--from")
    except InputFileError as e:
        raise LogLayoutError(path, e.allowed) from e
    topic = f"/{arm}/measured_js"
    typestore = get_typestore(Stores.ROS2_JAZZY)
    times: list[float] = []
    q: list[np.ndarray] = []
    qd: list[np.ndarray] = []
    effort: list[np.ndarray] = []
    try:
        with Reader(path) as reader:
            connections = [c for c in reader.connections if c.topic == topic]
            if not connections:
                topics = sorted({c.topic for c in reader.connections}) or ["none"]
                raise MissingTopicError(path, f"a bag with {topic}; it has {', '.join(topics)} (--arm picks the arm)")
            for connection, stamp_ns, raw in reader.messages(connections=connections):
                message: Any = typestore.deserialize_cdr(raw, connection.msgtype)
                names = list(message.name)
                if len(message.effort) < 6:
                    raise NoEffortsError(
                        path, f"{topic} with six efforts per message; message {len(times)} has {len(message.effort)}"
                    )
                header = message.header.stamp
                stamp = header.sec + 1e-9 * header.nanosec
                times.append(stamp if stamp > 0.0 else 1e-9 * stamp_ns)
                q.append(_reorder(names, np.asarray(message.position, dtype=float)))
                qd.append(
                    _reorder(names, np.asarray(message.velocity, dtype=float))
                    if len(message.velocity) >= 6
                    else np.full(6, np.nan)
                )
                effort.append(_reorder(names, np.asarray(message.effort, dtype=float)))
    except JointLogError:
        raise
    except Exception as e:  # rosbags' own errors (ReaderError, a torn MCAP's struct or EOF error)
        raise TruncatedLogError(path, f"a complete rosbag2 bag ({type(e).__name__}: {e})") from e
    if not times:
        raise MissingTopicError(path, f"messages on {topic}; it has none")
    t_s = np.asarray(times) - times[0]
    q_arr = np.asarray(q)
    qd_arr = np.asarray(qd)
    if np.all(np.isnan(qd_arr)):  # a console that sends no velocities: the positions' derivative
        qd_arr = np.gradient(q_arr, t_s, axis=0)
    return _checked(JointLog(str(path), "rosbag2", t_s, q_arr, qd_arr, np.asarray(effort)))


def joint_log_from_ticks(
    source: str, layout: str, ticks: Sequence[tuple[float, np.ndarray, np.ndarray, np.ndarray]]
) -> JointLog:
    """A joint log of a control loop's ticks ``(stamp_s, q, qd, effort)``, time from the first.

    A tick that read the measurement the tick before read too repeats its stamp: it is the same sample, and
    only its first reading is kept.
    """
    kept = [tick for k, tick in enumerate(ticks) if k == 0 or tick[0] > ticks[k - 1][0]]
    t_s = np.array([float(tick[0]) for tick in kept])
    return JointLog(
        source,
        layout,
        t_s - t_s[0],
        np.array([tick[1] for tick in kept], dtype=float),
        np.array([tick[2] for tick in kept], dtype=float),
        np.array([tick[3] for tick in kept], dtype=float),
    )


def _read_recording(path: Path) -> JointLog:
    """A deploy recording's ``/deploy/measured`` ticks, read and checked within the recordings' limits."""
    from array import array

    from hardware_if.recording.schema import RecordingMessages, as_float  # mcap: the deploy's own format

    topic = "/deploy/measured"
    log_times, values = array("q"), array("d")  # per tick: stamp, q, qd, effort (19 numbers)
    try:
        for _, index, log_time_ns, row in RecordingMessages(path, [topic], field="--from"):
            if "effort" not in row:
                raise NoEffortsError(
                    path, f"measurements with efforts ('effort' in {topic}); message {index} of this recording has none"
                )
            for key in ("stamp_s", "qd"):
                if row.get(key) is None:
                    raise LogLayoutError(path, f"{topic} message {index}: {key} must be given; it is {row.get(key)}")
            log_times.append(log_time_ns)
            values.append(as_float(row["stamp_s"]))
            for key in ("q", "qd", "effort"):
                values.extend(as_float(v) for v in row[key])
    except InputFileError as e:
        if isinstance(e, JointLogError):
            raise
        raise LogLayoutError(path, e.allowed) from e
    if not log_times:
        raise MissingTopicError(path, f"a recording with {topic} messages")
    table = np.frombuffer(values).reshape(-1, 19)[np.argsort(log_times, kind="stable")]  # in log-time order
    ticks = [(float(row[0]), row[1:7], row[7:13], row[13:19]) for row in table]
    return _checked(joint_log_from_ticks(str(path), "recording", ticks))


def _is_recording(path: Path) -> bool:
    """An MCAP file written by this project's deploy (its library), not by ``ros2 bag`` (profile ``ros2``)."""
    from hardware_if.recording.reader import RecordingFileError, read_header  # mcap: the recordings' own format

    try:
        header = read_header(path, field="--from")
    except RecordingFileError:  # not a readable MCAP header: the bag reader then names what is wrong
        return False
    return header.library == "tissue-retract"


def read_joint_log(path: str | Path, *, arm: str = "PSM1", rate_hz: float | None = None) -> JointLog:
    """Read one free-space joint log (see the module notes for the layouts).

    Args:
        path: A bag folder or storage file, a recording, a CSV, or a folder of CSVs.
        arm: The arm's namespace in a bag (``/<arm>/measured_js``).
        rate_hz: The sample rate of a CSV log, which carries no time; default by layout.

    Raises:
        JointLogError: The file is missing or not a usable log (a subclass says why).
    """
    path = Path(path)
    if not path.exists():
        raise LogLayoutError(path, "an existing bag, recording, CSV file or folder")
    if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0.0):
        raise LogLayoutError(path, f"a sample rate > 0 (got {rate_hz})")
    if path.is_dir():
        if (path / "metadata.yaml").exists():
            return _read_bag(path, arm)
        if (path / "data_torque.csv").exists():
            return _read_radiang_folder(path, rate_hz)
        raise LogLayoutError(path, "a rosbag2 folder (metadata.yaml) or a folder with data_torque.csv")
    suffix = path.suffix.lower()
    if suffix == ".mcap":
        return _read_recording(path) if _is_recording(path) else _read_bag(path, arm)
    if suffix == ".db3":
        return _read_bag(path, arm)
    if suffix == ".csv":
        return _read_csv(path, rate_hz)
    raise LogLayoutError(path, "a .mcap or .db3 bag, a bag folder, a .csv log or a folder of CSVs")
