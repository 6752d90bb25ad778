"""The minimum shaft insertion past the remote centre of motion."""

from __future__ import annotations

import numpy as np

from safety.limits.limit import FilterState, Limit

__all__ = ["RcmInsertionLimit"]

_INSERTION = 2


class RcmInsertionLimit(Limit):
    """Keep the insertion joint at or above ``min_insertion_m`` (hard).

    The dVRK refuses Cartesian control with less than 45 mm of shaft past the RCM (SafeDistanceFromRCM,
    plus a 2 mm buffer): closer in, the wrist can hit the cannula and the RCM geometry degenerates. Below
    the minimum the only allowed motion is outwards.

    Args:
        min_insertion_m: Lowest insertion [m].
        dof: Number of joints.
    """

    name = "rcm_insertion"
    joint_bounds = True
    rows = 1

    def __init__(self, min_insertion_m: float, dof: int = 6) -> None:
        self.min_insertion_m = float(min_insertion_m)
        self._G = np.zeros((1, dof))
        self._G[0, _INSERTION] = -1.0
        self._h = np.zeros(1)
        self._lower = np.full(dof, -np.inf)
        self._upper = np.full(dof, np.inf)

    def compute_qp_inequalities(self, state: FilterState) -> tuple[np.ndarray, np.ndarray]:
        """Row ``-dq_2 <= max(q_2 - min_insertion, 0)``."""
        self._h[0] = max(float(state.q[_INSERTION]) - self.min_insertion_m, 0.0)
        return self._G, self._h

    def compute_joint_bounds(self, state: FilterState) -> tuple[np.ndarray, np.ndarray]:
        """``dq_2 >= -max(q_2 - min_insertion, 0)``; the other joints are free."""
        self._lower[_INSERTION] = -max(float(state.q[_INSERTION]) - self.min_insertion_m, 0.0)
        return self._lower, self._upper
