"""The simulated console's side of one arm: its operating state, its set-points and its own motion.

:class:`ConsoleArm` is what the console does whichever command topic asked for it: the operating state
machine (``enable``, ``home``, ``disable``, ``unhome``; homing takes :data:`HOMING_SETTLE_S` plus a
trajectory to the home joints), the set-points and the console's own trajectories, the PID's tracking-error
trip, and the tick that steps the arm model, senses the efforts the console reports and publishes the arm's
state (:mod:`~hardware_if.console.state_topics`) and its events. :class:`~hardware_if.console.sim_dvrk.SimulatedPsm`
serves the CRTK command topics and services onto it.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time  # type: ignore[import-untyped]
from crtk_msgs.msg import OperatingState, StringStamped  # type: ignore[import-untyped]
from rclpy.node import Node
from std_msgs.msg import Bool, Float64, String  # type: ignore[import-untyped]

from hardware_if.common.crtk import (
    DEFAULT_ARM,
    DEFAULT_RATE_HZ,
    JAW_JOINT_NAME,
    JAW_TRACKING_TOLERANCE,
    JOINT_NAMES,
    TRACKING_TOLERANCE,
    ArmTopics,
    event_qos,
)
from hardware_if.common.errors import DvrkError
from hardware_if.console.arm_model import ArmModel, ArmSample, KinematicArm
from hardware_if.console.console_guard import other_consoles
from hardware_if.console.motion import JointTrajectory
from hardware_if.console.stamp_fault import StampFault
from hardware_if.console.state_topics import StateTopics
from psm_control.errors import ConfigurationError
from psm_control.robot import PsmModel
from sim.force_sensing import ForceSensor, console_force, sensing_params
from sim.scene_stream import SceneStream

__all__ = ["HOMING_SETTLE_S", "OPERATING_STATE_REPUBLISH_S", "ConsoleArm"]

#: Time a home takes before the arm starts moving to the home joints [s]: the console powers the arm and
#: biases its encoders first. Real homing takes seconds; scripts that race it must wait on is_homed.
HOMING_SETTLE_S = 1.0
#: Period of the operating_state republication [s]. The dVRK's Python client subscribes without
#: history, so a client started after the last change learns the state from this.
OPERATING_STATE_REPUBLISH_S = 0.1


class ConsoleArm(Node):
    """One arm behind a simulated console: its state machine and motion, stepped and published every period.

    The command topics and services that drive it are :class:`~hardware_if.console.sim_dvrk.SimulatedPsm`'s
    (:meth:`_serve`).

    Args:
        arm: Arm name / namespace.
        rate_hz: Publishing rate of the periodic topics [Hz] (the dVRK's default is 100).
        model: Kinematic model; default the Classic PSM with the 400006 needle driver.
        arm_model: Physics; default :class:`KinematicArm`.
        base_frame: 4x4 pose of the RCM in ``<arm>_base`` (``measured_cp = base_frame @ local``).
        home_q: Joints homing moves to; default all zero, as the dVRK's PSM homing.
        homing_settle_s: Time a home takes before the move to ``home_q`` starts [s].
        scene: Where the arm (measured and set-point) and the task's markers are streamed as a 3-D scene
            every tick (``sim-dvrk --live``); None streams nothing.
        context: rclpy context of the node; default rclpy's default context.
        sensor: What the console makes of the tissue force: the joint efforts on ``measured_js`` and the
            ``measured_cf`` computed from them (:mod:`sim.force_sensing`); default the ``dvrk`` model, the
            console's uncompensated estimate, so that a rehearsal meets the sensor the robot has.
        exclusive: Refuse to serve an arm that another console already serves on the domain (waits up to
            :data:`~hardware_if.console.console_guard.CONSOLE_DISCOVERY_S` for discovery first).
        stamp_fault: A clock fault to inject on ``measured_js`` (:mod:`~hardware_if.console.stamp_fault`),
            said on ``warning`` when it starts; None: none.

    Raises:
        DvrkError: ``exclusive`` and another node already publishes the arm's ``measured_js``.
    """

    def __init__(
        self,
        arm: str = DEFAULT_ARM,
        *,
        rate_hz: float = DEFAULT_RATE_HZ,
        model: PsmModel | None = None,
        arm_model: ArmModel | None = None,
        base_frame: np.ndarray | None = None,
        home_q: np.ndarray | None = None,
        homing_settle_s: float = HOMING_SETTLE_S,
        scene: SceneStream | None = None,
        context: Any = None,
        sensor: ForceSensor | None = None,
        exclusive: bool = False,
        stamp_fault: StampFault | None = None,
    ) -> None:
        if not (np.isfinite(rate_hz) and 1.0 <= rate_hz <= 5000.0):
            raise ConfigurationError("rate_hz", rate_hz, "a publishing rate in 1..5000 Hz")
        if not (np.isfinite(homing_settle_s) and 0.0 <= homing_settle_s <= 60.0):
            raise ConfigurationError("homing_settle_s", homing_settle_s, "a duration in 0..60 s")
        self.topics = ArmTopics(arm)
        super().__init__(f"{arm.lower()}_sim_dvrk", context=context)
        if exclusive and (others := other_consoles(self, arm)):
            self.destroy_node()
            raise DvrkError(
                f"/{arm} is already served on this ROS domain by {', '.join(others)}: one console per arm "
                "(stop that one, or serve another --arm or --domain-id)"
            )
        self.period_s = 1.0 / rate_hz
        self.homing_settle_s = float(homing_settle_s)
        self.model = model if model is not None else PsmModel.from_variant()
        self.arm_model: ArmModel = arm_model if arm_model is not None else KinematicArm()
        self.configuration = self.model.configuration(np.zeros(6), base_frame=base_frame)
        self._ik_configuration = self.configuration.copy()
        self._fk_configuration = self.configuration.copy()
        self.home_q = np.zeros(6) if home_q is None else self.model.check_joints(home_q, strict=True)
        self.scene = scene
        self.state = OperatingState(state="DISABLED", is_homed=False, is_busy=False)
        self._state_stamp_ns = 0
        self._state_published_s = float("-inf")
        self._setpoint_q = np.zeros(6)
        self._setpoint_jaw = 0.0
        self._setpoint_effort = np.zeros(6)
        self._trajectory: JointTrajectory | None = None
        self._jaw_trajectory: JointTrajectory | None = None
        self._homing = False
        self._homing_moves_at_s: float | None = None
        self._mode = "position"  # "position", "effort" or "free"
        self.trajectory_ratio = 1.0
        self.settings = {"use_gravity_compensation": True, "body/set_cf_orientation_absolute": False}
        self._sample: ArmSample = self.arm_model.reset(self._setpoint_q, self._setpoint_jaw)
        self.sensor = sensor if sensor is not None else ForceSensor(sensing_params("dvrk"))
        self._sense(0.0)
        self._last_tick_s = time.monotonic()
        self._answered = False  # a servo command's measured_js and setpoint_js went out since the last tick

        self.state_topics = StateTopics(self, self.topics)
        self.stamp_fault = stamp_fault
        if stamp_fault is not None:
            stamp_fault.on_start = lambda text: self._event("warning", f"{self.topics.arm}: {text}")
            self.state_topics.stamp_fault = stamp_fault
        event = event_qos()
        t = self.topics.topic
        self._operating_state = self.create_publisher(OperatingState, t("operating_state"), event)
        self._events = {name: self.create_publisher(String, t(name), event) for name in ("error", "warning", "status")}
        self._goal_reached = self.create_publisher(Bool, t("goal_reached"), event)
        self._ratio = self.create_publisher(Float64, t("trajectory_j/ratio"), event)
        self._serve()
        self._publish_operating_state(changed=True)
        self._ratio.publish(Float64(data=self.trajectory_ratio))
        self.create_timer(self.period_s, self._tick)

    def set_base_frame(self, transform_rcm_to_base: np.ndarray) -> None:
        """Move the RCM in ``<arm>_base`` (as the dVRK's ``set_base_frame``; a task reset moves it)."""
        for configuration in (self.configuration, self._ik_configuration, self._fk_configuration):
            configuration.set_base_frame(transform_rcm_to_base)

    def place_arm(self, q: np.ndarray, jaw: float) -> None:
        """Put the arm (measured and set-point) at ``q`` and ``jaw``, as an operator moves a disabled arm by hand."""
        self._setpoint_q = self.model.check_joints(q, strict=True).copy()
        self._setpoint_jaw = float(jaw)
        self._sample = self.arm_model.reset(self._setpoint_q, self._setpoint_jaw)

    @property
    def busy(self) -> bool:
        """Whether homing or a trajectory (arm or jaw) is running."""
        return self._homing or self._trajectory is not None or self._jaw_trajectory is not None

    def _serve(self) -> None:
        """Subscribe to the arm's commands and offer its services: none here (see the class notes)."""

    # -- state machine ----------------------------------------------------------------------------
    def _on_state_command(self, message: StringStamped) -> None:
        # A client that just connected may read the arm's state as soon as enable/home return (the dVRK's
        # scripts do, and an idempotent home returns at once): send it now, before the operating state.
        self._publish_state(joints=True)
        command = message.string
        if command == "enable":
            if self.state.state == "FAULT":
                # Recover from where the arm is, as the PID does when it is enabled again.
                self._servo(self._sample.q, self._sample.jaw)
            self._set_state("ENABLED")
        elif command == "disable":
            self._stop_motion()
            self._homing, self._homing_moves_at_s = False, None
            self._set_state("DISABLED", is_busy=False)
        elif command == "home":
            if self.state.state == "ENABLED" and self.state.is_homed and not self.busy:
                # The console's home is idempotent: a homed arm stays where it is and keeps its goals.
                self._event("status", f"{self.topics.arm}: already homed")
                self._publish_operating_state(changed=True)
                return
            if self._homing:
                return  # already homing: a repeated request neither restarts nor shortens it
            self._stop_motion()
            self._servo(self._sample.q, self._sample.jaw)  # homing starts from where the arm is
            self._homing = True
            self._homing_moves_at_s = time.monotonic() + self.homing_settle_s
            self._mode = "position"
            self._set_state("ENABLED", is_homed=False, is_busy=True)
            self._event("status", f"{self.topics.arm}: homing")
        elif command == "unhome":
            self._set_state(self.state.state, is_homed=False)
        else:
            self._event("error", f"{self.topics.arm}: unknown state command {command!r}")

    def _set_state(self, state: str, *, is_homed: bool | None = None, is_busy: bool | None = None) -> None:
        self.state.state = state
        if is_homed is not None:
            self.state.is_homed = is_homed
        if is_busy is not None:
            self.state.is_busy = is_busy
        self._publish_operating_state(changed=True)

    def _publish_operating_state(self, *, changed: bool) -> None:
        """Publish the operating state; ``changed`` gives it a new stamp, otherwise it is a republication.

        A republication keeps the stamp of the last change: the dVRK's client takes a newer stamp for a new
        event, and a move handle's ``is_busy()`` trusts any state stamped after its command, so re-stamping
        an idle state could end a move the console has not started yet.
        """
        if changed:
            now_ns = self.get_clock().now().nanoseconds
            self._state_stamp_ns = max(now_ns, self._state_stamp_ns + 1)  # strictly increasing
        sec, nanosec = divmod(self._state_stamp_ns, 1_000_000_000)
        self.state.header.stamp = Time(sec=sec, nanosec=nanosec)
        self._operating_state.publish(self.state)
        self._state_published_s = time.monotonic()

    def _event(self, kind: str, text: str) -> None:
        self._events[kind].publish(String(data=text))
        if kind == "status":
            self.get_logger().info(text)
        else:
            self.get_logger().warning(text)

    def _ready(self, what: str) -> bool:
        if self.state.state == "ENABLED" and self.state.is_homed and not self._homing:
            return True
        self._event(
            "error",
            f"{self.topics.arm}: {what} ignored, arm not ready ({self.state.state}, homed={self.state.is_homed})",
        )
        return False

    # -- set-points and the console's own motion --------------------------------------------------
    def _enter_position_mode(self) -> None:
        if self._mode != "position":
            self._mode = "position"
            self._setpoint_effort = np.zeros(6)

    def _start_move(self, goal: np.ndarray) -> None:
        self._enter_position_mode()
        self._trajectory = self._plan(goal)
        self._moving()

    def _moving(self) -> None:
        """A move_* was accepted: busy, with a new stamp even when a move was already running."""
        self.state.is_busy = True
        self._publish_operating_state(changed=True)

    def _plan(self, goal: np.ndarray) -> JointTrajectory:
        spec, ratio = self.model.spec, self.trajectory_ratio
        return JointTrajectory(
            self._setpoint_q, goal, spec.velocity_limit * ratio, spec.acceleration_limit * ratio, time.monotonic()
        )

    def _servo(self, q: np.ndarray, jaw: float) -> None:
        self._setpoint_q = np.asarray(q, dtype=float).copy()
        self._setpoint_jaw = float(jaw)
        self.arm_model.command(self._setpoint_q, self._setpoint_jaw)

    def _stop_motion(self) -> None:
        self._trajectory, self._jaw_trajectory = None, None

    def _end_trajectories(self, *, arm: bool, jaw: bool) -> None:
        """Drop running trajectories (a servo command replaces them); report the end of busy."""
        was_busy = self.busy
        if arm:
            self._trajectory = None
        if jaw:
            self._jaw_trajectory = None
        if was_busy and not self.busy:
            self._set_state(self.state.state, is_busy=False)

    # -- periodic publication ---------------------------------------------------------------------
    def _tick(self) -> None:
        now = time.monotonic()
        dt = now - self._last_tick_s
        self._last_tick_s = now
        answered, self._answered = self._answered, False
        if self._homing and self._homing_moves_at_s is not None and now >= self._homing_moves_at_s:
            self._homing_moves_at_s = None
            self._trajectory = self._plan(self.home_q)
        was_busy = self.busy
        if self._trajectory is not None:
            q, _ = self._trajectory.sample(now)
            self._servo(q, self._setpoint_jaw)
            if self._trajectory.done(now):
                self._trajectory = None
        if self._jaw_trajectory is not None:
            jaw, _ = self._jaw_trajectory.sample(now)
            self._servo(self._setpoint_q, float(jaw[0]))
            if self._jaw_trajectory.done(now):
                self._jaw_trajectory = None
        if self._homing and self._homing_moves_at_s is None and self._trajectory is None:
            self._homing = False
            self.state.is_homed = True
            self._event("status", f"{self.topics.arm}: homed")
        self._sample = self.arm_model.step(dt)
        self._sense(dt if self._sample.elapsed_s is None else self._sample.elapsed_s)
        if self._mode == "free":
            self._servo(self._sample.q, self._sample.jaw)  # nothing holds the arm: the set-point follows it
        # A servo command answered since the last tick already sent measured_js and setpoint_js: a stream
        # of commands at the rate or faster is answered once per command, not once more per tick.
        self._publish_state(joints=not answered)
        if self.scene is not None:
            self.scene.scene.base_frame = self.configuration.base_frame
            markers = self.arm_model.scene_markers()
            self.scene.tick(
                time.time(),
                self._sample.q,
                self._sample.jaw,
                commanded_q=self._setpoint_q,
                commanded_jaw=self._setpoint_jaw,
                **markers,
            )
        self._check_tracking()
        if was_busy and not self.busy:
            # After the state at the goal: a client that reads on "not busy" finds the goal already sent.
            self._set_state(self.state.state, is_busy=False)
            self._goal_reached.publish(Bool(data=True))
        if now - self._state_published_s >= OPERATING_STATE_REPUBLISH_S:
            self._publish_operating_state(changed=False)

    def _check_tracking(self) -> None:
        """The PID's tracking-error trip: measured vs set-point beyond the dVRK's tolerance -> FAULT."""
        if self.state.state != "ENABLED" or self._mode != "position":
            return
        errors = np.append(np.abs(self._sample.q - self._setpoint_q), abs(self._sample.jaw - self._setpoint_jaw))
        tolerances = np.append(TRACKING_TOLERANCE, JAW_TRACKING_TOLERANCE)
        over = np.flatnonzero(errors > tolerances)
        if over.size == 0:
            return
        k = int(over[0])
        name, unit = (*JOINT_NAMES, JAW_JOINT_NAME)[k], "m" if k == 2 else "rad"
        self._stop_motion()
        self._homing, self._homing_moves_at_s = False, None
        self._set_state("FAULT", is_busy=False)
        self._event(
            "error",
            f"{self.topics.arm}: PID tracking error on joint {name!r}: |measured - setpoint| = {errors[k]:.4f} {unit}, "
            f"tolerance {tolerances[k]:g} {unit}; arm in FAULT, send enable to recover",
        )

    def _stamp(self) -> float:
        return float(self.get_clock().now().nanoseconds) * 1e-9

    def _sense(self, dt_s: float) -> None:
        """The console's efforts and force estimate for the arm's state now (once per tick)."""
        sample = self._sample
        self.configuration.update(sample.q, sample.jaw)
        self._efforts = self.sensor.efforts(self.configuration, sample.qd, sample.force_n, dt_s)
        self._sensed_force = console_force(self.configuration.base_jacobian(), self._efforts)

    def _publish_state(self, *, joints: bool) -> None:
        """One period's state topics; the arm's ``measured_js``/``setpoint_js`` only with ``joints``."""
        stamp = self._stamp()
        if joints:
            self._publish_arm_joints(stamp)
        topics = self.state_topics
        topics.publish_jaw(stamp, self._sample, self._setpoint_jaw)
        topics.publish_poses_and_force(stamp, self.configuration, self._sample, self._setpoint_q, self._sensed_force)

    def _publish_arm_joints(self, stamp: float | None = None) -> None:
        """The arm's ``measured_js`` and ``setpoint_js``, stamped now unless ``stamp`` is given."""
        self.state_topics.publish_arm_joints(
            self._stamp() if stamp is None else stamp,
            self._sample,
            self._efforts,
            self._setpoint_q,
            self._setpoint_effort,
            effort_mode=self._mode == "effort",
        )
