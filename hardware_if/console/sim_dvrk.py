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
  republished every :data:`~hardware_if.console.console_arm.OPERATING_STATE_REPUBLISH_S` for clients that
  subscribe without history),
  ``goal_reached``, ``trajectory_j/ratio``, ``error``, ``warning``, ``status``.
- The operating state machine: ``enable``; ``home`` (enables, takes
  :data:`~hardware_if.console.console_arm.HOMING_SETTLE_S` plus a trajectory to the home joints, ends
  homed; a no-op on an arm that is already homed and idle); ``disable``; ``unhome``.
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
- A clock fault on ``measured_js`` when asked (``stamp_fault``, ``sim-dvrk --stamp-fault``): the last
  message repeated, stamps 5 s in the past, or one stamp 1 h ahead then repeated
  (:mod:`~hardware_if.console.stamp_fault`), to rehearse a client's deadman against it.
- Services (``crtk_msgs/srv``): ``forward_kinematics`` (pose in ``<arm>_base``),
  ``local/forward_kinematics`` (about the RCM) and ``inverse_kinematics`` (goal about the RCM, from the
  request's joints), with the dVRK's ``result``/``message`` conventions.

The operating state machine, the set-points and the console's own motion are
:class:`~hardware_if.console.console_arm.ConsoleArm`'s; the physics is an
:class:`~hardware_if.console.arm_model.ArmModel`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np
from crtk_msgs.msg import StringStamped  # type: ignore[import-untyped]
from crtk_msgs.srv import QueryForwardKinematics, QueryInverseKinematics  # type: ignore[import-untyped]
from geometry_msgs.msg import PoseStamped, WrenchStamped  # type: ignore[import-untyped]
from sensor_msgs.msg import JointState  # type: ignore[import-untyped]
from std_msgs.msg import Bool, Empty, Float64  # type: ignore[import-untyped]

from hardware_if.common import convert
from hardware_if.common.crtk import JOINT_NAMES, periodic_qos
from hardware_if.console.console_arm import ConsoleArm
from hardware_if.console.console_guard import CommandSources
from hardware_if.console.motion import JointTrajectory, inverse_kinematics

__all__ = ["SimulatedPsm"]

#: Jaw goals further than this beyond the jaw's limits are clamped with a warning [rad].
_JAW_CLAMP_WARN_RAD = 1e-3


class SimulatedPsm(ConsoleArm):
    """One simulated PSM on its CRTK topics and services (the arguments are :class:`ConsoleArm`'s)."""

    def _serve(self) -> None:
        """Subscribe to the CRTK command topics and offer the kinematics services."""
        state = periodic_qos()
        t = self.topics.topic
        arm = self.topics.arm
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

    def _on_servo_jp(self, message: JointState) -> None:
        if not self._ready("servo_jp"):
            return
        q = self._joints(message, "servo_jp", strict=False)
        if q is not None:
            self._servo_now(q)
            if self.stamp_fault is not None:
                self.stamp_fault.servo_command()

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
