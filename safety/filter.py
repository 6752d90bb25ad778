"""The QP safety filter: the closest safe joint displacement to the nominal one.

    minimise   1/2 ||z - z_nom||^2 + sum_i rho_i (s_i + s_i^2 / 2),   dq = S z
    subject to G_hard S z <= h_hard,   G_soft,i S z - s_i <= h_soft,i,   s >= 0

with one slack ``s_i`` per soft limit and ``S = diag(step)``: each joint is measured in units of its
largest step, so a radian and a millimetre are compared by how much of their range they use (and the
solver sees a well-scaled problem). The problem has a fixed size and sparsity
pattern, so one OSQP workspace is set up once and only ``update()``d each tick (about ten times cheaper
than rebuilding it). A nominal command that already satisfies every row is returned unchanged without a
solve. After a solve the hard rows are checked: a violation above the tolerance raises, never passes.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
import osqp
import qpsolvers
from scipy import sparse

from psm_control.errors import InfeasibleProblemError
from safety.limits import FilterState, Limit, LimitReport

__all__ = ["FilterResult", "SafetyFilter"]

_BIG = 1e30


class FilterResult(NamedTuple):
    """One tick of the safety filter.

    Attributes:
        dq: The safe displacement (6,).
        reports: One report per limit, in the filter's order.
        solved: Whether a QP was solved (False: the nominal command was already safe).
        change: ``||dq - dq_nom||`` in the filter's normalised joint metric.
    """

    dq: np.ndarray
    reports: tuple[LimitReport, ...]
    solved: bool
    change: float

    @property
    def interventions(self) -> tuple[str, ...]:
        """Names of the limits the nominal command violated."""
        return tuple(r.name for r in self.reports if r.intervened)


class SafetyFilter:
    """Project a nominal joint displacement onto the set the limits allow.

    Args:
        limits: The rules, each its own object.
        step_scale: Per-joint normalisation (6,), typically the largest step; ``W = diag(1/step^2)``.
        slack_penalty: ``rho``, the penalty on soft-limit slack.
        eps: OSQP absolute and relative tolerance.
        max_iter: OSQP iteration cap.
        hard_tolerance: Largest accepted violation of a hard row after the solve.
        naive: Rebuild the QP and solve it with ``qpsolvers.solve_qp`` every tick, with no shortcut
            (the benchmark's reference).
    """

    def __init__(
        self,
        limits: Sequence[Limit],
        step_scale: np.ndarray,
        *,
        slack_penalty: float = 1e4,
        eps: float = 1e-6,
        max_iter: int = 400,
        hard_tolerance: float = 1e-6,
        naive: bool = False,
    ) -> None:
        self.limits = tuple(limits)
        self.dof = int(np.asarray(step_scale).size)
        self.naive = naive
        self.hard_tolerance = hard_tolerance
        self.slack_penalty = slack_penalty
        self._scale = np.asarray(step_scale, dtype=float)
        self._weights = np.ones(self.dof)
        self._soft = [limit for limit in self.limits if limit.soft]
        self.n_slack = len(self._soft)
        self.n = self.dof + self.n_slack
        self.m_limits = sum(limit.rows for limit in self.limits)
        self._slices: list[slice] = []
        start = 0
        for limit in self.limits:
            self._slices.append(slice(start, start + limit.rows))
            start += limit.rows
        self._starts = np.array([sl.start for sl in self._slices])
        self._soft_index = np.array([i for i, limit in enumerate(self.limits) if limit.soft], dtype=int)
        self._hard_rows = np.concatenate(
            [np.arange(s.start, s.stop) for s, limit in zip(self._slices, self.limits, strict=True) if not limit.soft]
            or [np.zeros(0, dtype=int)]
        )
        # The full A = [[G, -S], [0, I]]: the dq block dense, the slack block fixed.
        self._A = np.zeros((self.m_limits + self.n_slack, self.n))
        for k, limit in enumerate(self._soft):
            rows = self._slices[self.limits.index(limit)]
            self._A[rows, self.dof + k] = -1.0
        self._A[self.m_limits :, self.dof :] = np.eye(self.n_slack)
        self._h = np.zeros(self.m_limits)
        self._l = np.full(self.m_limits + self.n_slack, -_BIG)
        self._l[self.m_limits :] = 0.0
        self._u = np.full(self.m_limits + self.n_slack, _BIG)
        penalties = np.array([slack_penalty * limit.penalty_scale for limit in self._soft])
        self._P_diag = np.concatenate([self._weights, penalties])
        self._q = np.concatenate([np.zeros(self.dof), penalties])
        # Fixed pattern: every entry of the dq block, and the slack block's nonzeros.
        self._pattern = self._A != 0.0
        self._pattern[: self.m_limits, : self.dof] = True
        self._pattern[self.m_limits :, self.dof :] = np.eye(self.n_slack, dtype=bool)
        self._box_only = True  # refined on the first tick, once the limits have returned their rows
        self._settings: dict[str, Any] = {
            "eps_abs": eps,
            "eps_rel": eps,
            "max_iter": max_iter,
            "polishing": False,
            "verbose": False,
            "warm_starting": True,
        }
        self._solver: osqp.OSQP | None = None
        self._A_csc: sparse.csc_matrix | None = None
        self._pattern_t = self._pattern.T

    def _stack(self, state: FilterState) -> None:
        for limit, rows in zip(self.limits, self._slices, strict=True):
            G, h = limit.compute_qp_inequalities(state)
            self._A[rows, : self.dof] = G * self._scale
            self._h[rows] = h
        hard = self._A[self._hard_rows, : self.dof]
        self._box_only = bool(np.all(np.count_nonzero(hard, axis=1) <= 1))

    def problem(self, state: FilterState, dq_nominal: np.ndarray) -> qpsolvers.Problem:
        """The filter's QP for this tick as an inspectable ``qpsolvers.Problem`` (slack as lower bounds)."""
        self._stack(state)
        return self._problem(dq_nominal)

    def _problem(self, dq_nominal: np.ndarray) -> qpsolvers.Problem:
        q = self._q.copy()
        q[: self.dof] = -dq_nominal / self._scale
        finite = np.isfinite(self._h)
        G = self._A[: self.m_limits][finite]
        h = self._h[finite]
        lb = np.concatenate([np.full(self.dof, -np.inf), np.zeros(self.n_slack)])
        return qpsolvers.Problem(np.diag(self._P_diag), q, G, h, lb=lb)

    def filter(self, state: FilterState, dq_nominal: np.ndarray) -> FilterResult:
        """Return the safe displacement closest to ``dq_nominal``.

        Raises:
            InfeasibleProblemError: The solver failed, or a hard limit is violated beyond the tolerance
                after the solve; the error carries the QP.
        """
        dq_nominal = np.asarray(dq_nominal, dtype=float)
        self._stack(state)
        G = self._A[: self.m_limits, : self.dof]
        z_nominal = dq_nominal / self._scale
        slack = np.zeros(self.n_slack)
        # With only single-joint hard rows the hard set is a box and the cost separable, so the clipped
        # nominal is optimal whenever it also meets the soft rows: no solve needed.
        z_clipped = self._clip_hard(z_nominal.copy())
        if not self.naive and self._box_only and bool(np.all(G @ z_clipped <= self._h)):
            z = z_clipped
            solved = False
        else:
            x, status = self._solve_naive(dq_nominal) if self.naive else self._solve_kept(dq_nominal)
            if x is None or not np.all(np.isfinite(x)):
                raise InfeasibleProblemError("safety_filter", status, self._problem(dq_nominal))
            z, slack = self._clip_hard(x[: self.dof]), np.maximum(x[self.dof :], 0.0)
            solved = True
        dq = z * self._scale
        if self._hard_rows.size:
            violation = float(np.max(G[self._hard_rows] @ z - self._h[self._hard_rows]))
            if violation > self.hard_tolerance:
                raise InfeasibleProblemError(
                    "safety_filter",
                    f"hard limit violated by {violation:.3g} after the solve",
                    self._problem(dq_nominal),
                )
        tolerance = 1e3 * self.hard_tolerance
        with np.errstate(invalid="ignore"):
            nominal_excess = np.nan_to_num(G @ z_nominal - self._h, nan=-np.inf, neginf=-np.inf)
            excess = np.nan_to_num(G @ z - self._h, nan=-np.inf, neginf=-np.inf)
        nominal_worst = np.maximum.reduceat(nominal_excess, self._starts)
        worst = np.maximum.reduceat(excess, self._starts)
        slack_of = np.zeros(len(self.limits))
        slack_of[self._soft_index] = slack
        reports = tuple(
            LimitReport(
                limit.name,
                bool(worst[i] >= -tolerance),
                bool(nominal_worst[i] > tolerance),
                float(max(nominal_worst[i], 0.0)),
                float(slack_of[i]),
            )
            for i, limit in enumerate(self.limits)
        )
        change = float(np.linalg.norm(z - z_nominal))
        return FilterResult(dq, reports, solved, change)

    def _clip_hard(self, z: np.ndarray) -> np.ndarray:
        """Project onto the hard rows that bound one joint each (the solver meets them only to tolerance)."""
        G = self._A[self._hard_rows, : self.dof]
        single = np.count_nonzero(G, axis=1) == 1
        joint = np.argmax(np.abs(G[single]), axis=1)
        coefficient = G[single][np.arange(joint.size), joint]
        bound = self._h[self._hard_rows][single] / coefficient
        upper = np.full(self.dof, np.inf)
        lower = np.full(self.dof, -np.inf)
        np.minimum.at(upper, joint[coefficient > 0], bound[coefficient > 0])
        np.maximum.at(lower, joint[coefficient < 0], bound[coefficient < 0])
        return np.minimum(np.maximum(z, lower), upper)

    def _solve_kept(self, dq_nominal: np.ndarray) -> tuple[np.ndarray | None, str]:
        self._q[: self.dof] = -dq_nominal / self._scale
        self._u[: self.m_limits] = np.minimum(self._h, _BIG)
        Ax = self._A.T[self._pattern_t]
        if self._solver is None:
            rows, cols = np.nonzero(self._pattern)
            A = sparse.csc_matrix((self._A[rows, cols], (rows, cols)), shape=self._A.shape)
            A.sort_indices()
            self._A_csc = A
            P = sparse.diags(self._P_diag, format="csc")
            self._solver = osqp.OSQP()
            self._solver.setup(P, self._q, A, self._l, self._u, **self._settings)
        else:
            self._solver.update(q=self._q, u=self._u, Ax=Ax)
        result = self._solver.solve(raise_error=False)
        status = str(result.info.status)
        if status not in ("solved", "solved inaccurate"):
            return None, status
        return result.x, status

    def _solve_naive(self, dq_nominal: np.ndarray) -> tuple[np.ndarray | None, str]:
        problem = self._problem(dq_nominal)
        x = qpsolvers.solve_qp(
            problem.P, problem.q, problem.G, problem.h, lb=problem.lb, solver="osqp", **self._settings
        )
        return x, "solved" if x is not None else "failed"
