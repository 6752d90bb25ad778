"""The simulated dVRK: a ROS 2 node serving one PSM's CRTK topics, as a real console does.

:class:`SimulatedPsm` publishes the arm's state every period (100 Hz by default), runs the operating
state machine (DISABLED -> ENABLED on ``enable``; ``home`` enables, sets ``is_busy``, moves to the
home joints and ends homed; ``disable``; ``unhome``), follows ``servo_jp`` at once and ``move_jp`` with
a trajectory, and, like the dVRK, refuses Cartesian goals (``servo_cp``, ``move_cp``) while the shaft is
less than 45 mm past the RCM, saying so on ``<arm>/error``. Motion commands are ignored with an error
unless the arm is ENABLED and homed. The physics is an :class:`~hardware_if.arm_model.ArmModel`.
"""

from __future__ import annotations

import time

import numpy as np
from crtk_msgs.msg import OperatingState, StringStamped  # type: ignore[import-untyped]
from geometry_msgs.msg import PoseStamped, WrenchStamped  # type: ignore[import-untyped]
from rclpy.node import Node
from sensor_msgs.msg import JointState  # type: ignore[import-untyped]
from std_msgs.msg import String  # type: ignore[import-untyped]

from hardware_if import convert
from hardware_if.arm_model import ArmModel, ArmSample, KinematicArm
from hardware_if.crtk import (
    DEFAULT_ARM,
    DEFAULT_RATE_HZ,
    JAW_JOINT_NAME,
    JOINT_NAMES,
    ArmTopics,
    event_qos,
    periodic_qos,
)
from hardware_if.motion import JointTrajectory, inverse_kinematics
from psm_control.errors import ConfigurationError
from psm_control.robot import PsmModel

__all__ = ["SimulatedPsm"]


