"""The control chain: the only path from a policy's action to a backend.

    CartesianDelta --set_target--> goal pose
    tick:  measured state -> checks -> IK (psm_control.ik) -> safety filter -> Ruckig -> verifier -> command

:class:`ControlChain` implements :class:`psm_control.commands.Controller`; the simulation and the ROS 2
interface drive it the same way (``set_target`` once per policy step, ``tick`` once per control period).
Kinematics are linearised at the last command (where the robot is being sent), so the motion is smooth
whatever the measurements do; measurements are checked (finite, fresh, inside the limits) and supply
the pose a delta applies to and the tissue force.

Bad input and faults (NaN/inf/huge actions, stale measurements, a failed QP, a measured state outside the
limits, any unexpected error) never raise out of :meth:`ControlChain.tick`: the chain brakes along a
jerk-limited stop, or holds the last verified command, and reports a safety stop with its reason.
"""

from __future__ import annotations

import math
import sys
from typing import Any

import numpy as np

from psm_control.commands import CartesianDelta, ControlOutput, JointCommand, MeasuredState
from psm_control.errors import TissueRetractError
from psm_control.frames import BaseTransform
from psm_control.ik import DifferentialIk
from psm_control.reductions import all_of
from psm_control.robot import PsmModel
from psm_control.urdf import GRASP_FRAME
from safety.config import SafetyConfig
from safety.filter import SafetyFilter
from safety.force_bound import ForceBound
from safety.force_watch import ForceLimitStallWatch
from safety.limits import (
    FilterState,
    JointAccelerationLimit,
    JointPositionLimit,
    JointVelocityLimit,
    Limit,
    RcmInsertionLimit,
    RetractionForceLimit,
    WorkspaceBoxLimit,
    may_hold_tissue,
)
from safety.log import SafetyLog
from safety.smoother import JointSmoother
from safety.stiffness import StiffnessEstimator
from safety.verifier import CommandVerifier

__all__ = ["DEADMAN_STOP", "ControlChain", "default_limits"]

_TRACKING_TOLERANCE = 1e-6
#: How the reason of a stop for a stale measurement begins: its stamp is older than the deadman timeout by
#: the chain's own clock (which starts at the stamp of the measurement it was reset with). A deploy to a
#: robot holds on it.
DEADMAN_STOP = "deadman: "


def default_limits(config: SafetyConfig) -> list[Limit]:
    """The filter's limits for a configuration, hard ones first."""
    step = config.velocity * config.horizon_s
    margin = np.asarray(config.position_margin)
    lower = config.spec.lower + margin
    lower[2] = max(lower[2], config.min_insertion_m)
    upper = config.spec.upper - margin
    return [
        JointPositionLimit(config.spec.lower, config.spec.upper, np.asarray(config.position_margin)),
        JointVelocityLimit(config.velocity, config.horizon_s),
        RcmInsertionLimit(config.min_insertion_m, config.spec.dof),
        JointAccelerationLimit(config.acceleration, step, lower, upper),
        WorkspaceBoxLimit(np.asarray(config.workspace_min_m), np.asarray(config.workspace_max_m), config.cbf_gamma),
        RetractionForceLimit(config.effective_force_limit_n, config.acceleration, config.jerk),
    ]


