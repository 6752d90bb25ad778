"""The retraction-force limit, predicted with an online estimate of the tissue's stiffness."""

from __future__ import annotations

import math

import numpy as np

from safety.limits.limit import FilterState, Limit

__all__ = ["RetractionForceLimit"]

# Sign patterns (along n, along t1, along t2) of the rows: the first four bound motion that may pull
# harder, the last four close the octahedron when no force direction is known yet.
_SIGNS = np.array(
    [
        [1.0, 1.0, 1.0],
        [1.0, 1.0, -1.0],
        [1.0, -1.0, 1.0],
        [1.0, -1.0, -1.0],
        [-1.0, 1.0, 1.0],
        [-1.0, 1.0, -1.0],
        [-1.0, -1.0, 1.0],
        [-1.0, -1.0, -1.0],
    ]
)


def _frame(n: np.ndarray) -> np.ndarray:
    """Rows ``n, t1, t2``: an orthonormal frame whose first axis is the unit vector ``n``."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1)
    return np.array([n, t1, np.cross(n, t1)])


class RetractionForceLimit(Limit):
    """Keep the predicted retraction-force magnitude below ``F_max`` in every direction of motion (soft).

    With the force ``F`` the tool applies to the tissue, its direction ``n`` and a frame ``(n, t1, t2)``,
    a displacement ``d = J dq`` of the point the jaws hold on tissue of stiffness ``K`` (isotropic, the estimate) gives
    ``|F + K d|^2 = (|F| + K d_n)^2 + K^2 (d_t1^2 + d_t2^2)``, which never exceeds
    ``(|F| + K (d_n + |d_t1| + |d_t2|))^2``. So the four rows
    ``K (d_n +- d_t1 +- d_t2) <= F_max - |F|`` bound the magnitude, not only its component along ``n``:
    a sideways step, which the tissue's geometry turns into a harder pull, spends the same budget as a
    step along the force, and at the limit the only moves allowed back off along ``-n``. Soft, so a force
    already above the limit is driven back down by the least step that predicts it at the limit again
    (the slack's penalty), instead of being held there.

    While no force direction is known (``|F| < min_force_n``, or no reading) but the jaw grips, four
    more rows with ``-d_n`` make the set an octahedron: a step in any direction adds at most
    ``F_max - |F|``. With the jaw open and no force measured, the rows are unused.

    The goal ``dq`` is where the joints come to rest (the smoother never passes its furthest goal), and
    the joint-acceleration rows push it out to at least the braking distance of motion under way, so
    the force predicted here is the force at the end of the stop, not the one a tick later.

    The rows plan to ``(1 - reserve) F_max``: the reserve absorbs what the quasi-static prediction misses
    (the tissue still moving after the tool stops, a reading one tick old).

    Args:
        force_limit_n: ``F_max`` [N].
        min_force_n: Smallest force whose direction is used [N].
        dof: Number of joints.
        reserve: Fraction of ``F_max`` the plan keeps unused, in [0, 1).
    """

    name = "retraction_force"
    soft = True
    rows = 8

    def __init__(self, force_limit_n: float, min_force_n: float = 0.05, dof: int = 6, reserve: float = 0.0) -> None:
        self.force_limit_n = float(force_limit_n)
        self.reserve = float(reserve)
        self._planned_n = self.force_limit_n * (1.0 - self.reserve)
        self.min_force_n = float(min_force_n)
        self._G = np.zeros((self.rows, dof))
        self._h = np.full(self.rows, np.inf)
        self._up = np.array([0.0, 0.0, 1.0])

    def compute_qp_inequalities(self, state: FilterState) -> tuple[np.ndarray, np.ndarray]:
        """Rows ``K (s . frame) J dq <= F_max - |F|`` (see the class); unused with an open, unloaded jaw."""
        force = np.asarray(state.retraction_force_n, dtype=float)
        magnitude = math.sqrt(float(force @ force))
        known = magnitude >= self.min_force_n  # False for NaN too
        G, h = self._G, self._h
        if not (known or state.gripping):
            G[:] = 0.0
            h[:] = np.inf
            return G, h
        frame = _frame(force / magnitude if known else self._up)
        budget = self._planned_n - (magnitude if math.isfinite(magnitude) else 0.0)
        jacobian = state.tool_jacobian if state.grasp_jacobian is None else state.grasp_jacobian
        np.matmul(state.stiffness_n_per_m * (_SIGNS @ frame), jacobian, out=G)
        h[:] = budget
        if known:
            G[4:] = 0.0
            h[4:] = np.inf
        return G, h