class SimulatedPsm(Node):
    """One simulated PSM on its CRTK topics.

    Args:
        arm: Arm name / namespace.
        rate_hz: Publishing rate of the periodic topics [Hz] (the dVRK's default is 100).
        model: Kinematic model; default the Classic PSM with the 400006 needle driver.
        arm_model: Physics; default :class:`KinematicArm`.
        base_frame: 4x4 pose of the RCM in ``<arm>_base`` (``measured_cp = base_frame @ local``).
        home_q: Joints homing moves to; default all zero, as the dVRK's PSM homing.
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
    ) -> None:
        if not (np.isfinite(rate_hz) and 1.0 <= rate_hz <= 5000.0):
            raise ConfigurationError("rate_hz", rate_hz, "a publishing rate in 1..5000 Hz")
        self.topics = ArmTopics(arm)
        super().__init__(f"{arm.lower()}_sim_dvrk")
        self.period_s = 1.0 / rate_hz
        self.model = model if model is not None else PsmModel.from_variant()
        self.arm_model: ArmModel = arm_model if arm_model is not None else KinematicArm()
        self.configuration = self.model.configuration(np.zeros(6), base_frame=base_frame)
        self._ik_configuration = self.configuration.copy()
        self.home_q = np.zeros(6) if home_q is None else self.model.check_joints(home_q, strict=True)
        self.state = OperatingState(state="DISABLED", is_homed=False, is_busy=False)
        self._setpoint_q = np.zeros(6)
        self._setpoint_jaw = 0.0
        self._trajectory: JointTrajectory | None = None
        self._homing = False
        self._sample: ArmSample = self.arm_model.reset(self._setpoint_q, self._setpoint_jaw)
        self._last_tick_s = time.monotonic()
        self._joints_published_s = float("-inf")

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
        self._operating_state = self.create_publisher(OperatingState, t("operating_state"), event)
        self._events = {name: self.create_publisher(String, t(name), event) for name in ("error", "warning", "status")}
        # Commands arrive volatile: a restarted console must not replay an old "home" from history.
        self.create_subscription(StringStamped, t("state_command"), self._on_state_command, state)
        self.create_subscription(JointState, t("servo_jp"), self._on_servo_jp, state)
        self.create_subscription(JointState, t("move_jp"), self._on_move_jp, state)
        self.create_subscription(JointState, t("jaw/servo_jp"), self._on_jaw_servo_jp, state)
        self.create_subscription(PoseStamped, t("servo_cp"), self._on_servo_cp, state)
        self.create_subscription(PoseStamped, t("move_cp"), self._on_move_cp, state)
        self._publish_operating_state()
        self.create_timer(self.period_s, self._tick)

    def set_base_frame(self, transform_rcm_to_base: np.ndarray) -> None:
        """Move the RCM in ``<arm>_base`` (as the dVRK's ``set_base_frame``; a task reset moves it)."""
        self.configuration.set_base_frame(transform_rcm_to_base)
        self._ik_configuration.set_base_frame(transform_rcm_to_base)

    # -- state machine ----------------------------------------------------------------------------
    def _on_state_command(self, message: StringStamped) -> None:
        command = message.string
        if command == "enable":
            self._set_state("ENABLED")
        elif command == "disable":
            self._trajectory, self._homing = None, False
            self._set_state("DISABLED", is_busy=False)
        elif command == "home":
            self._set_state("ENABLED", is_homed=False, is_busy=True)
            self._homing = True
            self._trajectory = self._plan(self.home_q)
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
        self._publish_operating_state()

    def _publish_operating_state(self) -> None:
        self.state.header.stamp = self.get_clock().now().to_msg()
        self._operating_state.publish(self.state)

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
    def _on_servo_jp(self, message: JointState) -> None:
        if not self._ready("servo_jp"):
            return
        try:
            q = self.model.check_joints(convert.joint_state_positions(message), name="servo_jp")
        except ValueError as e:
            self._event("error", f"{self.topics.arm}: servo_jp rejected: {e}")
            return
        self._trajectory = None
        self._servo(q, self._setpoint_jaw)
        if self.arm_model.instantaneous:
            # The kinematic arm is already there: answer with the new state now, not a period later.
            self._sample = self.arm_model.step(0.0)
            self._publish_joints()

    def _on_jaw_servo_jp(self, message: JointState) -> None:
        if len(message.position) == 1 and self._ready("jaw/servo_jp"):
            self._servo(self._setpoint_q, float(message.position[0]))

    def _on_move_jp(self, message: JointState) -> None:
        if not self._ready("move_jp"):
            return
        try:
            goal = self.model.check_joints(convert.joint_state_positions(message), strict=True, name="move_jp")
        except ValueError as e:
            self._event("error", f"{self.topics.arm}: move_jp rejected: {e}")
            return
        self._trajectory = self._plan(goal)

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
            self._trajectory = None
            self._servo(q, self._setpoint_jaw)

    def _on_move_cp(self, message: PoseStamped) -> None:
        q = self._cartesian_goal(message, "move_cp")
        if q is not None:
            self._trajectory = self._plan(q)

    def _plan(self, goal: np.ndarray) -> JointTrajectory:
        spec = self.model.spec
        return JointTrajectory(self._setpoint_q, goal, spec.velocity_limit, spec.acceleration_limit, time.monotonic())

    def _servo(self, q: np.ndarray, jaw: float) -> None:
        self._setpoint_q = np.asarray(q, dtype=float).copy()
        self._setpoint_jaw = float(jaw)
        self.arm_model.command(self._setpoint_q, self._setpoint_jaw)

    # -- periodic publication ---------------------------------------------------------------------
    def _tick(self) -> None:
        now = time.monotonic()
        dt = now - self._last_tick_s
        self._last_tick_s = now
        if self._trajectory is not None:
            q, _ = self._trajectory.sample(now)
            self._servo(q, self._setpoint_jaw)
            if self._trajectory.done(now):
                self._trajectory = None
                if self._homing:
                    self._homing = False
                    self._set_state("ENABLED", is_homed=True, is_busy=False)
        self._sample = self.arm_model.step(dt)
        if now - self._joints_published_s >= 0.5 * self.period_s:
            self._publish_joints()
        self._publish_poses_and_force()

    def _stamp(self) -> float:
        return float(self.get_clock().now().nanoseconds) * 1e-9

    def _publish_joints(self) -> None:
        self._joints_published_s = time.monotonic()
        stamp, sample = self._stamp(), self._sample
        self._pub["measured_js"].publish(convert.joint_state(JOINT_NAMES, sample.q, sample.qd, stamp_s=stamp))
        self._pub["setpoint_js"].publish(convert.joint_state(JOINT_NAMES, self._setpoint_q, stamp_s=stamp))
        self._pub["jaw/measured_js"].publish(convert.joint_state((JAW_JOINT_NAME,), [sample.jaw], stamp_s=stamp))
        self._pub["jaw/setpoint_js"].publish(
            convert.joint_state((JAW_JOINT_NAME,), [self._setpoint_jaw], stamp_s=stamp)
        )

    def _publish_poses_and_force(self) -> None:
        stamp, sample = self._stamp(), self._sample
        base_id, local_id = self.topics.base_frame_id, self.topics.local_frame_id
        for prefix, q in (("measured", sample.q), ("setpoint", self._setpoint_q)):
            self.configuration.update(q, sample.jaw)
            local = self.configuration.local_pose()
            self._pub[f"local/{prefix}_cp"].publish(convert.pose_stamped(local, local_id, stamp))
            self._pub[f"{prefix}_cp"].publish(convert.pose_stamped(self.configuration.measured_pose(), base_id, stamp))
        self.configuration.update(sample.q, sample.jaw)
        rotation = self.configuration.measured_pose()[:3, :3]
        spatial = convert.wrench_stamped(sample.force_n, frame_id=base_id, stamp_s=stamp)
        self._pub["spatial/measured_cf"].publish(spatial)
        body = convert.wrench_stamped(rotation.T @ sample.force_n, frame_id=f"{self.topics.arm}_tip", stamp_s=stamp)
        self._pub["body/measured_cf"].publish(body)