def _rot_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class ControlChain:
    """IK -> QP safety filter -> Ruckig -> verifier, one tick per control period.

    Args:
        config: Safety configuration (validated); default :class:`SafetyConfig()`.
        base_frame: 4x4 pose of the RCM in the base frame (dVRK ``set_base_frame``); default identity.
        safety: False skips the safety filter and verifier limits (ablation only; says so on stderr).
        naive_qp: Rebuild and solve every QP through ``qpsolvers.solve_qp`` (the benchmark's reference).
    """

    def __init__(
        self,
        config: SafetyConfig | None = None,
        *,
        base_frame: np.ndarray | None = None,
        safety: bool = True,
        naive_qp: bool = False,
    ) -> None:
        self.config = config if config is not None else SafetyConfig()
        self.control_period_s = self.config.control_period_s
        self.safety = safety
        if not safety:
            print(
                "WARNING: ControlChain(safety=False): the safety filter and hard-limit verifier are OFF "
                "(ablation only; never on hardware)",
                file=sys.stderr,
            )
        self.model = PsmModel(self.config.spec)
        self._command_state = self.model.configuration(base_frame=base_frame)
        self._measured_state = self.model.configuration(base_frame=base_frame)
        self._verifier_state = self.model.configuration(base_frame=base_frame)
        self.ik = DifferentialIk(
            self.model.dof,
            eps_abs=self.config.solver_eps,
            eps_rel=self.config.solver_eps,
            max_iter=self.config.solver_max_iter,
            naive=naive_qp,
        )
        self.step = self.config.velocity * self.config.horizon_s
        self.limits = default_limits(self.config)
        self.filter = SafetyFilter(
            self.limits,
            self.step,
            slack_penalty=self.config.slack_penalty,
            eps=self.config.solver_eps,
            max_iter=self.config.solver_max_iter,
            hard_tolerance=self.config.hard_tolerance,
            naive=naive_qp,
        )
        self.smoother = JointSmoother(
            self.config.velocity, self.config.acceleration, self.config.jerk, self.control_period_s
        )
        self.verifier = CommandVerifier(self.config, self._verifier_state)
        self.stiffness = StiffnessEstimator(
            self.config.stiffness_prior_n_per_m,
            min_n_per_m=self.config.stiffness_min_n_per_m,
            max_n_per_m=self.config.stiffness_max_n_per_m,
            forgetting=self.config.stiffness_forgetting,
        )
        self.force_bound = ForceBound.from_config(self.config)
        self.log = SafetyLog(tuple(limit.name for limit in self.limits), self.control_period_s, self.model.dof)
        self.stall_watch = ForceLimitStallWatch(self.config.effective_force_limit_n, self.control_period_s)
        self._goal_local: np.ndarray | None = None
        self._jaw_goal = 0.0
        self._jaw = 0.0
        self._stamp = 0.0
        self._pending_stop = ""
        self._latched = ""
        self._is_reset = False
        self._zeros = np.zeros(self.model.dof)
        self._negative_step = -self.step
        self._jaw_step = float(self.model.spec.jaw_velocity_limit * self.control_period_s)
        self._base = BaseTransform(self._command_state.base_frame)
        self._q_center = (self.model.lower + self.model.upper) / 2.0
        self._q_half = (self.model.upper - self.model.lower) / 2.0

    def set_base_frame(self, transform_rcm_to_base: np.ndarray) -> None:
        """Set the pose of the RCM in the base frame (as the dVRK's ``set_base_frame``)."""
        for state in (self._command_state, self._measured_state, self._verifier_state):
            state.set_base_frame(transform_rcm_to_base)
        self.verifier.set_base_frame(self._command_state.base_frame)
        self._base = BaseTransform(self._command_state.base_frame)

    # -- Controller protocol -------------------------------------------------------------------------

    def reset(self, measured: MeasuredState) -> None:
        """Forget the goal, the motion and any latched stop; hold at the measured configuration."""
        self._goal_local = None
        self._pending_stop = ""
        self._latched = ""
        self.stiffness.reset()
        self.force_bound.reset()
        self.ik.reset()
        self.filter.reset()
        self.stall_watch.reset()
        self._is_reset = True
        self._stamp = float(measured.stamp_s) if np.isfinite(measured.stamp_s) else 0.0
        try:
            q = self.model.check_joints(measured.q, strict=True)
            self._jaw = self.model.check_jaw(measured.jaw)
        except TissueRetractError as e:
            # Out of limits or not finite: hold where the robot is reported (if finite) and latch the stop.
            self._latched = f"measured state invalid at reset: {e}"
            q = np.asarray(measured.q, dtype=float)
            if q.shape != (self.model.dof,) or not np.all(np.isfinite(q)):
                q = self.model.home()
            self._jaw = float(measured.jaw) if np.isfinite(measured.jaw) else 0.0
        self._jaw_goal = self._jaw
        self._command_state.update(q)
        self.smoother.reset(q)
        self.verifier.reset(JointCommand(q.copy(), self._zeros.copy(), self._zeros.copy(), self._jaw, self._stamp))

    def set_target(self, delta: CartesianDelta, measured: MeasuredState) -> None:
        """Set the goal: ``delta`` applied to the measured tool pose. Bad input clears it and stops."""
        reason = self._check_delta(delta)
        if not reason:
            try:
                self._measured_state.update(self.model.check_joints(measured.q))
            except TissueRetractError as e:
                reason = f"bad measurement: {e}"
        if reason:
            self._goal_local = None
            self._pending_stop = reason
            return
        translation = np.asarray(delta.translation_m, dtype=float)
        rotation = _rot_z(float(delta.yaw_rad))
        if delta.frame == "base":
            goal = self._measured_state.measured_pose()
            goal[:3, 3] += translation
            goal[:3, :3] = rotation @ goal[:3, :3]
            goal = self._base.transform_base_to_rcm @ goal
        else:
            goal = self._measured_state.local_pose()
            goal[:3, 3] += translation
            goal[:3, :3] = rotation @ goal[:3, :3]
        self._goal_local = goal
        self._jaw_goal = float(np.clip(delta.jaw_rad, self.model.spec.jaw_lower, self.model.spec.jaw_upper))

    def tick(self, measured: MeasuredState) -> ControlOutput:
        """Advance one period; always returns a verified command (or the held last safe one)."""
        try:
            return self._tick(measured)
        except Exception as e:  # the safety boundary: no error may leave the backend unchecked
            return self._stop(f"internal error: {type(e).__name__}: {e}", brake=False)

    # -- internals ----------------------------------------------------------------------------------

    def _check_delta(self, delta: CartesianDelta) -> str:
        try:
            translation = np.asarray(delta.translation_m, dtype=float)
            yaw, jaw = float(delta.yaw_rad), float(delta.jaw_rad)
        except (TypeError, ValueError) as e:
            return f"bad action: not numeric ({e})"
        if translation.shape != (3,) or not np.all(np.isfinite(translation)):
            return f"bad action: translation must be 3 finite numbers, got {translation}"
        if not (math.isfinite(yaw) and math.isfinite(jaw)):
            return f"bad action: yaw={yaw}, jaw={jaw} must be finite"
        if float(np.linalg.norm(translation)) > self.config.max_translation_m:
            return f"bad action: translation {np.linalg.norm(translation):.3g} m > {self.config.max_translation_m} m"
        if abs(yaw) > self.config.max_yaw_rad:
            return f"bad action: yaw {yaw:.3g} rad beyond +-{self.config.max_yaw_rad} rad"
        if delta.frame not in ("base", "local"):
            return f"bad action: frame {delta.frame!r} is not 'base' or 'local'"
        return ""

    def _check_measured(self, measured: MeasuredState, now: float) -> str:
        stamp = float(measured.stamp_s)
        if not math.isfinite(stamp):
            return "bad measurement: stamp is not finite"
        if now - stamp > self.config.deadman_timeout_s:
            return f"{DEADMAN_STOP}measurement {now - stamp:.3g} s old > {self.config.deadman_timeout_s} s"
        q = np.asarray(measured.q, dtype=float)
        # One comparison passes a finite in-limit vector (NaN fails it); anything else gets the detailed check.
        if q.shape != self.model.lower.shape or not all_of(np.abs(q - self._q_center) <= self._q_half):
            try:
                self.model.check_joints(measured.q, strict=True, name="measured q")
            except TissueRetractError as e:
                return f"measured state outside limits: {e}"
        force = np.asarray(measured.force_n, dtype=float)
        if force.shape != (3,) or not math.isfinite(float(force.sum())):
            return "bad measurement: force is not 3 finite numbers"
        return ""

    def _command(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> JointCommand:
        step = self._jaw_step
        self._jaw += min(max(self._jaw_goal - self._jaw, -step), step)
        return JointCommand(q, qd, qdd, self._jaw, self._stamp)

    def _stop(self, reason: str, *, brake: bool = True) -> ControlOutput:
        """Clear the goal and stop: brake along a jerk-limited stop if it verifies, else hold."""
        self._goal_local = None
        self._jaw_goal = self._jaw
        if not self._is_reset:
            return ControlOutput(
                JointCommand(self.model.home(), self._zeros, self._zeros, 0.0, self._stamp), True, reason
            )
        if brake:
            try:
                state = self.smoother.brake()
                verdict = self.verifier.verify(self._command(state.q, state.qd, state.qdd))
                if verdict.ok:
                    self.log.record(self._stamp, stop_reason=reason)
                    return ControlOutput(verdict.command, True, reason)
                reason = f"{reason}; {verdict.reason}"
            except Exception as e:  # braking itself failed: fall through to the hold
                reason = f"{reason}; brake failed: {e}"
        command = self.verifier.hold(self._stamp)
        self.smoother.reset(command.q)
        self.log.record(self._stamp, stop_reason=reason)
        return ControlOutput(command, True, reason)

    def _tick(self, measured: MeasuredState) -> ControlOutput:
        if not self._is_reset:
            self.reset(measured)
        self._stamp += self.control_period_s
        if self._latched:
            return self._stop(self._latched, brake=False)
        reason = self._pending_stop or self._check_measured(measured, self._stamp)
        self._pending_stop = ""
        if reason:
            return self._stop(reason)
        current = self.smoother.state
        self._command_state.update(current.q)
        if self._goal_local is None:
            dq_nominal = self._zeros
        else:
            q = current.q
            lower = np.maximum(self.model.lower - q, self._negative_step)
            upper = np.minimum(self.model.upper - q, self.step)
            dq_nominal = self.ik.solve(self._command_state, self._goal_local, lower, upper).dq
        force = -np.asarray(measured.force_n, dtype=float)  # force_n is the tissue's force on the tool
        tool = self._base.point(self._command_state.local_pose()[:3, 3])
        # The stiffness is learned where the tissue is held: the wrist can move the jaws with the tip still.
        held = self._base.point(self._command_state.frame_pose_local(GRASP_FRAME)[:3, 3])
        # An inexact force would teach the estimator its own error as stiffness (safety.force_bound).
        stiffness = self.stiffness.update(held, force) if self.force_bound.exact else self.stiffness.value
        jaw = min(self._jaw, float(measured.jaw))
        # The force was computed with the last command's acceleration (a calibrated dVRK's is: ArmListener), at
        # the commanded tip speed; a sensing regime bounds the force only within the speeds it was judged at.
        tip_speed = None
        if self.force_bound.regime is not None:
            tip_speed = float(np.linalg.norm(self._command_state.local_jacobian()[:3] @ current.qd))
        estimate = self.force_bound.update(jaw, held, force, stiffness, current.qdd, tip_speed)
        interventions: tuple[str, ...] = ()
        events: tuple[dict[str, Any], ...] = ()
        intervened = active = 0
        if self.safety:
            state = FilterState(
                current.q,
                current.qd,
                tool,
                self._base.vectors(self._command_state.local_jacobian()[:3]),
                self._base.vectors(self._command_state.local_jacobian(GRASP_FRAME)[:3]),
                estimate.force_n,
                estimate.stiffness_n_per_m,
                self.control_period_s,
                jaw,
                estimate.margin_n,
                self.force_bound.holding,
            )
            try:
                result = self.filter.filter(state, dq_nominal)
            except TissueRetractError as e:
                return self._stop(f"safety filter: {e}")
            dq = result.dq
            interventions = result.interventions
            intervened = result.intervened_mask
            active = result.active_mask
            holding = state.tissue_held or may_hold_tissue(state.jaw_rad, estimate.force_n, estimate.margin_n)
            grasp_jacobian = state.grasp_jacobian  # the grasp point's motion matters only with tissue held
            stall = self.stall_watch.update(
                holding=holding,
                held_back=RetractionForceLimit.name in interventions,
                force_n=math.sqrt(float(estimate.force_n @ estimate.force_n)) + estimate.margin_n,
                asked_m=float(np.linalg.norm(grasp_jacobian @ dq_nominal)) if holding else 0.0,
                allowed_m=float(np.linalg.norm(grasp_jacobian @ dq)) if holding else 0.0,
                stiffness_n_per_m=estimate.stiffness_n_per_m,
                stamp_s=self._stamp,
                force_source=estimate.source,
            )
            if stall is not None:
                events = (stall.to_event(),)
        else:
            dq = dq_nominal
        try:
            next_state = self.smoother.step_to(current.q + dq)
        except TissueRetractError as e:
            return self._stop(str(e))
        candidate = self._command(next_state.q, next_state.qd, next_state.qdd)
        if self.safety:
            verdict = self.verifier.verify(candidate)
            if not verdict.ok:
                self._latched = verdict.reason
                return self._stop(verdict.reason, brake=False)
            candidate = verdict.command
        self.log.record(
            self._stamp,
            intervened=intervened,
            active=active,
            nominal=dq_nominal,
            filtered=dq,
            force_n=math.sqrt(float(force @ force)),
            stiffness_n_per_m=stiffness,
        )
        return ControlOutput(candidate, False, "", interventions, events)
