"""The abstract safety limit: one rule, as linear inequality rows on the joint displacement.

In the manner of pink/mink's ``Limit.compute_qp_inequalities``: each rule looks at the current
:class:`FilterState` and returns ``(G, h)`` such that a safe joint displacement ``dq`` over the tick's
horizon satisfies ``G @ dq <= h``. Every limit returns the same number of rows every tick (unused rows are
``0 <= +inf``), so the safety filter can keep one solver workspace with a fixed sparsity pattern.
"""

from __future__ import annotations

import abc
from typing import NamedTuple

import numpy as np

__all__ = ["FilterState", "Limit", "LimitReport"]

#: Right-hand side of an unused row.
INACTIVE = np.inf


class FilterState(NamedTuple):
    """What the limits need to know about the robot at one tick.

    Attributes:
        q: Commanded joint positions (6,) the step starts from.
        qd: Commanded joint velocities (6,).
        tool_position_m: Tool-tip position in the base frame (3,) [m].
        tool_jacobian: Linear Jacobian of the tool tip in the base axes (3, 6).
        grasp_jacobian: Linear Jacobian of the grasp point (midway along the jaws: where held tissue moves)
            in the base axes (3, 6). The wrist can swing it while the tip stays put.
        retraction_force_n: Force the tool applies to the tissue (3,), base axes [N].
        stiffness_n_per_m: Current tissue stiffness estimate along the force direction [N/m].
        dt: Control period [s].
        jaw_rad: The jaw's opening [rad], the smaller of commanded and measured (closed: it may hold tissue).
        force_margin_n: How far the true force may exceed ``retraction_force_n`` [N] (the sensing's error,
            or the held load where the force is bounded from the grasp point's travel): the force limit
            keeps this much below its limit.
        tissue_held: The jaws may hold tissue whatever the jaw and the force say (with an inexact force
            sensor, until an opened jaw has surely let go: :class:`safety.force_bound.ForceBound`).
    """

    q: np.ndarray
    qd: np.ndarray
    tool_position_m: np.ndarray
    tool_jacobian: np.ndarray
    grasp_jacobian: np.ndarray
    retraction_force_n: np.ndarray
    stiffness_n_per_m: float
    dt: float
    jaw_rad: float = 0.0
    force_margin_n: float = 0.0
    tissue_held: bool = False


class LimitReport(NamedTuple):
    """How one limit affected one tick.

    Attributes:
        name: The limit's name.
        active: A row holds with equality (within tolerance) at the filtered command.
        intervened: The nominal command violated the limit, so the filter had to change it.
        nominal_violation: Largest ``G dq_nominal - h`` (> 0 when the nominal was unsafe).
        slack: Slack used by a soft limit (0 for hard limits, or when satisfied).
    """

    name: str
    active: bool
    intervened: bool
    nominal_violation: float
    slack: float = 0.0


class Limit(abc.ABC):
    """One safety rule of the filter.

    Attributes:
        name: Short name used in logs and reports.
        soft: Soft limits get a slack variable with a large penalty; hard limits must hold after the solve.
        rows: Number of inequality rows this limit always returns.
        penalty_scale: Multiplies the filter's slack penalty for a soft limit (its priority).
        joint_bounds: Every row involves one joint at most (``G`` rows are multiples of unit vectors), so
            the filter may merge the rows into per-joint bounds instead of giving each its own row.
    """

    name: str = "limit"
    soft: bool = False
    rows: int = 0
    penalty_scale: float = 1.0
    joint_bounds: bool = False

    @abc.abstractmethod
    def compute_qp_inequalities(self, state: FilterState) -> tuple[np.ndarray, np.ndarray]:
        """Return ``(G, h)`` with ``G`` of shape (rows, 6) and ``h`` of shape (rows,)."""

    def compute_joint_bounds(self, state: FilterState) -> tuple[np.ndarray, np.ndarray]:
        """Return per-joint ``(lower, upper)`` on ``dq`` that say the same as the rows (``joint_bounds`` only).

        The filter merges these into one pair of bounds per joint. This generic form derives them from
        :meth:`compute_qp_inequalities`; subclasses override it with the direct formula (tested equal).

        Raises:
            ValueError: A row involves more than one joint, or a row ``0 <= h`` has ``h < 0``.
        """
        G, h = self.compute_qp_inequalities(state)
        if np.any(np.count_nonzero(G, axis=1) > 1):
            raise ValueError(f"{self.name}: a row involves more than one joint")
        if np.any(h[~np.any(G != 0.0, axis=1)] < 0.0):
            raise ValueError(f"{self.name}: a row 0 <= h has h < 0 (no displacement meets it)")
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = h[:, None] / G
        upper = np.min(np.where(G > 0.0, ratio, np.inf), axis=0, initial=np.inf)
        lower = np.max(np.where(G < 0.0, ratio, -np.inf), axis=0, initial=-np.inf)
        return lower, upper

    def report(
        self, G: np.ndarray, h: np.ndarray, dq_nominal: np.ndarray, dq: np.ndarray, tolerance: float, slack: float = 0.0
    ) -> LimitReport:
        """Say whether this limit was active at ``dq`` and whether the nominal command violated it."""
        finite = np.isfinite(h)
        if not np.any(finite):
            return LimitReport(self.name, False, False, 0.0, slack)
        violation = float(np.max(G[finite] @ dq_nominal - h[finite]))
        margin = float(np.max(G[finite] @ dq - h[finite]))
        return LimitReport(self.name, margin >= -tolerance, violation > tolerance, max(violation, 0.0), slack)
