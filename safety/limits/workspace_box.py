"""A box the tool tip must stay in, as a discrete-time control barrier function."""

from __future__ import annotations

import numpy as np

from safety.limits.limit import FilterState, Limit

__all__ = ["WorkspaceBoxLimit"]


class WorkspaceBoxLimit(Limit):
    """Keep the tool tip in an axis-aligned box of the base frame (soft, large penalty).

    With the barriers ``b = x - lo`` and ``b = hi - x`` per axis, the linearised step must satisfy
    ``b(q + dq) >= (1 - gamma) b(q)``: it may use only the fraction ``gamma`` of the distance to a face, so
    the tip approaches a face geometrically and a tip outside the box is driven back. Soft, because a tip
    already far outside cannot be brought back within one step's velocity bound; the verifier checks the
    outgoing command against the box.

    Args:
        lower_m: Lower corner (3,) [m].
        upper_m: Upper corner (3,) [m].
        gamma: Barrier rate in (0, 1].
    """

    name = "workspace_box"
    soft = True
    rows = 6

    def __init__(self, lower_m: np.ndarray, upper_m: np.ndarray, gamma: float = 0.5) -> None:
        self.lower_m = np.asarray(lower_m, dtype=float)
        self.upper_m = np.asarray(upper_m, dtype=float)
        self.gamma = float(gamma)
        self._G = np.zeros((6, 6))
        self._h = np.zeros(6)

    def compute_qp_inequalities(self, state: FilterState) -> tuple[np.ndarray, np.ndarray]:
        """Rows ``J dq <= gamma (hi - x)`` and ``-J dq <= gamma (x - lo)``."""
        J = state.tool_jacobian
        x = state.tool_position_m
        G, h = self._G, self._h
        G[:3] = J
        np.negative(J, out=G[3:])
        np.subtract(self.upper_m, x, out=h[:3])
        np.subtract(x, self.lower_m, out=h[3:])
        h *= self.gamma
        return G, h
