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

A CSV log carries no time, and a layout's rate is not always the log's: WPI's recording
script runs its loop at ``sampling_rate * speedscale`` (``run_robot_with_vel.py``), so its ``0.5_scale`` logs are
100 Hz, not 200. Read at 200 Hz their accelerations were twice the arm's, and a calibration fitted at full speed
added the inertia they did not have (2.96 -> 2.82 N RMS on the half-speed log; 2.96 -> 1.07 N read at its own
rate). So without ``rate_hz`` the rate the log's own positions and velocities imply is taken when the arm's three
outer joints agree on it within :data:`RATE_AGREEMENT` and it is more than :data:`RATE_MISMATCH` from the layout's
(:attr:`JointLog.rate_note` says so).

Bad logs raise a :class:`JointLogError` subclass that names the file and what is wrong. A file is opened only
when it is a regular file of at most :data:`MAX_LOG_BYTES` (a FIFO named ``.csv`` would block, a link to
``/dev/zero`` never ends), and a CSV log is read to at most :data:`MAX_SAMPLES` rows.

What a fit or a check may take from a log that was read is :func:`check_free_space_log`'s: finite values within
the arm's ranges, efforts that vary on every joint the log carries, enough samples to filter.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from psm_control.errors import InputFileError
from psm_control.inputs import check_regular_file
from psm_control.spec import psm_spec

__all__ = [
    "EFFORT_SPREAD_FLOOR",
    "JOINT_NAMES",
    "JOINT_RANGE_MARGIN",
    "LND_COUPLING",
    "MAX_EFFORT",
    "MAX_LOG_BYTES",
    "MAX_SAMPLES",
    "MIN_SAMPLES",
    "RATE_AGREEMENT",
    "RATE_MISMATCH",
    "SPEED_FACTOR",
    "ImplausibleLogError",
    "JointLog",
    "JointLogError",
    "LogLayoutError",
    "MissingTopicError",
    "NoEffortsError",
    "NonFiniteLogError",
    "StillEffortsError",
    "TooFewSamplesError",
    "TooLongLogError",
    "TruncatedLogError",
    "check_free_space_log",
    "implied_rate_hz",
    "joint_log_from_ticks",
    "read_joint_log",
]

#: The dVRK's joint names on ``measured_js``, in order.
JOINT_NAMES = ("yaw", "pitch", "insertion", "roll", "wrist_pitch", "wrist_yaw")
#: The large needle driver's actuator-to-joint coupling of the wrist pitch, wrist yaw and jaw
#: (WPI-AIM/dvrk_dynamics_identification, ``M_motor2dvrk_q``, the dVRK's 400006 instrument).
LND_COUPLING = np.array([[1.0186, 0.0, 0.0], [-0.8306, 0.6089, 0.6089], [0.0, -1.2177, 1.2177]])
_MIN_SAMPLES = 10
#: Largest log file read [bytes] (512 MiB): an hour of a WPI-layout CSV at 200 Hz is about 310 MB.
MAX_LOG_BYTES = 512 * 1024 * 1024
#: Most samples a log may have: an hour at 200 Hz, the public logs' rate (a fit streams its regressor, so its
#: memory does not grow with this; the per-sample arrays a log keeps do, about 0.5 KB a sample).
MAX_SAMPLES = 720_000
#: Fewest samples a fit or a check takes from one log (after the samples near the RCM are left out): the
#: velocities are filtered at 4 Hz forwards and backwards, and a log shorter than that filter's period (0.25 s,
#: 50 samples at 200 Hz) has no accelerations to speak of; the filter itself needs more than 3 x (order + 1) = 9.
MIN_SAMPLES = 60
#: Margin beyond the Classic PSM's joint ranges (:func:`psm_control.spec.psm_spec`) a log's positions may reach
#: [rad on the revolute joints, m on the insertion]: the public logs reach 2 mm below the insertion's 0 (homing)
#: and stay within the revolute ranges; an encoder off by more than this is not the arm the model describes.
JOINT_RANGE_MARGIN = (0.1, 0.1, 0.01, 0.1, 0.1, 0.1)
#: Largest joint speed a log may show, as a multiple of the dVRK's move_jp velocity limits (90 deg/s on yaw and
#: pitch, 0.2 m/s on the insertion, 1080 deg/s on the wrist): the public logs' fastest is 1.6 x (the insertion at
#: 0.32 m/s).
SPEED_FACTOR = 10.0
#: Largest joint effort a log may show [N m on the revolute joints, N on the insertion]: 20 x the largest on the
#: public PSMs' logs (5.0 N on the insertion), beyond what the PSM's motors give.
MAX_EFFORT = 100.0
#: How closely the yaw, pitch and insertion must agree on the sample rate their positions and velocities imply
#: (the ratio of the highest to the lowest, less 1) before a CSV log's rate is taken from them: the public WPI
#: logs' agree within 0.4 %; radiang's three-joint ``results2`` logs differ 2.7 x (their velocities are not the
#: positions' derivative on every joint), and keep their layout's rate.
RATE_AGREEMENT = 0.05
#: How far from its layout's rate a CSV log's implied rate must be to be taken instead (relative): WPI's half-speed
#: logs imply 0.50 x; a console's velocity filter biases the estimate by a few per cent (radiang's 250 Hz folders
#: imply 230-234 Hz), which stays with the layout's rate.
RATE_MISMATCH = 0.25
#: Smallest spread (standard deviation) of each carried joint's efforts [N m, or N on the insertion]: an arm that
#: moves under its own dynamics shows at least its motor currents' noise (the public logs' quietest joint, radiang's
#: roll held at 0, spreads by 4e-4 N m); a console that reports the exact force sends zeros (or a constant).
EFFORT_SPREAD_FLOOR = 1e-4


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


