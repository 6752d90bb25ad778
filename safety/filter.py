"""The QP safety filter: the closest safe joint displacement to the nominal one.

    minimise   1/2 ||z - z_nom||^2 + sum_i rho_i (sigma_i + sigma_i^2 / 2),   dq = S z
    subject to lb <= z <= ub,   (G_i S z) / c_i - sigma_i <= h_i / c_i,   sigma >= 0

``S = diag(step)`` measures each joint in units of its largest step, so a radian and a millimetre are
compared by how much of their range they use. The hard limits that bound one joint per row (position,
velocity, insertion, acceleration; ``Limit.joint_bounds``) are merged into one pair of bounds per joint,
the tightest of them, so the solver sees one row per joint instead of one per rule. Every other limit
keeps its own rows; a soft one gets one slack ``sigma_i``. Each such limit's rows are divided by
``c_i``, the largest row norm of ``G_i S`` this tick, so every row and every slack has unit magnitude
whatever its physical unit (metres, newtons): a violation or a tolerance means the same for every row,
the solvers work on well-scaled data, and the penalty ``rho`` needs to exceed only the (bounded)
multiplier of a unit row to be exact.

A nominal command whose clip to the bounds already meets every other row is returned without a solve
(the bounds are a box and the cost is separable, so the clip is optimal). When the clip violates a
row, the projection onto the bounds and the first such row is computed exactly (:mod:`safety.halfspace`)
and kept if it meets every other row and its multiplier is within the row's slack penalty (the KKT
conditions of the whole problem). Every other case, typically a pull against an edge of the force
polytope where two or three of its planes hold at once, is solved by a dual active-set method
(:class:`psm_control.active_set.ActiveSetQp`, DAQP) whose workspace keeps one size and is only updated
each tick; its answer is the QP's solution up to rounding, and it is used only after it meets the KKT
conditions to :data:`KKT_TOLERANCE`. The per-tick arithmetic is in :mod:`safety.filter_kernels`. After a
solve ``z`` is clipped to the bounds and every hard row is re-checked: a violation above the tolerance
raises, never passes. :attr:`SafetyFilter.paths` counts how each tick was solved and the worst row any
answer left violated (``tissue-retract bench chain`` prints them).

With ``naive=True`` the filter is the benchmark's reference instead: every tick the QP is rebuilt and
solved through ``qpsolvers`` by OSQP, with no shortcut and no kept workspace.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from psm_control.active_set import ActiveSetQp
from psm_control.errors import InfeasibleProblemError
from psm_control.reductions import all_of, any_of
from safety.filter_kernels import (
    assess,
    clip_and_count_violations,
    merge_bounds,
    normalise_rows,
    solver_rows,
    worst_row_violation,
)
from safety.halfspace import project_onto_box_and_halfspace
from safety.limits import FilterState, Limit, LimitReport

if TYPE_CHECKING:  # imported where a problem is built: qpsolvers brings SciPy's sparse matrices and OSQP, a
    # third of a second of every process's start that the filter's own solvers never need
    import qpsolvers

__all__ = ["KKT_TOLERANCE", "FilterResult", "SafetyFilter", "SolvePaths"]

_INFINITY = 1e30  # DAQP's and OSQP's infinity: bounds beyond it are infinite
_SOLVED = ("solved", "solved inaccurate")  # the second only from OSQP, in the naive reference
#: Largest KKT residual accepted from the active-set solver: a row (normalised to unit norm, in units of
#: the joints' steps) violated by more than this, or a multiplier that does not balance the cost's
#: gradient to this relative precision, is a failed solve.
KKT_TOLERANCE = 1e-9


class _Reports:
    """What the reports are made of, turned into :class:`LimitReport` objects only when asked for.

    ``worst`` is (2, limits): row 0 the largest ``G dq - h`` per limit at the filtered command, row 1 at
    the nominal one, in the filter's column order; ``order`` maps it to the caller's order of limits.
    """

    __slots__ = ("_names", "_order", "_reports", "_slack", "_tolerance", "_worst")

    def __init__(
        self, names: tuple[str, ...], worst: np.ndarray, order: np.ndarray, tolerance: float, slack: np.ndarray
    ) -> None:
        self._names = names
        self._worst = worst
        self._order = order
        self._tolerance = tolerance
        self._slack = slack
        self._reports: tuple[LimitReport, ...] | None = None

    def build(self) -> tuple[LimitReport, ...]:
        if self._reports is None:
            worst = self._worst[:, self._order]
            self._reports = tuple(
                map(
                    LimitReport,
                    self._names,
                    (worst[0] >= -self._tolerance).tolist(),
                    (worst[1] > self._tolerance).tolist(),
                    np.maximum(worst[1], 0.0).tolist(),
                    self._slack.tolist(),
                )
            )
        return self._reports


class FilterResult(NamedTuple):
    """One tick of the safety filter.

    Attributes:
        dq: The safe displacement (6,).
        solved: Whether a QP was solved (False: the nominal command was already safe).
        change: ``||dq - dq_nom||`` in the filter's normalised joint metric.
        iterations: Iterations of this tick's solver (active-set iterations; OSQP's in the naive reference;
            0 without a solve).
        active_mask: Bit ``i`` set when limit ``i`` (the filter's order) was active at ``dq``.
        intervened_mask: Bit ``i`` set when the nominal command violated limit ``i``.
        interventions: Names of the limits the nominal command violated.
    """

    dq: np.ndarray
    solved: bool
    change: float
    iterations: int
    active_mask: int
    intervened_mask: int
    interventions: tuple[str, ...]
    detail: _Reports

    @property
    def reports(self) -> tuple[LimitReport, ...]:
        """One report per limit, in the filter's order (built on first access)."""
        return self.detail.build()


@dataclass
class SolvePaths:
    """How the filter's ticks were solved since it was made, and the worst row any answer left violated.

    Attributes:
        solver_name: The general QP solver.
        ticks: Ticks filtered.
        clipped: Ticks whose nominal command, clipped to the joint bounds, met every other row (no solve).
        projected: Ticks solved by the exact projection onto the bounds and one row.
        solver: Ticks solved by the general QP solver.
        worst_row_violation: Largest ``a . z - sigma - b`` over every bound and row of every answer, in the
            filter's normalised units (each row of unit norm, each joint in units of its step); <= 0 when
            every row held exactly.
        over_tolerance: Ticks whose answer left a bound or row violated by more than :data:`KKT_TOLERANCE`.
    """

    solver_name: str
    ticks: int = 0
    clipped: int = 0
    projected: int = 0
    solver: int = 0
    worst_row_violation: float = -math.inf
    over_tolerance: int = 0


class SafetyFilter:
    """Project a nominal joint displacement onto the set the limits allow.

    Args:
        limits: The rules, each its own object.
        step_scale: Per-joint normalisation (6,), typically the largest step; ``W = diag(1/step^2)``.
        slack_penalty: ``rho``, the penalty on a soft limit's normalised slack (one unit of slack is a
            violation as large as the limit's largest row moves in one full step).
        eps: OSQP absolute and relative tolerance of the naive reference (of the normalised rows); the
            active-set solver needs none: its answer is exact up to rounding and checked to
            :data:`KKT_TOLERANCE`.
        max_iter: Iteration cap of the solver; a solve that does not finish within it raises.
        hard_tolerance: Largest accepted violation of a hard row after the solve.
        naive: Rebuild the QP and solve it with ``qpsolvers.solve_qp`` every tick, with no shortcut
            (the benchmark's reference).
    """

    def __init__(
        self,
        limits: Sequence[Limit],
        step_scale: np.ndarray,
        *,
        slack_penalty: float = 1e3,
        eps: float = 1e-5,
        max_iter: int = 400,
        hard_tolerance: float = 1e-6,
        naive: bool = False,
    ) -> None:
        self.limits = tuple(limits)
        self.dof = dof = int(np.asarray(step_scale).size)
        self.naive = naive
        self.hard_tolerance = hard_tolerance
        self.slack_penalty = slack_penalty
        self._scale = np.asarray(step_scale, dtype=float)
        self._bound = [i for i, limit in enumerate(self.limits) if limit.joint_bounds and not limit.soft]
        self._rowed = [i for i in range(len(self.limits)) if i not in self._bound]
        self._soft = [i for i in self._rowed if self.limits[i].soft]
        self.n_slack = len(self._soft)
        self.n = dof + self.n_slack
        self._slices: dict[int, slice] = {}
        start = 0
        for i in self._rowed:
            self._slices[i] = slice(start, start + self.limits[i].rows)
            start += self.limits[i].rows
        self.m_rows = start
        #: Rows of every limit together (as before the bound limits were merged); kept for callers.
        self.m_limits = sum(limit.rows for limit in self.limits)
        rows_per_limit = [self.limits[i].rows for i in self._rowed]
        # First row of each limit that keeps rows (none when every limit bounds joints).
        self._row_starts = np.cumsum([0, *rows_per_limit[:-1]]).astype(np.intp)[: len(rows_per_limit)]
        self._row_owner = np.repeat(np.arange(len(self._rowed)), rows_per_limit).astype(np.intp)
        slack_column = {limit: k for k, limit in enumerate(self._soft)}
        self._row_slack = np.array([slack_column.get(self._rowed[int(r)], -1) for r in self._row_owner], dtype=np.intp)
        self._hard_row = self._row_slack < 0
        self._soft_of_rowed = np.array([k for k, i in enumerate(self._rowed) if self.limits[i].soft], dtype=np.intp)
        # Per-tick data: merged bounds of the bound limits, rows of the others (G S, physical h).
        self._bound_lower = np.zeros((len(self._bound), dof))
        self._bound_upper = np.zeros((len(self._bound), dof))
        self._G = np.zeros((self.m_rows, dof))
        self._h = np.zeros(self.m_rows)
        self._lb = np.full(dof, -np.inf)  # z units
        self._ub = np.full(dof, np.inf)
        self._norm = np.ones(len(self._rowed))
        self._row_norm = np.ones(self.m_rows)
        self._penalty = np.array([slack_penalty * self.limits[i].penalty_scale for i in self._soft])
        # The QP in x = [z, sigma]: bounds [lb, 0] <= x <= [ub, inf]; rows (G S / c) z - sigma <= h / c.
        self._P_diag = np.concatenate([np.ones(dof), self._penalty])
        self._H = np.diag(self._P_diag)
        self._f = np.concatenate([np.zeros(dof), self._penalty])
        self._lower = np.concatenate([np.zeros(dof), np.zeros(self.n_slack)])
        self._upper = np.concatenate([np.zeros(dof), np.full(self.n_slack, _INFINITY)])
        self._A = np.zeros((self.m_rows, self.n))
        soft_rows = np.flatnonzero(self._row_slack >= 0)
        self._A[soft_rows, dof + self._row_slack[soft_rows]] = -1.0
        self._row_lower = np.full(self.m_rows, -_INFINITY)
        self._row_upper = np.full(self.m_rows, _INFINITY)
        # A hard row's multiplier may be anything; a soft row's must stay within its slack's penalty.
        self._row_penalty = np.where(self._row_slack >= 0, np.r_[self._penalty, 0.0][self._row_slack], np.inf)
        self._qp = ActiveSetQp(self.n, self.m_rows, iteration_limit=max_iter, kkt_tolerance=KKT_TOLERANCE)
        # OSQP's settings, for the naive reference only.
        self._settings: dict[str, Any] = {
            "eps_abs": eps,
            "eps_rel": eps,
            "max_iter": max_iter,
            "polishing": False,
            "verbose": False,
            "scaling": 0,
            "rho": 1.0,
            "adaptive_rho_interval": 10,
            "check_termination": 5,
        }
        self.paths = SolvePaths(solver_name="OSQP" if naive else "DAQP")
        self._iterations = 0
        self._names = tuple(limit.name for limit in self.limits)
        self._report_order = np.argsort(np.array(self._bound + self._rowed, dtype=np.intp))
        self._no_slack = np.zeros(len(self.limits))
        self._bound_limits = [(k, self.limits[i]) for k, i in enumerate(self._bound)]
        self._row_limits = [(self._slices[i], self.limits[i]) for i in self._rowed]
        self._n_bound = len(self._bound)
        self._report_tolerance = 1e3 * hard_tolerance
        self._rows = np.zeros((self.m_rows, dof))
        # Bit of each column of the (bound limits, then the others) order: limit i is bit i.
        self._bit_values = np.array([1 << i for i in self._bound + self._rowed], dtype=np.int64)
        self._mask_names: dict[int, tuple[str, ...]] = {}
        self._zero_slack = np.zeros(self.n_slack)
        self._zero_slack.flags.writeable = False
        self._no_sigma = np.zeros(self.n_slack)

    def reset(self) -> None:
        """Forget solver state carried between solves, so a new episode starts from the same state."""
        self._qp.reset()

    # -- assembly -----------------------------------------------------------------------------------

    def _stack(self, state: FilterState) -> None:
        lower, upper = self._bound_lower, self._bound_upper
        for k, limit in self._bound_limits:
            lower[k], upper[k] = limit.compute_joint_bounds(state)
        if not merge_bounds(lower, upper, self._scale, self.hard_tolerance, self._lb, self._ub):
            raise InfeasibleProblemError(
                "safety_filter", f"joint bounds conflict: lower {self._lb} above upper {self._ub}"
            )
        if self.m_rows:
            G, h = self._G, self._h
            for rows, limit in self._row_limits:
                G[rows], h[rows] = limit.compute_qp_inequalities(state)
            normalise_rows(G, self._scale, self._row_starts, self._norm, self._row_norm)

    def problem(self, state: FilterState, dq_nominal: np.ndarray) -> qpsolvers.Problem:
        """The filter's QP for this tick as an inspectable ``qpsolvers.Problem`` (merged bounds as lb/ub)."""
        self._stack(state)
        return self._problem(np.asarray(dq_nominal, dtype=float))

    def _problem(self, dq_nominal: np.ndarray) -> qpsolvers.Problem:
        import qpsolvers

        q = self._f.copy()
        q[: self.dof] = -dq_nominal / self._scale
        h = self._h / self._row_norm
        finite = np.isfinite(h)
        G = np.zeros((self.m_rows, self.n))
        G[:, : self.dof] = self._G / self._row_norm[:, None]
        soft = np.flatnonzero(self._row_slack >= 0)
        G[soft, self.dof + self._row_slack[soft]] = -1.0
        lb = np.concatenate([self._lb, np.zeros(self.n_slack)])
        ub = np.concatenate([self._ub, np.full(self.n_slack, np.inf)])
        return qpsolvers.Problem(np.diag(self._P_diag), q, G[finite], h[finite], lb=lb, ub=ub)

    # -- the filter -----------------------------------------------------------------------------------

    def filter(self, state: FilterState, dq_nominal: np.ndarray) -> FilterResult:
        """Return the safe displacement closest to ``dq_nominal``.

        Raises:
            InfeasibleProblemError: The bounds conflict, the solver failed or did not converge, or a hard
                limit is violated beyond the tolerance after the solve; the error carries the QP.
        """
        dq_nominal = np.asarray(dq_nominal, dtype=float)
        self._stack(state)
        z_nominal = dq_nominal / self._scale
        z = np.empty(self.dof)
        violated, first_violated = clip_and_count_violations(z_nominal, self._lb, self._ub, self._G, self._h, z)
        sigma = self._zero_slack
        solved = False
        self._iterations = 0
        projected = None
        if violated and not self.naive:
            # One try: when it fails the active-set solver is exact and costs about as much as two more.
            projected = self._project_one_row(first_violated, z_nominal)
        if projected is not None:
            z = projected
            solved = True
        elif self.naive or violated:
            x, slack, status = self._solve(z_nominal)
            if (
                x is None
                or status not in _SOLVED
                or not all_of(np.isfinite(x))
                or (slack is not self._zero_slack and not all_of(np.isfinite(slack)))
            ):
                raise InfeasibleProblemError("safety_filter", status, self._problem(dq_nominal))
            z = np.minimum(np.maximum(x, self._lb), self._ub)
            if slack is not self._zero_slack:
                sigma = np.maximum(slack, 0.0)
            solved = True
        self._count(projected is not None, solved, z, sigma)
        dq = z * self._scale
        active, intervened, detail = self._reports(dq_nominal, dq, z_nominal, z, sigma)
        change = z - z_nominal
        return FilterResult(
            dq,
            solved,
            math.sqrt(float(change @ change)),
            self._iterations,
            active,
            intervened,
            self._interventions(intervened),
            detail,
        )

    def _count(self, projected: bool, solved: bool, z: np.ndarray, sigma: np.ndarray) -> None:
        paths = self.paths
        paths.ticks += 1
        if projected:
            paths.projected += 1
        elif solved:
            paths.solver += 1
        else:
            paths.clipped += 1
        if sigma is self._zero_slack:
            sigma = self._no_sigma  # the same zeros, writable: one compiled signature for the kernel
        violation = worst_row_violation(self._G, self._h, self._row_norm, self._row_slack, sigma, z, self._lb, self._ub)
        if not violation <= paths.worst_row_violation:
            paths.worst_row_violation = violation
        if not violation <= KKT_TOLERANCE:
            paths.over_tolerance += 1

    def _interventions(self, mask: int) -> tuple[str, ...]:
        names = self._mask_names.get(mask)
        if names is None:
            names = tuple(name for i, name in enumerate(self._names) if mask >> i & 1)
            self._mask_names[mask] = names
        return names

    def _reports(
        self, dq_nominal: np.ndarray, dq: np.ndarray, z_nominal: np.ndarray, z: np.ndarray, sigma: np.ndarray
    ) -> tuple[int, int, _Reports]:
        """Per limit: active at ``dq``, violated by the nominal, and by how much; raise on a hard violation.

        Returns the active and intervened bit masks (limit ``i`` is bit ``i``) and the reports' data.
        """
        worst = np.empty((2, len(self.limits)))
        bound_excess, hard_excess, active, intervened = assess(
            self._bound_lower,
            self._bound_upper,
            dq,
            dq_nominal,
            self._G,
            self._h,
            z,
            z_nominal,
            self._row_starts,
            self._hard_row,
            self._bit_values,
            self._report_tolerance,
            worst,
        )
        if bound_excess > self.hard_tolerance:
            raise InfeasibleProblemError("safety_filter", "a joint bound is violated after the clip")
        if hard_excess > self.hard_tolerance:
            raise InfeasibleProblemError("safety_filter", f"hard limit violated by {hard_excess:.3g} after the solve")
        slack = self._no_slack
        if sigma is not self._zero_slack and sigma.any():
            slack = np.zeros(len(self.limits))
            slack[self._soft] = sigma * self._norm[self._soft_of_rowed]
        return active, intervened, _Reports(self._names, worst, self._report_order, self._report_tolerance, slack)

    # -- solvers ------------------------------------------------------------------------------------

    def _project_one_row(self, row: int, z_nominal: np.ndarray) -> np.ndarray | None:
        """The exact solution when only ``row`` is violated at the clipped nominal, or None for the solver.

        It is the QP's solution if the projection onto the bounds and that one row meets every other row
        and the row's multiplier stays within its slack penalty (so the penalised problem would not
        take slack either): these are the whole problem's KKT conditions. Otherwise the active-set solver
        solves the whole problem.
        """
        norm = self._row_norm[row]
        z = np.empty(self.dof)
        multiplier = project_onto_box_and_halfspace(
            z_nominal, self._G[row] / norm, self._h[row] / norm, self._lb, self._ub, z
        )
        if not multiplier <= self._row_penalty[row]:  # also NaN: infeasible
            return None
        excess = self._G @ z - self._h
        excess[row] = 0.0  # the projected row holds with equality, up to rounding
        return None if any_of(excess > 0.0) else z

    def _solve(self, z_nominal: np.ndarray) -> tuple[np.ndarray | None, np.ndarray, str]:
        """Solve this tick's QP: ``(z, sigma, status)``; ``sigma`` is the shared zero vector without slack."""
        u_rows = self._row_upper
        solver_rows(self._G, self._h, self._row_norm, self._lb, self._ub, _INFINITY, self._A, u_rows)
        if self.naive:
            return self._solve_naive(z_nominal, self._A[:, : self.dof].copy(), u_rows.copy())
        dof = self.dof
        np.negative(z_nominal, out=self._f[:dof])
        self._lower[:dof] = self._lb
        self._upper[:dof] = self._ub
        solution = self._qp.solve(
            self._H, self._f, self._lower, self._upper, self._A, self._row_lower, u_rows, new_H=False
        )
        self._iterations = solution.iterations
        x = solution.x
        if x is None:
            return None, self._zero_slack, solution.status
        sigma = x[dof:]
        return x[:dof], sigma if sigma.any() else self._zero_slack, solution.status

    def _solve_naive(
        self, z_nominal: np.ndarray, rows: np.ndarray, u_rows: np.ndarray
    ) -> tuple[np.ndarray | None, np.ndarray, str]:
        """The reference: without slack first, with it only when that does not settle it, each rebuilt for OSQP."""
        lb = np.maximum(self._lb, -_INFINITY)
        ub = np.minimum(self._ub, _INFINITY)
        # If the rows can all be met and no soft row's multiplier exceeds its penalty, the slack-free
        # solution is exactly the penalised problem's (slack zero), and ADMM converges fast on it.
        x, y_rows, status, iterations = self._stage_naive(False, z_nominal, lb, ub, rows, u_rows)
        self._iterations = iterations
        if status in _SOLVED and x is not None and not any_of(y_rows > self._row_penalty):
            return x, self._zero_slack, status
        x, _, status, iterations = self._stage_naive(True, z_nominal, lb, ub, rows, u_rows)
        self._iterations += iterations
        if x is None:
            return None, self._zero_slack, status
        return x[: self.dof], x[self.dof :], status

    def _stage_naive(
        self, slack: bool, z_nominal: np.ndarray, lb: np.ndarray, ub: np.ndarray, rows: np.ndarray, u_rows: np.ndarray
    ) -> tuple[np.ndarray | None, np.ndarray, str, int]:
        """The same QP rebuilt and solved from scratch through qpsolvers (``solve_qp`` returns only ``x``;
        ``solve_problem``, which it wraps, also gives the multipliers and the solver's status)."""
        import qpsolvers

        live = u_rows < _INFINITY
        n = self.n if slack else self.dof
        G = np.zeros((self.m_rows, n))
        G[:, : self.dof] = rows
        if slack:
            soft = np.flatnonzero(self._row_slack >= 0)
            G[soft, self.dof + self._row_slack[soft]] = -1.0
            P = self._H
            q = np.concatenate([-z_nominal, self._penalty])
            lb = np.concatenate([lb, np.zeros(self.n_slack)])
            ub = np.concatenate([ub, np.full(self.n_slack, np.inf)])
        else:
            P, q = np.eye(self.dof), -z_nominal
        settings = self._settings
        problem = qpsolvers.Problem(
            P, q, G[live] if live.any() else None, u_rows[live] if live.any() else None, lb=lb, ub=ub
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            solution = qpsolvers.solve_problem(problem, solver="osqp", **settings)
        info = solution.extras["info"]
        y_rows = np.zeros(self.m_rows)
        if live.any() and solution.z is not None:
            y_rows[live] = solution.z
        return solution.x, y_rows, str(info.status), int(info.iter)
