"""One arm's state as its console publishes it over ROS 2: checked, kept, and waited for.

:class:`ArmListener` subscribes to the arm's state and event topics (joints, jaw, poses, force, operating
state, errors) and keeps the latest of each. Every message is checked first: the first malformed or
non-finite one latches a data fault, after which the client's deadman holds
(:class:`~hardware_if.client.psm_client.PsmClient`, which adds the commands to this). A ``measured_js`` is
a new measurement only when its stamp advanced: one stamped as the last is a repeat (it does not make the
measurement fresh), and a stamp that went back or jumped ahead is a data fault
(:func:`~hardware_if.client.deadman.stamp_step_fault`), a jump from the moment the clock is pinned
(:meth:`ArmListener.pin_clock`, before a program's first command). Its reads never
block; its waits block until the console has published what they wait for, or time out. The force is the
console's ``body/measured_cf``, or the joint efforts with a wrench calibration's model removed.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Self

import numpy as np
from crtk_msgs.msg import OperatingState  # type: ignore[import-untyped]
from geometry_msgs.msg import PoseStamped, WrenchStamped  # type: ignore[import-untyped]
from rclpy.context import Context
from rclpy.node import Node
from sensor_msgs.msg import JointState  # type: ignore[import-untyped]
from std_msgs.msg import String  # type: ignore[import-untyped]

from hardware_if.client.deadman import STAMP_JUMP_S, stamp_step_fault
from hardware_if.client.task_estimate import JawReading
from hardware_if.common import convert
from hardware_if.common.crtk import JAW_JOINT_NAME, JOINT_NAMES, ArmTopics, event_qos, periodic_qos
from hardware_if.common.errors import DvrkError, DvrkTimeoutError
from hardware_if.common.session import SpinThread
from hardware_if.wrench.calibration import WrenchCalibration
from psm_control.commands import MeasuredState
from psm_control.errors import TissueRetractError
from psm_control.robot import PsmModel

__all__ = ["ArmListener"]

#: Largest calibrated force taken as a measurement [N]: a PSM's motors exert a small fraction of it, so a
#: larger one comes from the calibration, not the tissue, and holds the arm as invalid data.
CALIBRATED_FORCE_MAX_N = 1e4
#: Allowed clock difference between this machine and the arm's when comparing stamps [s].
CLOCK_SLACK_S = 0.05
#: The state topic's history (sent at once to a late subscriber) is over when no state came for this [s].
STATE_HISTORY_QUIET_S = 0.25
#: How many of the last measurements a new stamp is judged against (``stamp_step_fault``'s ``ahead_s``).
STAMP_OFFSETS_KEPT = 100


class ArmListener(Node):
    """The latest state of one dVRK arm over ROS 2, every message checked.

    Args:
        arm: Arm name / namespace (``PSM1``, ``PSM2``, ...).
        node_name: ROS node name.
        on_measured: Called (from the ROS thread) with each ``measured_js`` and its arrival time on
            ``time.perf_counter`` [s], e.g. to record or time the stream.
        context: The rclpy context (default: the global one), e.g. one per ROS domain.

    Use as a context manager (or call :meth:`start` and :meth:`close`).
    """

    def __init__(
        self,
        arm: str,
        *,
        node_name: str,
        on_measured: Callable[[JointState, float], None] | None = None,
        context: Context | None = None,
    ) -> None:
        self.topics = ArmTopics(arm)
        super().__init__(node_name, context=context)
        self._joined_s = time.monotonic()  # when this node joined the domain
        self._lock = threading.Condition()
        self._data_fault = ""
        self._on_measured = on_measured
        self._measured: JointState | None = None
        self._measured_rx_s: float | None = None  # when the latest measured_js with a new stamp arrived
        self._repeated_rx_s: float | None = None  # when that measurement last arrived again, stamp unchanged
        # Stamp less arrival of the measurements last taken: the largest is the least delayed, which a new stamp
        # may not run ahead of by more than STAMP_JUMP_S. They are the last taken, not the last second's: a
        # stall of this process, however long, leaves the ones before it to judge by.
        self._stamp_offsets_s: deque[float] = deque(maxlen=STAMP_OFFSETS_KEPT)
        self._clock_pinned = False
        self._setpoint_q: np.ndarray | None = None
        self._jaw = 0.0
        self._jaw_velocity = 0.0
        self._setpoint_jaw: float | None = None
        self._force_body_n = np.zeros(3)
        self._calibration: WrenchCalibration | None = None
        self._force_sensor = False
        self._calibration_configuration = PsmModel().configuration()
        # The acceleration of the last command sent (the chain's), given to the calibration: the arm tracks it,
        # and a single measured_js carries none.
        self._commanded_qdd: np.ndarray | None = None
        self._poses: dict[str, np.ndarray] = {}
        self._frame_ids: dict[str, str] = {}
        self._state = OperatingState()
        self._state_received = False
        self._state_count = 0
        self._state_rx_s = float("-inf")
        self._unsettled_stamp_s = float("-inf")
        self._errors: list[str] = []
        self._spinner: SpinThread | None = None

        state, event = periodic_qos(), event_qos()
        t = self.topics.topic
        self.create_subscription(JointState, t("measured_js"), self._on_measured_js, state)
        self.create_subscription(JointState, t("setpoint_js"), self._on_setpoint_js, state)
        self.create_subscription(JointState, t("jaw/measured_js"), self._on_jaw, state)
        self.create_subscription(JointState, t("jaw/setpoint_js"), self._on_jaw_setpoint, state)
        self.create_subscription(WrenchStamped, t("body/measured_cf"), self._on_wrench, state)
        for name in ("measured_cp", "local/measured_cp", "setpoint_cp"):
            self.create_subscription(PoseStamped, t(name), self._pose_callback(name), state)
        self.create_subscription(OperatingState, t("operating_state"), self._on_operating_state, event)
        self.create_subscription(String, t("error"), self._on_error, event)

    # -- lifetime ---------------------------------------------------------------------------------
    def start(self) -> Self:
        """Spin the node on a background thread."""
        if self._spinner is None:
            self._spinner = SpinThread(self, f"{self.topics.arm}-client")
        return self

    def close(self) -> None:
        """Stop spinning and destroy the node (safe to call twice)."""
        if self._spinner is None:  # never spun: nothing to stop first
            self.destroy_node()
        elif self._spinner.close():
            self._spinner = None

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- callbacks (ROS thread) -------------------------------------------------------------------
    def _invalid(self, topic: str, what: str) -> None:
        """Latch the first malformed or non-finite message (lock held): the deadman holds on it."""
        if not self._data_fault:
            self._data_fault = f"invalid data: {topic}: {what}"
            self.get_logger().error(f"{self.topics.arm}: {self._data_fault}")
            self._lock.notify_all()

    def _joints(self, message: JointState, topic: str, names: tuple[str, ...] = JOINT_NAMES) -> np.ndarray | None:
        """Positions (and velocities, efforts) checked: the right joints, finite; None after latching a fault."""
        try:
            q = convert.joint_state_positions(message, names)
            convert.joint_state_velocities(message, names)
        except (TissueRetractError, ValueError) as e:
            with self._lock:
                self._invalid(topic, str(e))
            return None
        # math.isfinite over the few values: numpy's per-call overhead was most of a callback's time.
        bad = [name for name, value in zip(names, q.tolist(), strict=True) if not math.isfinite(value)]
        if not bad and not all(map(math.isfinite, message.velocity)):
            bad = ["velocity"]
        if not bad and not all(map(math.isfinite, message.effort)):
            bad = ["effort"]
        if bad:
            with self._lock:
                self._invalid(topic, f"non-finite {', '.join(bad)} (finite numbers only)")
            return None
        return q

    def _on_measured_js(self, message: JointState) -> None:
        if self._on_measured is not None:
            self._on_measured(message, time.perf_counter())
        if self._joints(message, "measured_js") is None:
            return  # never used: the deadman holds on the latched fault
        rx_s = time.monotonic()
        stamp_s = convert.time_to_seconds(message.header.stamp)
        with self._lock:
            previous = self._measured
            if previous is not None and self._measured_rx_s is not None:
                stamp, last = message.header.stamp, previous.header.stamp
                if (stamp.sec, stamp.nanosec) == (last.sec, last.nanosec):
                    self._repeated_rx_s = rx_s  # the same measurement again: it stays as old as it was
                    return
                ahead_s = (stamp_s - rx_s) - max(self._stamp_offsets_s)
                last_s = convert.time_to_seconds(last)
                fault = stamp_step_fault(last_s, stamp_s, ahead_s, STAMP_JUMP_S)
                if fault and stamp_s > last_s and not self._clock_pinned:
                    # A jump before the clock is pinned: the measurements it was judged against may all have
                    # been late (the first ones a process takes while it is still starting, on a busy
                    # machine), so they are no baseline; judged from here on.
                    self._stamp_offsets_s.clear()
                    fault = ""
                if fault:
                    self._invalid("measured_js", fault)
                    return
            self._measured = message
            self._measured_rx_s = rx_s
            self._stamp_offsets_s.append(stamp_s - rx_s)
            self._repeated_rx_s = None
            self._lock.notify_all()

    def pin_clock(self) -> None:
        """Judge every ``measured_js`` stamp from now on against the measurements before it: one that jumps
        ahead of its arrival by more than :data:`~hardware_if.client.deadman.STAMP_JUMP_S` is a data fault.

        Before this (a program starting, commanding nothing yet), a jump starts the baseline afresh instead:
        the first measurements a process takes may have waited in its queue while it started (seconds, on a
        busy machine), and a prompt one after them looks like a clock that leapt. A stamp that goes back is a
        fault either way. A deploy pins it at each episode's first tick, :class:`PsmClient` at its first
        ``servo_jp`` at the latest.
        """
        with self._lock:
            self._clock_pinned = True

    def _on_setpoint_js(self, message: JointState) -> None:
        q = self._joints(message, "setpoint_js")
        if q is None:
            return
        with self._lock:
            self._setpoint_q = q

    def _on_jaw(self, message: JointState) -> None:
        q = self._joints(message, "jaw/measured_js", (JAW_JOINT_NAME,))
        if q is None:
            return
        velocity = convert.joint_state_velocities(message, (JAW_JOINT_NAME,))  # checked by _joints
        with self._lock:
            self._jaw = float(q[0])
            self._jaw_velocity = float(velocity[0])

    def _on_jaw_setpoint(self, message: JointState) -> None:
        q = self._joints(message, "jaw/setpoint_js", (JAW_JOINT_NAME,))
        if q is None:
            return
        with self._lock:
            self._setpoint_jaw = float(q[0])

    def _on_wrench(self, message: WrenchStamped) -> None:
        f, t = message.wrench.force, message.wrench.torque
        finite = all(map(math.isfinite, (f.x, f.y, f.z, t.x, t.y, t.z)))
        force = convert.wrench_force(message)
        with self._lock:
            if not finite:
                self._invalid("body/measured_cf", "non-finite force or torque (finite numbers only)")
                return
            self._force_body_n = force

    def _pose_callback(self, name: str) -> Callable[[PoseStamped], None]:
        def callback(message: PoseStamped) -> None:
            p = message.pose.position
            try:
                if not all(map(math.isfinite, (p.x, p.y, p.z))):
                    raise ValueError("non-finite position (finite numbers only)")
                pose = convert.pose_matrix(message)
            except (TissueRetractError, ValueError) as e:
                with self._lock:
                    self._invalid(name, str(e))
                return
            with self._lock:
                self._poses[name] = pose
                self._frame_ids[name] = message.header.frame_id
                self._lock.notify_all()

        return callback

    def _on_operating_state(self, message: OperatingState) -> None:
        with self._lock:
            self._state = message
            self._state_received = True
            self._state_rx_s = time.monotonic()
            self._state_count += 1
            if message.is_busy or not message.is_homed:
                self._unsettled_stamp_s = max(self._unsettled_stamp_s, convert.time_to_seconds(message.header.stamp))
            self._lock.notify_all()

    def _on_error(self, message: String) -> None:
        with self._lock:
            self._errors.append(message.data)
        self.get_logger().warning(f"{self.topics.arm} error: {message.data}")

    @property
    def errors(self) -> list[str]:
        """Messages the arm published on its ``error`` topic, oldest first."""
        with self._lock:
            return list(self._errors)

    @property
    def force_sensing(self) -> str:
        """What the force comes from, as the simulation's presets name it: ``dvrk-calibrated``, ``dvrk``, or ``ideal``
        for a force sensor at the instrument (the sensing whose shipped policies it takes)."""
        with self._lock:
            if self._force_sensor:
                return "ideal"
            return "dvrk" if self._calibration is None else "dvrk-calibrated"

    def declare_force_sensor(self, declared: bool) -> None:
        """``measured_cf`` comes from a force sensor at the instrument (the console's force source set to it), as
        the user declared: the policy then takes the force as exact sensing's policies do."""
        with self._lock:
            self._force_sensor = declared

    def set_wrench_calibration(self, calibration: WrenchCalibration | None) -> None:
        """Take the force from ``measured_js`` efforts with a calibration's model removed, not ``measured_cf``."""
        with self._lock:
            self._calibration = calibration

    def efforts(self) -> np.ndarray:
        """The latest ``measured_js`` efforts (6,) (zeros when the console sends none)."""
        with self._lock:
            message = self._measured
            if message is None or len(message.effort) != len(JOINT_NAMES):
                return np.zeros(len(JOINT_NAMES))
            return np.asarray(message.effort, dtype=float)

    def _calibrated_force(self, message: JointState, rotation: np.ndarray) -> np.ndarray:
        """The calibrated force in ``<arm>_base`` [N]: computed about the RCM, turned as ``measured_cp`` is."""
        if self._calibration is None or len(message.effort) != len(JOINT_NAMES):
            return np.asarray(rotation @ self._force_body_n)
        local = self._calibration_configuration
        local.update(convert.joint_state_positions(message))
        with np.errstate(all="ignore"):  # a force that overflows is a sensing fault, said by measure()
            force_local = self._calibration.force(
                local, convert.joint_state_velocities(message), np.asarray(message.effort), self._commanded_qdd
            )
            return np.asarray(rotation @ local.local_pose()[:3, :3].T @ force_local)

    # -- Backend ----------------------------------------------------------------------------------
    def measure(self) -> MeasuredState:
        """The latest measurement; its ``stamp_s`` is the arm's. Never blocks, even if the arm is gone.

        Raises:
            DvrkTimeoutError: No ``measured_js`` has ever arrived (see :meth:`wait_for_measurement`).
        """
        with self._lock:
            message = self._measured
            if message is None:
                raise DvrkTimeoutError(f"a measured_js from {self.topics.arm}", 0.0, self._state.state)
            rotation = self._poses.get("measured_cp", np.eye(4))[:3, :3]
            force = self._calibrated_force(message, rotation)
            magnitude = math.hypot(*force.tolist())  # nan for a nan component, inf only past the float range
            if not magnitude <= CALIBRATED_FORCE_MAX_N:
                # Finite efforts through a calibration that overflows or has gone wrong: the force the filter
                # would limit is unknown, a sensing fault like a non-finite measured_cf.
                self._invalid(
                    "measured_js effort",
                    f"the calibrated force {magnitude:.4g} N is no measurement (finite and at most "
                    f"{CALIBRATED_FORCE_MAX_N:g} N; check the wrench calibration)",
                )
            return MeasuredState(
                q=convert.joint_state_positions(message),
                qd=convert.joint_state_velocities(message),
                jaw=self._jaw,
                force_n=force,
                stamp_s=convert.time_to_seconds(message.header.stamp),
            )

    def jaw_reading(self) -> JawReading:
        """The jaw's measured angle and velocity and its set-point (the measured angle until one arrived)."""
        with self._lock:
            setpoint = self._jaw if self._setpoint_jaw is None else self._setpoint_jaw
            return JawReading(self._jaw, self._jaw_velocity, setpoint)

    def pose(self, name: str = "measured_cp") -> tuple[np.ndarray, str]:
        """The latest 4x4 pose and frame_id on ``measured_cp``, ``local/measured_cp`` or ``setpoint_cp``.

        Raises:
            DvrkTimeoutError: That pose has never been received.
        """
        with self._lock:
            if name not in self._poses:
                raise DvrkTimeoutError(f"a {name} from {self.topics.arm}", 0.0, self._state.state)
            return self._poses[name].copy(), self._frame_ids[name]

    # -- blocking helpers -------------------------------------------------------------------------
    def operating_state(self) -> tuple[str, bool, bool]:
        """The latest (state, is_homed, is_busy); state is "" before any was received."""
        with self._lock:
            s = self._state
            return (s.state if self._state_received else "", bool(s.is_homed), bool(s.is_busy))

    def wait_for_operating_state(self, timeout_s: float) -> tuple[str, bool, bool]:
        """Wait for the console's current operating state (at most ``timeout_s``) and return it.

        A late subscriber first gets the state topic's history (oldest first), so the first state that
        arrives may be long gone. The current one is a state stamped since this call, or the last of the
        history once no more arrived for :data:`STATE_HISTORY_QUIET_S`. Returned as :meth:`operating_state`
        does (state "" if none came).
        """
        deadline = time.monotonic() + timeout_s
        since_s = self._now_s() - CLOCK_SLACK_S

        def current() -> bool:
            if not self._state_received:
                return False
            fresh = convert.time_to_seconds(self._state.header.stamp) >= since_s
            return fresh or time.monotonic() - self._state_rx_s >= STATE_HISTORY_QUIET_S

        with self._lock:
            while not current() and (remaining := deadline - time.monotonic()) > 0.0:
                self._lock.wait(min(remaining, STATE_HISTORY_QUIET_S))
        return self.operating_state()

    def wait_for_measurement(self, timeout_s: float = 5.0) -> MeasuredState:
        """Block until a ``measured_js`` has arrived, then return it.

        Raises:
            DvrkTimeoutError: None arrived within ``timeout_s``.
            DvrkError: The first data were invalid (a fault is latched: nothing later is taken).
        """
        deadline = time.monotonic() + timeout_s
        with self._lock:
            while self._measured is None:
                if self._data_fault:
                    raise DvrkError(f"{self.topics.arm}: {self._data_fault}")
                remaining = deadline - time.monotonic()
                if remaining <= 0.0:
                    raise DvrkTimeoutError(f"a measured_js from {self.topics.arm}", timeout_s, self._state.state)
                self._lock.wait(remaining)
            measured = self.measure()  # the force through a calibration is checked here (the lock is re-entrant)
            if self._data_fault:
                raise DvrkError(f"{self.topics.arm}: {self._data_fault}")
            return measured

    def next_measurement(self, after_stamp_s: float, timeout_s: float) -> MeasuredState:
        """Block until a ``measured_js`` stamped after ``after_stamp_s`` (the arm's clock) arrived; return it.

        Also waits for a first ``measured_cp`` and ``local/measured_cp``, which :meth:`pose` then has.
        """
        deadline = time.monotonic() + timeout_s

        def arrived() -> bool:
            message = self._measured
            fresh = message is not None and convert.time_to_seconds(message.header.stamp) > after_stamp_s
            return fresh and all(name in self._poses for name in ("measured_cp", "local/measured_cp"))

        with self._lock:
            while not arrived():
                remaining = deadline - time.monotonic()
                if remaining <= 0.0:
                    what = f"a new measured_js and the measured_cp poses from {self.topics.arm}"
                    raise DvrkTimeoutError(what, timeout_s, self._state.state)
                self._lock.wait(remaining)
        return self.measure()

    def _now_s(self) -> float:
        return float(self.get_clock().now().nanoseconds) * 1e-9
