"""The simulated dVRK: a ROS 2 node serving one PSM's CRTK topics and services, as a dVRK 2.4 console does.

:class:`SimulatedPsm` serves everything the dVRK's own Python client (``dvrk.psm``) connects to, so its
``check_connections()`` passes and its scripts run unmodified:

- State, every period (100 Hz by default; the dVRK's ROS bridge publishes at one such rate too):
  ``measured_js`` (with joint efforts), ``setpoint_js``, ``measured_cp``/``setpoint_cp`` and their
  ``local/`` versions, ``measured_cv``, ``local/measured_cv``, ``body/`` and ``spatial/measured_cf``,
  ``body/`` and ``spatial/jacobian``, ``jaw/measured_js`` and ``jaw/setpoint_js``. Only topics with a
  subscriber are computed and sent. The kinematic arm answers a ``servo_jp``/``servo_jr`` at once on
  ``measured_js`` and ``setpoint_js``; a tick after such an answer does not send those two again.
- Events (transient-local): ``operating_state`` (on every change and every accepted ``move_*``, and
  republished every :data:`OPERATING_STATE_REPUBLISH_S` for clients that subscribe without history),
  ``goal_reached``, ``trajectory_j/ratio``, ``error``, ``warning``, ``status``.
- The operating state machine: ``enable``; ``home`` (enables, takes :data:`HOMING_SETTLE_S` plus a
  trajectory to the home joints, ends homed; a no-op on an arm that is already homed and idle);
  ``disable``; ``unhome``.
- Motion: ``servo_jp``/``servo_jr``/``servo_cp`` at once; ``move_jp``/``move_jr``/``move_cp`` and
  ``jaw/move_jp`` by trajectories within the dVRK's limits scaled by ``trajectory_j/set_ratio``, with
  ``is_busy`` true from the command to the end of the last running trajectory; ``jaw/servo_jp``; jaw
  goals are clamped to the jaw's limits; ``hold`` (stop where the set-point is) and ``free``.
- Like the dVRK, Cartesian goals (``servo_cp``, ``move_cp``) are refused while the shaft is less than
  45 mm past the RCM, and motion commands are ignored with an error unless the arm is ENABLED and homed.
- The PID tracking-error trip: when a measured joint (or the jaw) is further from its set-point than
  the dVRK 2.4's tolerance (:data:`~hardware_if.common.crtk.TRACKING_TOLERANCE`) while the arm is servoed, the
  console stops, goes to FAULT and says which joint on ``error``; ``enable`` recovers, from where the
  arm is. (The kinematic arm always tracks; a physics model that lags or is blocked can trip it.)
- Effort commands (``servo_jf``, ``jaw/servo_jf``, ``body/`` and ``spatial/servo_cf``) are served but not
  rendered: the simulated arm is position-driven (the kinematic arm, and the task scene's arm, which
  PyBullet moves kinematically), as in the dVRK's own KINEMATIC simulation. The console switches to
  effort mode as the dVRK does (any trajectory stops), the arm holds where it is, the commanded effort
  is echoed on ``setpoint_js.effort`` and a warning says that efforts are not simulated.
- Services (``crtk_msgs/srv``): ``forward_kinematics`` (pose in ``<arm>_base``),
  ``local/forward_kinematics`` (about the RCM) and ``inverse_kinematics`` (goal about the RCM, from the
  request's joints), with the dVRK's ``result``/``message`` conventions.

The physics is an :class:`~hardware_if.console.arm_model.ArmModel`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time  # type: ignore[import-untyped]
from crtk_msgs.msg import OperatingState, StringStamped  # type: ignore[import-untyped]
from crtk_msgs.srv import QueryForwardKinematics, QueryInverseKinematics  # type: ignore[import-untyped]
from geometry_msgs.msg import PoseStamped, TwistStamped, WrenchStamped  # type: ignore[import-untyped]
from rclpy.node import Node
from sensor_msgs.msg import JointState  # type: ignore[import-untyped]
from std_msgs.msg import Bool, Empty, Float64, Float64MultiArray, MultiArrayDimension, String  # type: ignore[import-untyped]

from hardware_if.common import convert
from hardware_if.common.crtk import (
    DEFAULT_ARM,
    DEFAULT_RATE_HZ,
    JAW_JOINT_NAME,
    JAW_TRACKING_TOLERANCE,
    JOINT_NAMES,
    TRACKING_TOLERANCE,
    ArmTopics,
    event_qos,
    periodic_qos,
)
from hardware_if.common.errors import DvrkError
from hardware_if.console.arm_model import ArmModel, ArmSample, KinematicArm
from hardware_if.console.console_guard import CommandSources, other_consoles
from hardware_if.console.motion import JointTrajectory, inverse_kinematics
from psm_control.errors import ConfigurationError
from psm_control.robot import PsmModel
from sim.force_sensing import ForceSensor, console_force, sensing_params
from sim.scene_stream import SceneStream

__all__ = ["HOMING_SETTLE_S", "OPERATING_STATE_REPUBLISH_S", "SimulatedPsm"]

#: Time a home takes before the arm starts moving to the home joints [s]: the console powers the arm and
#: biases its encoders first. Real homing takes seconds; scripts that race it must wait on is_homed.
HOMING_SETTLE_S = 1.0
#: Period of the operating_state republication [s]. The dVRK's Python client subscribes without
#: history, so a client started after the last change learns the state from this.
OPERATING_STATE_REPUBLISH_S = 0.1
#: Jaw goals further than this beyond the jaw's limits are clamped with a warning [rad].
_JAW_CLAMP_WARN_RAD = 1e-3


class SimulatedPsm(Node):
    """One simulated PSM on its CRTK topics and services.

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

        state, event = periodic_qos(), event_qos()
        t = self.topics.topic
        self._pub = {
            name: self.create_publisher(JointState, t(name), state)
            for name in ("measured_js", "setpoint_js", "jaw/measured_js", "jaw/setpoint_js")
        }
        for name in ("measured_cp", "setpoint_cp", "local/measured_cp", "local/setpoint_cp"):
            self._pub[name] = self.create_publisher(PoseStamped, t(name), state)
        for name in ("body/measured_cf", "spatial/measured_cf"):
            self._pub[name] = self.create_publisher(WrenchStamped, t(name), state)
        for name in ("measured_cv", "local/measured_cv"):
            self._pub[name] = self.create_publisher(TwistStamped, t(name), state)
        for name in ("body/jacobian", "spatial/jacobian"):
            self._pub[name] = self.create_publisher(Float64MultiArray, t(name), state)
        self._operating_state = self.create_publisher(OperatingState, t("operating_state"), event)
        self._events = {name: self.create_publisher(String, t(name), event) for name in ("error", "warning", "status")}
        self._goal_reached = self.create_publisher(Bool, t("goal_reached"), event)
        self._ratio = self.create_publisher(Float64, t("trajectory_j/ratio"), event)
        # Commands arrive volatile: a restarted console must not replay an old "home" from history.
        self.command_sources = CommandSources(self, arm, partial(self._event, "warning"))
        subscriptions: tuple[tuple[type, str, Callable[[Any], None]], ...] = (
            (StringStamped, "state_command", self._on_state_command),
            (JointState, "servo_jp", self._on_servo_jp),
            (JointState, "servo_jr", self._on_servo_jr),
            (JointState, "move_jp", self._on_move_jp),
            (JointState, "move_jr", self._on_move_jr),
            (JointState, "servo_jf", self._on_servo_jf),
            (JointState, "jaw/servo_jp", self._on_jaw_servo_jp),
            (JointState, "jaw/move_jp", self._on_jaw_move_jp),
            (JointState, "jaw/servo_jf", self._on_jaw_servo_jf),
            (PoseStamped, "servo_cp", self._on_servo_cp),
            (PoseStamped, "move_cp", self._on_move_cp),
            (WrenchStamped, "body/servo_cf", lambda m: self._on_servo_cf(m, "body/servo_cf")),
            (WrenchStamped, "spatial/servo_cf", lambda m: self._on_servo_cf(m, "spatial/servo_cf")),
            (Empty, "hold", self._on_hold),
            (Empty, "free", self._on_free),
            (Float64, "trajectory_j/set_ratio", self._on_set_ratio),
        )
        noting = self.command_sources.noting
        for message_type, name, callback in subscriptions:
            self.create_subscription(message_type, t(name), noting(name, callback), state)
        for name in ("use_gravity_compensation", "body/set_cf_orientation_absolute", "emulate_tool_present"):
            self.create_subscription(Bool, t(name), noting(name, partial(self._on_setting, name=name)), state)
        self.create_service(QueryForwardKinematics, t("forward_kinematics"), self._on_forward_kinematics)
        self.create_service(QueryForwardKinematics, t("local/forward_kinematics"), self._on_local_forward_kinematics)
        self.create_service(QueryInverseKinematics, t("inverse_kinematics"), self._on_inverse_kinematics)
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

    # -- motion commands --------------------------------------------------------------------------
    def _joints(self, message: JointState, what: str, *, strict: bool) -> np.ndarray | None:
        try:
            return self.model.check_joints(convert.joint_state_positions(message), strict=strict, name=what)
        except ValueError as e:
            self._event("error", f"{self.topics.arm}: {what} rejected: {e}")
            return None

    def _jaw_goal(self, message: JointState, what: str) -> float | None:
        if len(message.position) != 1 or not np.isfinite(message.position[0]):
            got = list(message.position)
            self._event("error", f"{self.topics.arm}: {what} rejected: needs one finite jaw angle, got {got}")
            return None
        value = float(message.position[0])
        lower, upper = self.model.spec.jaw_lower, self.model.spec.jaw_upper
        clamped = float(np.clip(value, lower, upper))
        if abs(clamped - value) > _JAW_CLAMP_WARN_RAD:
            self._event(
                "warning",
                f"{self.topics.arm}: {what} {value:.4f} rad clamped to the jaw's limits [{lower:.4f}, {upper:.4f}] rad",
            )
        return clamped

    def _enter_position_mode(self) -> None:
        if self._mode != "position":
            self._mode = "position"
            self._setpoint_effort = np.zeros(6)

    def _on_servo_jp(self, message: JointState) -> None:
        if not self._ready("servo_jp"):
            return
        q = self._joints(message, "servo_jp", strict=False)
        if q is not None:
            self._servo_now(q)

    def _on_servo_jr(self, message: JointState) -> None:
        if not self._ready("servo_jr"):
            return
        delta = self._joints(message, "servo_jr", strict=False)
        if delta is not None:
            self._servo_now(self._setpoint_q + delta)

    def _servo_now(self, q: np.ndarray) -> None:
        self._enter_position_mode()
        self._end_trajectories(arm=True, jaw=False)
        self._servo(q, self._setpoint_jaw)
        if self.arm_model.instantaneous:
            # The kinematic arm is already there: answer with the arm's new joints now, not a period later.
            self._sample = self.arm_model.step(0.0)
            self._publish_arm_joints()
            self._answered = True

    def _on_jaw_servo_jp(self, message: JointState) -> None:
        if not self._ready("jaw/servo_jp"):
            return
        jaw = self._jaw_goal(message, "jaw/servo_jp")
        if jaw is not None:
            self._end_trajectories(arm=False, jaw=True)
            self._servo(self._setpoint_q, jaw)

    def _on_move_jp(self, message: JointState) -> None:
        if self._ready("move_jp"):
            goal = self._joints(message, "move_jp", strict=True)
            if goal is not None:
                self._start_move(goal)

    def _on_move_jr(self, message: JointState) -> None:
        if not self._ready("move_jr"):
            return
        delta = self._joints(message, "move_jr", strict=False)
        if delta is None:
            return
        try:
            goal = self.model.check_joints(self._setpoint_q + delta, strict=True, name="move_jr")
        except ValueError as e:
            self._event("error", f"{self.topics.arm}: move_jr rejected: {e}")
            return
        self._start_move(goal)

    def _on_jaw_move_jp(self, message: JointState) -> None:
        if not self._ready("jaw/move_jp"):
            return
        jaw = self._jaw_goal(message, "jaw/move_jp")
        if jaw is None:
            return
        spec, ratio = self.model.spec, self.trajectory_ratio
        self._enter_position_mode()
        self._jaw_trajectory = JointTrajectory(
            np.array([self._setpoint_jaw]),
            np.array([jaw]),
            np.array([spec.jaw_velocity_limit * ratio]),
            np.array([spec.jaw_acceleration_limit * ratio]),
            time.monotonic(),
        )
        self._moving()

    def _cartesian_goal(self, message: PoseStamped, what: str) -> np.ndarray | None:
        if not self._ready(what):
            return None
        insertion = float(self._sample.q[2])
        minimum = self.model.spec.rcm.min_insertion_m
        if insertion < minimum:
            self._event(
                "error",
                f"{self.topics.arm}: {what} refused, the tool must be at least {minimum * 1000:.0f} mm past the RCM "
                f"for cartesian control (insertion {insertion * 1000:.1f} mm)",
            )
            return None
        goal_local = np.linalg.inv(self.configuration.base_frame) @ convert.pose_matrix(message)
        self._ik_configuration.update(self._setpoint_q)
        q, residual = inverse_kinematics(self._ik_configuration, goal_local)
        if residual > 1e-4:
            self._event("error", f"{self.topics.arm}: {what} unreachable (IK residual {residual * 1000:.2f} mm)")
            return None
        return q

    def _on_servo_cp(self, message: PoseStamped) -> None:
        q = self._cartesian_goal(message, "servo_cp")
        if q is not None:
            self._enter_position_mode()
            self._end_trajectories(arm=True, jaw=False)
            self._servo(q, self._setpoint_jaw)

    def _on_move_cp(self, message: PoseStamped) -> None:
        q = self._cartesian_goal(message, "move_cp")
        if q is not None:
            self._start_move(q)

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

    def _on_hold(self, _message: Empty) -> None:
        if not self._ready("hold"):
            return
        self._enter_position_mode()
        self._end_trajectories(arm=True, jaw=True)
        self._servo(self._setpoint_q, self._setpoint_jaw)
        self._event("status", f"{self.topics.arm}: holding")

    def _on_free(self, _message: Empty) -> None:
        if not self._ready("free"):
            return
        self._end_trajectories(arm=True, jaw=True)
        self._mode = "free"
        self._setpoint_effort = np.zeros(6)
        self._event("status", f"{self.topics.arm}: free (no gravity in the simulation: the arm stays where it is)")

    def _effort_mode(self, what: str, effort: np.ndarray | None) -> None:
        self._end_trajectories(arm=True, jaw=True)
        if self._mode != "effort":
            self._event(
                "warning",
                f"{self.topics.arm}: {what}: effort control is not simulated (the simulated arm is position-driven, "
                "as the dVRK's KINEMATIC simulation); the arm holds where it is",
            )
        self._mode = "effort"
        if effort is not None:
            self._setpoint_effort = effort

    def _on_servo_jf(self, message: JointState) -> None:
        if not self._ready("servo_jf"):
            return
        effort = np.asarray(message.effort, dtype=float)
        if effort.shape != (6,) or not np.all(np.isfinite(effort)):
            got = list(message.effort)
            self._event("error", f"{self.topics.arm}: servo_jf rejected: needs 6 finite efforts, got {got}")
            return
        self._effort_mode("servo_jf", effort)

    def _on_jaw_servo_jf(self, message: JointState) -> None:
        if not self._ready("jaw/servo_jf"):
            return
        if len(message.effort) != 1 or not np.isfinite(message.effort[0]):
            got = list(message.effort)
            self._event("error", f"{self.topics.arm}: jaw/servo_jf rejected: needs one finite effort, got {got}")
            return
        self._effort_mode("jaw/servo_jf", None)

    def _on_servo_cf(self, message: WrenchStamped, what: str) -> None:
        if not self._ready(what):
            return
        w = message.wrench
        wrench = np.array([w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z], dtype=float)
        if not np.all(np.isfinite(wrench)):
            self._event("error", f"{self.topics.arm}: {what} rejected: the wrench is not finite")
            return
        self.configuration.update(self._setpoint_q)
        jacobian = self.configuration.base_jacobian()
        if what.startswith("body/") and not self.settings["body/set_cf_orientation_absolute"]:
            rotation = self.configuration.measured_pose()[:3, :3]
            wrench = np.concatenate([rotation @ wrench[:3], rotation @ wrench[3:]])
        self._effort_mode(what, jacobian.T @ wrench)

    def _on_set_ratio(self, message: Float64) -> None:
        ratio = float(message.data)
        if not (np.isfinite(ratio) and 0.0 < ratio <= 1.0):
            self._event("error", f"{self.topics.arm}: trajectory_j/set_ratio {ratio} rejected, allowed ]0, 1]")
            return
        self.trajectory_ratio = ratio
        self._ratio.publish(Float64(data=ratio))

    def _on_setting(self, message: Bool, name: str) -> None:
        self.settings[name] = bool(message.data)
        self._event("status", f"{self.topics.arm}: {name} {bool(message.data)}")

    # -- services ---------------------------------------------------------------------------------
    def _fk_joints(self, jp: Any, response: Any) -> bool:
        q = np.asarray(jp, dtype=float)
        if q.shape != (6,) or not np.all(np.isfinite(q)):
            response.result = False
            response.message = f"expects 6 finite joints ({', '.join(JOINT_NAMES)}), got {[float(v) for v in q]}"
            return False
        self._fk_configuration.update(q)
        return True

    def _on_forward_kinematics(self, request: Any, response: Any) -> Any:
        if self._fk_joints(request.jp, response):
            pose = self._fk_configuration.measured_pose()
            response.cp = convert.pose_stamped(pose, self.topics.base_frame_id).pose
            response.result = True
        return response

    def _on_local_forward_kinematics(self, request: Any, response: Any) -> Any:
        if self._fk_joints(request.jp, response):
            response.cp = convert.pose_stamped(self._fk_configuration.local_pose(), self.topics.local_frame_id).pose
            response.result = True
        return response

    def _on_inverse_kinematics(self, request: Any, response: Any) -> Any:
        start = np.asarray(request.jp, dtype=float)
        if start.shape != (6,) or not np.all(np.isfinite(start)):
            response.result, response.message = False, "incorrect number of joints"
            return response
        goal = PoseStamped()
        goal.pose = request.cp
        self._ik_configuration.update(np.clip(start, self.model.lower, self.model.upper))
        q, residual = inverse_kinematics(self._ik_configuration, convert.pose_matrix(goal))
        response.jp = [float(v) for v in q]
        response.result = residual <= 1e-4
        response.message = "" if response.result else f"inverse kinematics failed (residual {residual * 1000:.2f} mm)"
        return response

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
        self._sense(dt)
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

    def _subscribed(self, name: str) -> bool:
        """Whether any subscriber is matched on a state topic: a message for nobody is neither built nor sent.

        At 1 kHz, building and publishing the 14 state topics took most of the console's time, and a client
        typically reads half of them. A subscriber that connects gets the next period's message.
        """
        return bool(self._pub[name].get_subscription_count() > 0)

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
        self._publish_jaw(stamp)
        self._publish_poses_and_force(stamp)

    def _publish_arm_joints(self, stamp: float | None = None) -> None:
        stamp, sample = self._stamp() if stamp is None else stamp, self._sample
        if self._subscribed("measured_js"):
            # Joint efforts: what the motors exert against the force on the tool (J^T f) and what the console
            # does not model (self.sensor), plus a commanded effort in effort mode. measured_cf is computed
            # from them the other way round, as the console does.
            effort = self._efforts
            if self._mode == "effort":
                effort = effort + self._setpoint_effort
            self._pub["measured_js"].publish(
                convert.joint_state(JOINT_NAMES, sample.q, sample.qd, effort, stamp_s=stamp)
            )
        if self._subscribed("setpoint_js"):
            self._pub["setpoint_js"].publish(
                convert.joint_state(JOINT_NAMES, self._setpoint_q, effort=self._setpoint_effort, stamp_s=stamp)
            )

    def _publish_jaw(self, stamp: float) -> None:
        sample = self._sample
        if self._subscribed("jaw/measured_js"):
            self._pub["jaw/measured_js"].publish(
                convert.joint_state(
                    (JAW_JOINT_NAME,), [sample.jaw], [sample.jaw_velocity], [sample.jaw_effort], stamp_s=stamp
                )
            )
        if self._subscribed("jaw/setpoint_js"):
            self._pub["jaw/setpoint_js"].publish(
                convert.joint_state((JAW_JOINT_NAME,), [self._setpoint_jaw], stamp_s=stamp)
            )

    def _publish_poses_and_force(self, stamp: float) -> None:
        sample = self._sample
        base_id, local_id = self.topics.base_frame_id, self.topics.local_frame_id
        wanted = {name for name in _MEASURED_TOPICS + _SETPOINT_TOPICS if self._subscribed(name)}
        if wanted & set(_SETPOINT_TOPICS):
            self.configuration.update(self._setpoint_q, sample.jaw)
            self._publish_pose("setpoint", wanted, stamp)
        if not wanted & set(_MEASURED_TOPICS):
            return
        self.configuration.update(sample.q, sample.jaw)
        self._publish_pose("measured", wanted, stamp)
        rotation = self.configuration.measured_pose()[:3, :3]
        if "spatial/measured_cf" in wanted:
            spatial = convert.wrench_stamped(self._sensed_force, frame_id=base_id, stamp_s=stamp)
            self._pub["spatial/measured_cf"].publish(spatial)
        if "body/measured_cf" in wanted:
            tip_id = f"{self.topics.arm}_tip"
            body = convert.wrench_stamped(rotation.T @ self._sensed_force, frame_id=tip_id, stamp_s=stamp)
            self._pub["body/measured_cf"].publish(body)
        if not wanted & {"spatial/jacobian", "body/jacobian", "measured_cv", "local/measured_cv"}:
            return
        local_jacobian = self.configuration.local_jacobian()
        spatial_jacobian = self.configuration.base_jacobian()
        if "spatial/jacobian" in wanted:
            self._pub["spatial/jacobian"].publish(_matrix_message(spatial_jacobian))
        if "body/jacobian" in wanted:
            body_jacobian = np.vstack([rotation.T @ spatial_jacobian[:3], rotation.T @ spatial_jacobian[3:]])
            self._pub["body/jacobian"].publish(_matrix_message(body_jacobian))
        if "measured_cv" in wanted:
            self._pub["measured_cv"].publish(_twist_stamped(spatial_jacobian @ sample.qd, base_id, stamp))
        if "local/measured_cv" in wanted:
            self._pub["local/measured_cv"].publish(_twist_stamped(local_jacobian @ sample.qd, local_id, stamp))

    def _publish_pose(self, prefix: str, wanted: set[str], stamp: float) -> None:
        """``<prefix>_cp`` and ``local/<prefix>_cp`` at the configuration's joints, those subscribed."""
        if f"local/{prefix}_cp" in wanted:
            local = convert.pose_stamped(self.configuration.local_pose(), self.topics.local_frame_id, stamp)
            self._pub[f"local/{prefix}_cp"].publish(local)
        if f"{prefix}_cp" in wanted:
            pose = convert.pose_stamped(self.configuration.measured_pose(), self.topics.base_frame_id, stamp)
            self._pub[f"{prefix}_cp"].publish(pose)


