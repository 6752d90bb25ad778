"""Joint acceleration limits: never ask a moving joint to stop sooner than it can brake."""

from __future__ import annotations

import math

import numpy as np

from safety.limits.limit import FilterState, Limit

__all__ = ["AT_REST_SPEED", "JointAccelerationLimit"]

#: Speeds below this count as at rest [rad/s or m/s]. Ruckig leaves float dust such as -2.9e-20 after a
#: stop; taken as motion, its sign would forbid the joint from ever moving the other way.
AT_REST_SPEED = 1e-9


class JointAccelerationLimit(Limit):
    """A moving joint's goal must lie at least ``v^2 / (2 a_max)`` ahead of it (hard).

    That is the least distance in which any stop within the acceleration limit can be made: a goal closer
    than that cannot be reached without exceeding the limit (the smoother would overshoot it instead), so
    the filter moves the goal out to where the joint can really stop. The distance is capped at the
    largest step and at the room left to the position bounds, so the row never conflicts with the joint
    position, velocity and insertion limits (the smoother's own braking then governs).

    Args:
        acceleration_limit: Per-joint acceleration limits (6,).
        max_step: Largest goal step per joint (6,), as in :class:`JointVelocityLimit`.
        lower: Lowest allowed goal per joint (6,) (position limits with margin, minimum insertion).
        upper: Highest allowed goal per joint (6,).
    """

    name = "joint_acceleration"
    joint_bounds = True

    def __init__(
        self, acceleration_limit: np.ndarray, max_step: np.ndarray, lower: np.ndarray, upper: np.ndarray
    ) -> None:
        self.acceleration = np.asarray(acceleration_limit, dtype=float)
        self.max_step = np.asarray(max_step, dtype=float)
        self.lower = np.asarray(lower, dtype=float)
        self.upper = np.asarray(upper, dtype=float)
        self.rows = self.acceleration.size
        self._G = np.zeros((self.rows, self.rows))
        self._h = np.full(self.rows, np.inf)
        self._half_inverse = (0.5 / self.acceleration).tolist()
        self._step = self.max_step.tolist()
        self._lower = self.lower.tolist()
        self._upper = self.upper.tolist()

    def compute_qp_inequalities(self, state: FilterState) -> tuple[np.ndarray, np.ndarray]:
        """Row ``-sign(qd_i) dq_i <= -min(qd_i^2 / (2 a_i), step_i, room_i)`` per moving joint."""
        direction = np.where(np.abs(state.qd) < AT_REST_SPEED, 0.0, np.sign(state.qd))
        np.fill_diagonal(self._G, -direction)
        room = np.where(direction > 0, self.upper - state.q, state.q - self.lower)
        distance = np.minimum(np.minimum(state.qd**2 / (2.0 * self.acceleration), self.max_step), room)
        self._h[:] = np.where(direction != 0.0, -np.maximum(distance, 0.0), np.inf)
        return self._G, self._h

    def compute_joint_bounds(self, state: FilterState) -> tuple[np.ndarray, np.ndarray]:
        """``dq_i >= d_i`` for a joint moving up, ``dq_i <= -d_i`` moving down; ``d_i`` as in the rows."""
        # Six joints: plain floats are several times quicker than a dozen tiny NumPy calls.
        q, qd = state.q.tolist(), state.qd.tolist()
        lower = [-math.inf] * len(q)
        upper = [math.inf] * len(q)
        for i, v in enumerate(qd):
            if v > AT_REST_SPEED:
                lower[i] = max(min(v * v * self._half_inverse[i], self._step[i], self._upper[i] - q[i]), 0.0)
            elif v < -AT_REST_SPEED:
                upper[i] = -max(min(v * v * self._half_inverse[i], self._step[i], q[i] - self._lower[i]), 0.0)
        return np.array(lower), np.array(upper)
