"""Motion the simulated dVRK performs itself: ``move_jp`` trajectories and the IK behind ``*_cp`` goals.

:class:`JointTrajectory` is a synchronised quintic from one joint vector to another whose duration
keeps every joint within the dVRK's ``move_jp`` velocity and acceleration limits (the dVRK runs a
trajectory generator with those limits; it is not a straight line in Cartesian space).
:func:`inverse_kinematics` is a damped least-squares solve on the project's Pinocchio model, enough
for the simulated console to follow ``servo_cp``/``move_cp`` goals; the control chain has its own IK.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from psm_control.robot import PsmConfiguration

__all__ = ["JointTrajectory", "inverse_kinematics"]

# Peak speed and acceleration of the quintic s(t) = 10 t^3 - 15 t^4 + 6 t^5 over unit time and distance.
_QUINTIC_PEAK_VELOCITY = 1.875
_QUINTIC_PEAK_ACCELERATION = 10.0 / np.sqrt(3.0)


class JointTrajectory:
    """A rest-to-rest joint move within velocity and acceleration limits.

    Args:
        start: Start joints (n,).
        goal: Goal joints (n,).
        velocity_limit: Per-joint speed limit (n,) [rad/s or m/s].
        acceleration_limit: Per-joint acceleration limit (n,).
        start_s: Time the move starts [s].
    """

    def __init__(
        self,
        start: np.ndarray,
        goal: np.ndarray,
        velocity_limit: np.ndarray,
        acceleration_limit: np.ndarray,
        start_s: float = 0.0,
    ) -> None:
        self.start = np.asarray(start, dtype=float).copy()
        self.goal = np.asarray(goal, dtype=float).copy()
        self.start_s = start_s
        distance = np.abs(self.goal - self.start)
        by_velocity = _QUINTIC_PEAK_VELOCITY * distance / np.asarray(velocity_limit, dtype=float)
        by_acceleration = np.sqrt(_QUINTIC_PEAK_ACCELERATION * distance / np.asarray(acceleration_limit, dtype=float))
        self.duration_s = float(max(np.max(by_velocity, initial=0.0), np.max(by_acceleration, initial=0.0)))

    def done(self, t_s: float) -> bool:
        """Whether the move has finished at time ``t_s``."""
        return t_s - self.start_s >= self.duration_s

    def sample(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Position and velocity at time ``t_s`` (held at the ends)."""
        if self.duration_s <= 0.0:
            return self.goal.copy(), np.zeros_like(self.goal)
        tau = float(np.clip((t_s - self.start_s) / self.duration_s, 0.0, 1.0))
        s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
        ds = 30.0 * tau**2 * (1.0 - tau) ** 2 / self.duration_s
        delta = self.goal - self.start
        return self.start + s * delta, ds * delta


def inverse_kinematics(
    configuration: PsmConfiguration,
    goal_local: np.ndarray,
    *,
    iterations: int = 100,
    damping: float = 1e-4,
    tolerance: float = 1e-6,
) -> tuple[np.ndarray, float]:
    """Joints that put the tool tip at ``goal_local`` (4x4, about the RCM), from the configuration's q.

    Damped least squares on the 6-D pose error, clamped to the joint limits each step. The
    configuration is left at the solution.

    Returns:
        The joints (6,) and the remaining position error [m].
    """
    model = configuration.model
    goal = pin.SE3(goal_local[:3, :3].copy(), goal_local[:3, 3].copy())
    q = configuration.q.copy()
    for _ in range(iterations):
        current = configuration.local_pose()
        error_pose = pin.SE3(current[:3, :3].copy(), current[:3, 3].copy()).actInv(goal)
        twist_local = pin.log6(error_pose).vector
        # Express the error in the RCM frame's axes, as the Jacobian is (LOCAL_WORLD_ALIGNED).
        rotation = current[:3, :3]
        error = np.concatenate([rotation @ twist_local[:3], rotation @ twist_local[3:]])
        if np.linalg.norm(error) < tolerance:
            break
        J = configuration.local_jacobian()
        dq = J.T @ np.linalg.solve(J @ J.T + damping * np.eye(6), error)
        q = np.clip(q + dq, model.lower, model.upper)
        configuration.update(q)
    residual = float(np.linalg.norm(configuration.local_pose()[:3, 3] - goal_local[:3, 3]))
    return q, residual
