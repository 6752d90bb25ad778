"""Joint velocity limits over the look-ahead horizon."""

from __future__ import annotations

import numpy as np

from safety.limits.limit import FilterState, Limit

__all__ = ["JointVelocityLimit"]


class JointVelocityLimit(Limit):
    """Bound one tick's goal step to ``|dq| <= v_max * horizon``.

    The step is the motion asked for over ``horizon`` seconds, so this keeps its mean speed within
    ``v_max`` and the linearised constraints of the other limits trustworthy. The smoother enforces
    the instantaneous velocity limit between ticks.

    Args:
        velocity_limit: Per-joint speed limit (6,) [rad/s, m/s].
        horizon_s: Look-ahead of one goal step [s].
    """

    name = "joint_velocity"
    joint_bounds = True

    def __init__(self, velocity_limit: np.ndarray, horizon_s: float) -> None:
        self.step = np.asarray(velocity_limit, dtype=float) * horizon_s
        dof = self.step.size
        self.rows = 2 * dof
        self._G = np.vstack([np.eye(dof), -np.eye(dof)])
        self._h = np.concatenate([self.step, self.step])
        self._lower = -self.step

    def compute_qp_inequalities(self, state: FilterState) -> tuple[np.ndarray, np.ndarray]:
        """Rows ``dq <= step`` and ``-dq <= step``."""
        return self._G, self._h

    def compute_joint_bounds(self, state: FilterState) -> tuple[np.ndarray, np.ndarray]:
        """``-step <= dq <= step``."""
        return self._lower, self.step
