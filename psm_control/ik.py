"""Differential inverse kinematics of the PSM as a small quadratic program.

A Cartesian goal (a tool-tip pose about the RCM) becomes a joint displacement ``dq`` that minimises

    ||J_p dq - e_p||^2 w_p + ||J_o dq - e_o||^2 w_o + damping ||dq||^2

subject to ``lower <= dq <= upper`` (the joint position limits and the largest step allowed over the
look-ahead horizon, given by the caller). ``e_p`` is the position error and ``e_o`` the orientation error
(``log3(R_goal R^T)``), both about the RCM in its axes, where :meth:`PsmConfiguration.local_jacobian`
is expressed. The policy only commands position and yaw, so the goal orientation is the current one
turned about the target frame's z axis, and orientation is weighted well below position: a radian of
orientation error costs as much as ``orientation_weight`` metres of position error.

The problem can be built as a ``qpsolvers.Problem`` (inspectable, and carried by the error when it
fails). Each step is solved exactly by :func:`psm_control.boxqp.solve_box_qp` (the unconstrained
minimiser, or an active set of joints held at their bounds, checked against the KKT conditions); any
problem it does not settle goes to the dual active-set solver DAQP (:class:`psm_control.active_set.ActiveSetQp`,
a workspace kept between ticks), whose answer is exact as well and is checked against the same
conditions before it is used. With ``naive=True`` every step is rebuilt and solved by OSQP through
``qpsolvers`` instead (the benchmark's reference).
"""

from __future__ import annotations

import math
import warnings
from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin

from psm_control.active_set import ActiveSetQp
from psm_control.boxqp import FAILED, solve_box_qp
from psm_control.errors import InfeasibleProblemError
from psm_control.reductions import all_of
from psm_control.robot import PsmConfiguration

if TYPE_CHECKING:  # imported where a problem is built: qpsolvers brings SciPy's sparse matrices and OSQP, a
    # third of a second of every process's start that the chain's own solvers never need
    import qpsolvers

__all__ = ["DifferentialIk", "IkResult"]

_SOLVED = ("solved", "solved inaccurate")  # the second only from OSQP, in the naive reference


class IkResult:
    """One IK step.

    The control chain reads only ``dq`` each tick; the diagnostics are computed when first read.

    Attributes:
        dq: Joint displacement (6,) towards the goal.
        residual: Weighted task-space residual ``||W^(1/2) (J dq - e)||`` of the linearised problem.
        position_error_m: Distance from the current tool tip to the goal [m].
        orientation_error_rad: Angle between the current and goal tool orientations [rad].
    """

    __slots__ = ("_error", "_jacobian", "_sqrt_weights", "dq")

    def __init__(self, dq: np.ndarray, jacobian: np.ndarray, error: np.ndarray, sqrt_weights: np.ndarray) -> None:
        self.dq = dq
        self._jacobian = jacobian
        self._error = error
        self._sqrt_weights = sqrt_weights

    @property
    def residual(self) -> float:
        weighted = self._sqrt_weights * (self._jacobian @ self.dq - self._error)
        return math.sqrt(float(weighted @ weighted))

    @property
    def position_error_m(self) -> float:
        return float(np.linalg.norm(self._error[:3]))

    @property
    def orientation_error_rad(self) -> float:
        return float(np.linalg.norm(self._error[3:]))

    def __repr__(self) -> str:
        return (
            f"IkResult(dq={self.dq}, residual={self.residual:.3g}, position_error_m={self.position_error_m:.3g}, "
            f"orientation_error_rad={self.orientation_error_rad:.3g})"
        )


class DifferentialIk:
    """Damped, weighted, bounded differential IK on the Pinocchio model.

    Args:
        dof: Number of joints (6).
        position_weight: Cost weight of position error [1/m^2].
        orientation_weight: Cost weight of orientation error [1/rad^2]; 0.01 makes 0.1 rad cost like 1 cm.
        damping: Levenberg-Marquardt damping on ``dq``; keeps steps bounded near singularities.
        eps_abs: OSQP absolute tolerance (the naive reference only: the exact solvers need none).
        eps_rel: OSQP relative tolerance (the naive reference only).
        max_iter: Iteration cap of the solver.
        naive: Rebuild the problem and solve it by OSQP through ``qpsolvers`` every call (the reference
            the benchmark compares against) instead of solving it exactly.
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
            "check_termination": 5,
            "scaling": 0,
        }
        self._damping = damping * np.eye(dof)
        self._sqrt_weights = np.sqrt(self.weights)
        self._qp = ActiveSetQp(dof, 0, iteration_limit=max_iter)

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
        import qpsolvers

        J = configuration.local_jacobian()
        P, q = self._cost(J, self.errors(configuration, goal_local))
        return qpsolvers.Problem(P, q, lb=np.asarray(lower, dtype=float), ub=np.asarray(upper, dtype=float))

    def reset(self) -> None:
        """Forget solver state carried between solves (see :meth:`ActiveSetQp.reset`)."""
        self._qp.reset()

    def _cost(self, J: np.ndarray, error: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        JW = J.T * self.weights
        P = JW @ J
        P += self._damping
        return P, -(JW @ error)

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
        J = configuration.local_jacobian()
        error = self.errors(configuration, goal_local)
        JW = J.T * self.weights
        P = JW @ J
        P += self._damping
        b = JW @ error  # the cost's linear term is -b
        lower = np.asarray(lower, dtype=float)
        upper = np.asarray(upper, dtype=float)
        if not all_of(lower <= upper):
            raise InfeasibleProblemError(
                "ik", "lower bound above upper bound", self.problem(configuration, goal_local, lower, upper)
            )
        status = "solved"
        if self.naive:
            import qpsolvers

            settings = self._settings
            # solve_problem is what solve_qp wraps; it also says "solved inaccurate", which the kept
            # workspace accepts too, instead of returning None.
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                solution = qpsolvers.solve_problem(
                    qpsolvers.Problem(P, -b, lb=lower, ub=upper), solver="osqp", **settings
                )
            dq, status = solution.x, str(solution.extras["info"].status)
        else:
            # Solved exactly and directly in the common cases: the unconstrained minimiser within the
            # bounds, or a few joints held at a bound (psm_control.boxqp); DAQP takes any other case.
            dq = np.empty(self.dof)
            if solve_box_qp(P, b, lower, upper, dq) == FAILED:
                exact = self._qp.solve(P, -b, lower, upper)
                dq, status = exact.x, exact.status
        if dq is None or status not in _SOLVED or not all_of(np.isfinite(dq)):
            raise InfeasibleProblemError("ik", status, self.problem(configuration, goal_local, lower, upper))
        return IkResult(np.minimum(np.maximum(dq, lower), upper), J, error, self._sqrt_weights)