#: State topics computed at the measured joints.
_MEASURED_TOPICS = (
    "measured_cp",
    "local/measured_cp",
    "body/measured_cf",
    "spatial/measured_cf",
    "body/jacobian",
    "spatial/jacobian",
    "measured_cv",
    "local/measured_cv",
)
#: State topics computed at the set-point joints.
_SETPOINT_TOPICS = ("setpoint_cp", "local/setpoint_cp")


def _matrix_message(matrix: np.ndarray) -> Float64MultiArray:
    """A row-major ``std_msgs/Float64MultiArray`` of a 2-D array, as the dVRK publishes its Jacobians."""
    rows, columns = matrix.shape
    message = Float64MultiArray()
    message.layout.dim = [
        MultiArrayDimension(label="rows", size=rows, stride=rows * columns),
        MultiArrayDimension(label="columns", size=columns, stride=columns),
    ]
    message.data = [float(v) for v in matrix.ravel()]
    return message


def _twist_stamped(twist: np.ndarray, frame_id: str, stamp_s: float) -> TwistStamped:
    """A ``geometry_msgs/TwistStamped`` from [linear (3); angular (3)]."""
    message = TwistStamped()
    message.header.stamp = convert.seconds_to_time(stamp_s)
    message.header.frame_id = frame_id
    linear, angular = message.twist.linear, message.twist.angular
    linear.x, linear.y, linear.z = (float(v) for v in twist[:3])
    angular.x, angular.y, angular.z = (float(v) for v in twist[3:])
    return message
