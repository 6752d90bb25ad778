"""Joint acceleration limits: never ask a moving joint to stop sooner than it can brake."""

from __future__ import annotations

import numpy as np

from safety.limits.limit import FilterState, Limit

__all__ = ["JointAccelerationLimit"]


class JointAccelerationLimit(Limit):
    """A moving joint's goal must lie at least ``v^2 / (2 a_max)`` ahead of it (soft).

    That is the least distance in which any stop within the acceleration limit can be made; a goal closer
    than that cannot be reached without exceeding the limit, and the smoother would overshoot it instead.
    Stating it lets the filter trade the overshoot against the other limits, and the report says when a
    policy asked for a harder stop than the robot can make.

    The distance is capped at the largest step (the velocity limit's bound), beyond which the goal only
    keeps the joint moving at full speed.

    Args:
        acceleration_limit: Per-joint acceleration limits (6,).
        max_step: Largest goal step per joint (6,), as in :class:`JointVelocityLimit`.
    """

    name = "joint_acceleration"
    soft = True
    penalty_scale = 1e-3

    def __init__(self, acceleration_limit: np.ndarray, max_step: np.ndarray) -> None:
        self.acceleration = np.asarray(acceleration_limit, dtype=float)
        self.max_step = np.asarray(max_step, dtype=float)
        self.rows = self.acceleration.size
        self._G = np.zeros((self.rows, self.rows))
        self._h = np.full(self.rows, np.inf)

    def compute_qp_inequalities(self, state: FilterState) -> tuple[np.ndarray, np.ndarray]:
        """Row ``-sign(qd_i) dq_i <= -min(qd_i^2 / (2 a_i), step_i)`` for each moving joint, unused otherwise."""
        direction = np.sign(state.qd)
        np.fill_diagonal(self._G, -direction)
        distance = np.minimum(state.qd**2 / (2.0 * self.acceleration), self.max_step)
        self._h[:] = np.where(direction != 0.0, -distance, np.inf)
        return self._G, self._h
