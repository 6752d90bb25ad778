"""Differential inverse kinematics of the PSM as a small quadratic program.

A Cartesian goal (a tool-tip pose about the RCM) becomes a joint displacement ``dq`` that minimises

    ||J_p dq - e_p||^2 w_p + ||J_o dq - e_o||^2 w_o + damping ||dq||^2

subject to ``lower <= dq <= upper`` (the joint position limits and the largest step allowed over the
look-ahead horizon, given by the caller). ``e_p`` is the position error and ``e_o`` the orientation error
(``log3(R_goal R^T)``), both about the RCM in its axes, where :meth:`PsmConfiguration.local_jacobian`
is expressed. The policy only commands position and yaw, so the goal orientation is the current one
turned about the target frame's z axis, and orientation is weighted well below position: a radian of
orientation error costs as much as ``orientation_weight`` metres of position error.

The problem is built as a ``qpsolvers.Problem`` (inspectable, and carried by the error when it fails)
and solved by an OSQP workspace kept between ticks, updated in place each call, unless the unconstrained
minimiser already satisfies the bounds.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import osqp
import pinocchio as pin
import qpsolvers
from scipy import sparse

from psm_control.errors import InfeasibleProblemError
from psm_control.robot import PsmConfiguration

__all__ = ["DifferentialIk", "IkResult"]

_SOLVED = ("solved", "solved inaccurate")


class IkResult(NamedTuple):
    """One IK step.

    Attributes:
        dq: Joint displacement (6,) towards the goal.
        residual: Weighted task-space residual ``||W^(1/2) (J dq - e)||`` of the linearised problem.
        position_error_m: Distance from the current tool tip to the goal [m].
        orientation_error_rad: Angle between the current and goal tool orientations [rad].
    """

    dq: np.ndarray
    residual: float
    position_error_m: float
    orientation_error_rad: float


def _dense_csc(rows: int, cols: int, *, upper: bool = False) -> sparse.csc_matrix:
    """A CSC matrix whose every entry (or upper triangle) is a stored element, so updates keep its pattern."""
    indices: list[int] = []
    indptr = [0]
    for col in range(cols):
        col_rows = range(col + 1) if upper else range(rows)
        indices.extend(col_rows)
        indptr.append(len(indices))
    data = np.zeros(len(indices))
    return sparse.csc_matrix((data, np.array(indices), np.array(indptr)), shape=(rows, cols))


class DifferentialIk:
    """Damped, weighted, bounded differential IK on the Pinocchio model.

    Args:
        dof: Number of joints (6).
        position_weight: Cost weight of position error [1/m^2].
        orientation_weight: Cost weight of orientation error [1/rad^2]; 0.01 makes 0.1 rad cost like 1 cm.
        damping: Levenberg-Marquardt damping on ``dq``; keeps steps bounded near singularities.
        eps_abs: OSQP absolute tolerance.
        eps_rel: OSQP relative tolerance.
        max_iter: OSQP iteration cap.
        naive: Rebuild the problem and solve it through ``qpsolvers.solve_qp`` every call (the reference
            the benchmark compares against) instead of updating the kept OSQP workspace.
    """

    def __init__(
        self,
        dof: int = 6,
        *,
        position_weight: float = 1.0,
        orientation_weight: float = 0.01,
        damping: float = 1e-6,
        eps_abs: float = 1e-7,
        eps_rel: float = 1e-7,
        max_iter: int = 400,
        naive: bool = False,
    ) -> None:
        self.dof = dof
        self.weights = np.array([position_weight] * 3 + [orientation_weight] * 3)
        self.damping = damping
        self.naive = naive
        self._settings: dict[str, Any] = {
            "eps_abs": eps_abs,
            "eps_rel": eps_rel,
            "max_iter": max_iter,
            "polishing": False,
            "verbose": False,
            "warm_starting": True,
        }
        self._P_pattern = _dense_csc(dof, dof, upper=True)
        self._P_upper = np.triu_indices(dof)
        self._P_order = np.lexsort((self._P_upper[0], self._P_upper[1]))
        self._A = sparse.identity(dof, format="csc")
        self._solver: osqp.OSQP | None = None

    def errors(self, configuration: PsmConfiguration, goal_local: np.ndarray) -> np.ndarray:
        """Return ``[e_p, e_o]`` (6,): position [m] and orientation [rad] error about the RCM."""
        pose = configuration.local_pose()
        error = np.empty(6)
        error[:3] = goal_local[:3, 3] - pose[:3, 3]
        error[3:] = pin.log3(goal_local[:3, :3] @ pose[:3, :3].T)
        return error

    def problem(
        self, configuration: PsmConfiguration, goal_local: np.ndarray, lower: np.ndarray, upper: np.ndarray
    ) -> qpsolvers.Problem:
        """Build the QP for one step (``lower <= dq <= upper``), as an inspectable ``qpsolvers.Problem``."""
        P, q, _ = self._cost(configuration, goal_local)
        return qpsolvers.Problem(P, q, lb=np.asarray(lower, dtype=float), ub=np.asarray(upper, dtype=float))

    def _cost(
        self, configuration: PsmConfiguration, goal_local: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        J = configuration.local_jacobian()
        error = self.errors(configuration, goal_local)
        JW = J.T * self.weights
        P = JW @ J + self.damping * np.eye(self.dof)
        q = -JW @ error
        return P, q, error

    def solve(
        self, configuration: PsmConfiguration, goal_local: np.ndarray, lower: np.ndarray, upper: np.ndarray
    ) -> IkResult:
        """Return the joint displacement towards ``goal_local`` within ``[lower, upper]``.

        Args:
            configuration: Robot state to linearise about.
            goal_local: 4x4 goal pose of the tool tip about the RCM.
            lower: Lowest allowed displacement per joint (6,).
            upper: Highest allowed displacement per joint (6,).

        Raises:
            InfeasibleProblemError: The bounds are inconsistent or the solver did not converge; the
                error carries the ``qpsolvers.Problem``.
        """
        P, q, error = self._cost(configuration, goal_local)
        lower = np.asarray(lower, dtype=float)
        upper = np.asarray(upper, dtype=float)
        if not np.all(lower <= upper):
            problem = self.problem(configuration, goal_local, lower, upper)
            raise InfeasibleProblemError("ik", "lower bound above upper bound", problem)
        # A convex QP's unconstrained minimiser is its solution when it satisfies the bounds: the
        # common case of a small step, solved by one 6x6 linear solve instead of an ADMM run.
        dq = None if self.naive else np.linalg.solve(P, -q)
        if dq is not None and np.all(dq >= lower) and np.all(dq <= upper):
            status = "solved"
        elif self.naive:
            dq = qpsolvers.solve_qp(P, q, lb=lower, ub=upper, solver="osqp", **self._settings)
            status = "solved" if dq is not None else "failed"
        else:
            dq, status = self._solve_kept(P, q, lower, upper)
        if dq is None or status not in _SOLVED or not np.all(np.isfinite(dq)):
            raise InfeasibleProblemError("ik", status, self.problem(configuration, goal_local, lower, upper))
        dq = np.clip(dq, lower, upper)
        J = configuration.local_jacobian()
        residual = float(np.linalg.norm(np.sqrt(self.weights) * (J @ dq - error)))
        return IkResult(dq, residual, float(np.linalg.norm(error[:3])), float(np.linalg.norm(error[3:])))

    def _solve_kept(
        self, P: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray
    ) -> tuple[np.ndarray | None, str]:
        Px = P[self._P_upper][self._P_order]
        if self._solver is None:
            P_csc = self._P_pattern.copy()
            P_csc.data[:] = Px
            self._solver = osqp.OSQP()
            self._solver.setup(P_csc, q, self._A, lower, upper, **self._settings)
        else:
            self._solver.update(Px=Px, q=q, l=lower, u=upper)
        result = self._solver.solve(raise_error=False)
        return result.x, str(result.info.status)