class TooFewSamplesError(JointLogError):
    """Fewer samples than a fit or a check needs (:data:`MIN_SAMPLES`)."""


class TooLongLogError(JointLogError):
    """More samples than a log may have (:data:`MAX_SAMPLES`)."""


class ImplausibleLogError(JointLogError):
    """Finite values no PSM gives: a joint outside its range, a speed or an effort beyond the arm's (named)."""


class StillEffortsError(JointLogError):
    """Efforts that do not vary on a joint the log carries: no arm moving under its own dynamics (all zero: a
    console that reports the exact force, or sends no efforts)."""


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
        rate_note: Where a CSV log's sample rate came from when not from its layout or ``rate_hz``, for a user
            (``100.5 Hz, from its positions and velocities (its layout's 200 Hz does not match them)``); else "".
    """

    source: str
    layout: str
    t_s: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    effort: np.ndarray
    joints: int = 6
    rate_note: str = ""

    @property
    def rate_hz(self) -> float:
        """The median sample rate [Hz]."""
        return float(1.0 / np.median(np.diff(self.t_s)))


def _checked(log: JointLog) -> JointLog:
    if len(log.t_s) < _MIN_SAMPLES:
        raise TruncatedLogError(log.source, f"{len(log.t_s)} samples; at least {_MIN_SAMPLES} are needed")
    if len(log.t_s) > MAX_SAMPLES:
        raise TooLongLogError(
            log.source, f"at most {MAX_SAMPLES} samples (an hour at 200 Hz; this log has {len(log.t_s)}): split it"
        )
    _check_finite(log)
    if not np.all(np.diff(log.t_s) > 0.0):
        raise LogLayoutError(log.source, "sample times that increase")
    return log


def _check_finite(log: JointLog) -> None:
    """Refuse a log with a non-finite position, velocity or effort, naming the first.

    Raises:
        NonFiniteLogError: The first non-finite value, its joint and sample.
    """
    for name in ("q", "qd", "effort"):
        values = getattr(log, name)
        bad = np.argwhere(~np.isfinite(values))
        if len(bad):
            sample, joint = (int(i) for i in bad[0])
            raise NonFiniteLogError(
                log.source, f"{name} of joint {JOINT_NAMES[joint]} is {values[sample, joint]} at sample {sample}"
            )


def check_free_space_log(log: JointLog, *, min_samples: int = MIN_SAMPLES) -> None:
    """Refuse a log that does not show an arm moving under its own dynamics, before anything is fitted on it.

    Checked: at least ``min_samples`` samples; finite positions, velocities and efforts; positions within the
    Classic PSM's joint ranges widened by :data:`JOINT_RANGE_MARGIN`; speeds within :data:`SPEED_FACTOR` x the
    dVRK's move_jp limits; efforts within :data:`MAX_EFFORT`; and on every joint the log carries, efforts that
    spread by at least :data:`EFFORT_SPREAD_FLOOR`.

    Raises:
        JointLogError: A subclass naming the first thing wrong: :class:`TooFewSamplesError`,
            :class:`NonFiniteLogError`, :class:`ImplausibleLogError` or :class:`StillEffortsError`.
    """
    n = len(log.t_s)
    if n < min_samples:
        raise TooFewSamplesError(
            log.source,
            f"at least {min_samples} samples to filter and fit (this log has {n}; its velocities are filtered at "
            "4 Hz: record a few seconds or more)",
        )
    _check_finite(log)
    spec = psm_spec()
    margin = np.asarray(JOINT_RANGE_MARGIN)
    units = ("rad", "rad", "m", "rad", "rad", "rad")
    lower, upper = spec.lower - margin, spec.upper + margin
    for joint in range(log.joints):
        column = log.q[:, joint]
        outside = np.flatnonzero((column < lower[joint]) | (column > upper[joint]))
        if len(outside):
            k = int(outside[0])
            raise ImplausibleLogError(
                log.source,
                f"joint positions within the PSM's ranges (+-{margin[joint]:g} {units[joint]}): {JOINT_NAMES[joint]} "
                f"is {column[k]:g} {units[joint]} at sample {k}, its range {spec.lower[joint]:g} to "
                f"{spec.upper[joint]:g} {units[joint]}",
            )
    fastest = SPEED_FACTOR * spec.velocity_limit
    for joint in range(log.joints):
        k = int(np.argmax(np.abs(log.qd[:, joint])))
        if abs(log.qd[k, joint]) > fastest[joint]:
            raise ImplausibleLogError(
                log.source,
                f"joint speeds within {SPEED_FACTOR:g} x the dVRK's move_jp limits: {JOINT_NAMES[joint]} moves at "
                f"{log.qd[k, joint]:g} {units[joint]}/s at sample {k}, above {fastest[joint]:g}",
            )
        k = int(np.argmax(np.abs(log.effort[:, joint])))
        if abs(log.effort[k, joint]) > MAX_EFFORT:
            raise ImplausibleLogError(
                log.source,
                f"joint efforts of at most {MAX_EFFORT:g} N m (N on the insertion), as a PSM's motors give: "
                f"{JOINT_NAMES[joint]}'s is {log.effort[k, joint]:g} at sample {k}",
            )
    spread = np.std(log.effort[:, : log.joints], axis=0)
    if not np.any(log.effort[:, : log.joints]):
        raise StillEffortsError(
            log.source,
            "a log of an arm moving under its own dynamics, whose efforts vary (every effort in this log is 0: its "
            "console reports the exact force, as sim-dvrk --wrench ideal does, or sends no efforts; an exact "
            "console needs no calibration)",
        )
    still = [JOINT_NAMES[j] for j in range(log.joints) if spread[j] < EFFORT_SPREAD_FLOOR]
    if still:
        raise StillEffortsError(
            log.source,
            f"efforts that vary on every joint the log carries, by at least {EFFORT_SPREAD_FLOOR:g} N m or N "
            f"(standard deviation); {', '.join(still)} do not (spread "
            f"{', '.join(f'{spread[JOINT_NAMES.index(j)]:.3g}' for j in still)}): not an arm moving under its own "
            "dynamics",
        )


def _from_motor_space(q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, ...]:
    """The WPI logs' wrist pitch, wrist yaw and jaw from motor space to the dVRK's joints."""
    q, qd, tau = q.copy(), qd.copy(), tau.copy()
    q[:, 4:7] = q[:, 4:7] @ LND_COUPLING.T
    qd[:, 4:7] = qd[:, 4:7] @ LND_COUPLING.T
    tau[:, 4:7] = tau[:, 4:7] @ np.linalg.inv(LND_COUPLING)  # tau_motor = C^T tau_joint
    return q, qd, tau


def _load_csv(path: Path) -> np.ndarray:
    check_regular_file(path, "--from", MAX_LOG_BYTES)
    try:
        with warnings.catch_warnings():  # an empty file: numpy warns, then the row count below says so
            warnings.simplefilter("ignore", UserWarning)
            values = np.loadtxt(path, delimiter=",", ndmin=2, max_rows=MAX_SAMPLES + 1)
    except (OSError, ValueError) as e:
        raise LogLayoutError(path, f"comma-separated numbers ({e})") from e
    if values.size == 0:
        raise LogLayoutError(path, "a CSV log with rows of comma-separated numbers (this file has none)")
    if len(values) > MAX_SAMPLES:
        raise TooLongLogError(path, f"at most {MAX_SAMPLES} rows (an hour at 200 Hz): split the log")
    return values


def _rate(path: Path, rate_hz: float | None) -> float:
    if rate_hz is not None:
        return float(rate_hz)
    return 250.0 if "250" in path.name else 200.0


def implied_rate_hz(q: np.ndarray, qd: np.ndarray) -> float | None:
    """The sample rate a log's positions and velocities imply [Hz], from the yaw, pitch and insertion: per joint,
    the least-squares ``dt`` in ``(q[k+1] - q[k-1]) / 2 = qd[k] dt``; their median, or None when a joint does not
    move, its positions do not follow its velocities (less than 90 % of their change explained) or the joints
    disagree by more than :data:`RATE_AGREEMENT`."""
    if len(q) < 3:
        return None
    change, velocity = (q[2:, :3] - q[:-2, :3]) / 2.0, qd[1:-1, :3]
    power = np.sum(velocity * velocity, axis=0)
    if not (np.all(np.isfinite(power)) and np.all(np.isfinite(change)) and np.all(power > 0.0)):
        return None
    dt = np.sum(change * velocity, axis=0) / power
    left = np.sum(np.square(change - velocity * dt), axis=0)
    if not (np.all(dt > 0.0) and np.all(left <= 0.1 * np.sum(np.square(change), axis=0))):
        return None
    rates = 1.0 / dt
    if rates.max() > (1.0 + RATE_AGREEMENT) * rates.min():
        return None
    return float(np.median(rates))


def _timed(log: JointLog, rate_hz: float | None, layout_rate_hz: float) -> JointLog:
    """The log at ``rate_hz`` when given, else at the rate its motion implies when that is far from its layout's
    (see the module notes), else at the layout's."""
    rate, note = layout_rate_hz if rate_hz is None else rate_hz, ""
    if rate_hz is None:
        implied = implied_rate_hz(log.q, log.qd)
        if implied is not None and abs(implied / layout_rate_hz - 1.0) > RATE_MISMATCH:
            rate = implied
            note = (
                f"{implied:.1f} Hz, from its positions and velocities (its layout's {layout_rate_hz:g} Hz does not "
                "match them; --rate sets it)"
            )
    return replace(log, t_s=np.arange(len(log.q)) / rate, rate_note=note)


def _read_csv(path: Path, rate_hz: float | None) -> JointLog:
    values = _load_csv(path)
    n = len(values)
    t_s = np.arange(n) / 200.0
    if values.shape[1] == 21:
        q, qd, tau = _from_motor_space(values[:, 0:7], values[:, 7:14], values[:, 14:21])
        return _checked(_timed(JointLog(str(path), "wpi", t_s, q[:, :6], qd[:, :6], tau[:, :6]), rate_hz, 200.0))
    if values.shape[1] == 9:
        pad = np.zeros((n, 3))
        log = JointLog(
            str(path),
            "radiang",
            t_s,
            np.hstack([values[:, 0:3], pad]),
            np.hstack([values[:, 3:6], pad]),
            np.hstack([values[:, 6:9], pad]),
            joints=3,
        )
        return _checked(_timed(log, rate_hz, 200.0))
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
                if len(times) >= MAX_SAMPLES:
                    raise TooLongLogError(path, f"at most {MAX_SAMPLES} {topic} messages (an hour at 200 Hz)")
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
        InputFileError: A file that is not a regular file of at most :data:`MAX_LOG_BYTES`.
    """
    path = Path(path)
    if not path.exists():
        raise LogLayoutError(path, "an existing bag, recording, CSV file or folder")
    if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0.0):
        raise LogLayoutError(path, f"a sample rate > 0 (got {rate_hz})")
    if not path.is_dir():  # before anything opens it: a FIFO blocks, a device never ends
        check_regular_file(path, "--from", MAX_LOG_BYTES)
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
