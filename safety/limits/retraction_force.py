"""The retraction-force limit, predicted with an online estimate of the tissue's stiffness."""

from __future__ import annotations

import math

import numpy as np

from safety.limits.limit import FilterState, Limit

__all__ = ["RetractionForceLimit"]


class RetractionForceLimit(Limit):
    """Keep the predicted retraction force along its direction below ``F_max`` (soft, large penalty).

    With the force ``F`` the tool applies to the tissue, its direction ``n = F / |F|`` and the stiffness
    estimate ``K`` along ``n``, a step ``dq`` changes the force by about ``K n^T J dq``, so the row is
    ``n^T (F + K J dq) <= F_max``. Soft, because a force already above the limit may need more than one
    step to relax. Below ``min_force_n`` the direction is not trusted and the row is unused: the
    velocity bound then limits the force one step can add to ``K v_max horizon``.

    Args:
        force_limit_n: ``F_max`` [N].
        min_force_n: Smallest force whose direction is used [N].
        dof: Number of joints.
    """

    name = "retraction_force"
    soft = True
    rows = 1

    def __init__(self, force_limit_n: float, min_force_n: float = 0.05, dof: int = 6) -> None:
        self.force_limit_n = float(force_limit_n)
        self.min_force_n = float(min_force_n)
        self._G = np.zeros((1, dof))
        self._h = np.full(1, np.inf)

    def compute_qp_inequalities(self, state: FilterState) -> tuple[np.ndarray, np.ndarray]:
        """Row ``K n^T J dq <= F_max - |F|``, unused while ``|F| < min_force_n``."""
        fx, fy, fz = state.retraction_force_n.tolist()
        magnitude = math.sqrt(fx * fx + fy * fy + fz * fz)
        if not magnitude >= self.min_force_n:  # also NaN
            self._G[:] = 0.0
            self._h[0] = np.inf
            return self._G, self._h
        scale = state.stiffness_n_per_m / magnitude
        np.dot((fx * scale, fy * scale, fz * scale), state.tool_jacobian, out=self._G[0])
        self._h[0] = self.force_limit_n - magnitude
        return self._G, self._h
