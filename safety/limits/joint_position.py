"""Joint position limits with a margin, applied to where the commanded motion comes to rest."""

from __future__ import annotations

import numpy as np

from safety.limits.limit import FilterState, Limit

__all__ = ["JointPositionLimit"]


class JointPositionLimit(Limit):
    """Keep the step's goal ``q + dq`` inside ``[lower + margin, upper - margin]``.

    The smoother stops exactly at its goal and never passes the furthest goal it was given (it brakes at
    its acceleration and jerk limits, and a stop it already planned stays feasible), so bounding every goal
    bounds the whole motion: the stopping distance is contained in the goal. A joint already inside the
    margin may stay where it is or move back out of it, never further in.

    Args:
        lower: Lower joint limits (6,).
        upper: Upper joint limits (6,).
        margin: Distance kept from each limit (6,).
    """

    name = "joint_position"
    joint_bounds = True

    def __init__(self, lower: np.ndarray, upper: np.ndarray, margin: np.ndarray) -> None:
        self.lower = np.asarray(lower, dtype=float) + np.asarray(margin, dtype=float)
        self.upper = np.asarray(upper, dtype=float) - np.asarray(margin, dtype=float)
        dof = self.lower.size
        self.rows = 2 * dof
        self._G = np.vstack([np.eye(dof), -np.eye(dof)])

    def compute_qp_inequalities(self, state: FilterState) -> tuple[np.ndarray, np.ndarray]:
        """Rows ``dq <= max(upper - q, 0)`` and ``-dq <= max(q - lower, 0)``."""
        h = np.concatenate([np.maximum(self.upper - state.q, 0.0), np.maximum(state.q - self.lower, 0.0)])
        return self._G, h

    def compute_joint_bounds(self, state: FilterState) -> tuple[np.ndarray, np.ndarray]:
        """``-max(q - lower, 0) <= dq <= max(upper - q, 0)``."""
        return np.minimum(self.lower - state.q, 0.0), np.maximum(self.upper - state.q, 0.0)
