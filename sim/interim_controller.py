"""Interim controller: damped least-squares differential IK with joint-limit clipping, no safety filter.

It implements the :class:`~psm_control.commands.Controller` protocol so that the environments run
until the project's control chain (IK -> QP safety filter -> smoothing -> verifier) is available.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from psm_control.commands import CartesianDelta, ControlOutput, JointCommand, MeasuredState
from psm_control.robot import PsmConfiguration

__all__ = ["InterimIkController"]


class InterimIkController:
    """Moves the tool tip towards a Cartesian target, one damped least-squares step per tick.

    Args:
        configuration: Robot state object (its base frame places the RCM in the world).
        control_period_s: Tick period [s].
        damping: Levenberg-Marquardt damping of the least-squares step.
    """

    def __init__(self, configuration: PsmConfiguration, control_period_s: float = 1 / 240, damping: float = 1e-4):
        self.configuration = configuration
        self.control_period_s = control_period_s
        self.damping = damping
        self._q = configuration.q.copy()
        self._jaw = configuration.jaw
        self._target = configuration.measured_pose()
        self._jaw_target = self._jaw
        self._stamp = 0.0

    def reset(self, measured: MeasuredState) -> None:
        """Hold at the measured configuration."""
        self.configuration.update(measured.q, measured.jaw)
        self._q, self._jaw = np.array(measured.q, dtype=float), float(measured.jaw)
        self._target, self._jaw_target = self.configuration.measured_pose(), self._jaw
        self._stamp = measured.stamp_s

    def set_target(self, delta: CartesianDelta, measured: MeasuredState) -> None:
        """Target = measured tool pose moved by the delta (translation, then yaw about the frame's z)."""
        self.configuration.update(measured.q, measured.jaw)
        pose = self.configuration.measured_pose()
        rotation = np.eye(3) if delta.frame == "base" else self.configuration.base_frame[:3, :3]
        yaw = pin.exp3(rotation @ np.array([0.0, 0.0, delta.yaw_rad]))
        self._target = pose.copy()
        self._target[:3, 3] += rotation @ np.asarray(delta.translation_m, dtype=float)
        self._target[:3, :3] = yaw @ pose[:3, :3]
        self._jaw_target = float(delta.jaw_rad)

    def tick(self, measured: MeasuredState) -> ControlOutput:
        """One IK step towards the target, limited by the joints' speed and position limits."""
        model, dt = self.configuration.model, self.control_period_s
        self.configuration.update(self._q, self._jaw)
        pose = self.configuration.measured_pose()
        error = np.concatenate([self._target[:3, 3] - pose[:3, 3], pin.log3(self._target[:3, :3] @ pose[:3, :3].T)])
        J = self.configuration.base_jacobian()
        dq = J.T @ np.linalg.solve(J @ J.T + self.damping * np.eye(6), error)
        dq = np.clip(dq, -model.velocity_limit * dt, model.velocity_limit * dt)
        q = np.clip(self._q + dq, model.lower, model.upper)
        jaw_step = model.spec.jaw_velocity_limit * dt
        jaw = float(np.clip(self._jaw + np.clip(self._jaw_target - self._jaw, -jaw_step, jaw_step), *_jaw_range(model)))
        qd = (q - self._q) / dt
        self._q, self._jaw = q, jaw
        self._stamp = measured.stamp_s + dt
        return ControlOutput(JointCommand(q.copy(), qd, np.zeros(6), jaw, self._stamp))


def _jaw_range(model: object) -> tuple[float, float]:
    spec = model.spec  # type: ignore[attr-defined]
    return float(spec.jaw_lower), float(spec.jaw_upper)
