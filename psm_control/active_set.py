"""Small quadratic programs solved exactly by a dual active-set method, and checked against their KKT conditions.

    minimise   1/2 x^T H x + f^T x
    subject to lower <= x <= upper,   row_lower <= A x <= row_upper          (H symmetric positive definite)

The IK's and the safety filter's QPs have six to eight variables and a few dozen rows. An active-set
method ends on a vertex of its working set, where the active rows hold with equality up to rounding
(DAQP, Arnstroem, Bemporad and Axehill, IEEE TAC 67(8), 2022): the answer is the QP's solution, not an
approximation to a tolerance as an ADMM solver's (OSQP stops at its ``eps``, leaving rows violated by
about that much). One DAQP workspace is set up once and only updated, so a solve starts from the active
set of the one before, which changes little from one control tick to the next.

Whatever DAQP returns is checked here before it is used: the bounds and rows met, the multipliers of the
right sign and zero on every row that is not tight, and the gradient of the Lagrangian zero. The check is
compiled with Numba (a few hundred floating-point operations on arrays this small, where NumPy's per-call
overhead would cost more than the arithmetic).
"""

from __future__ import annotations

from typing import NamedTuple

import daqp
import numba
import numpy as np

__all__ = ["ActiveSetQp", "KktResidual", "QpSolution", "kkt_residual"]

#: DAQP's infinity: a bound at or beyond it is no bound.
INFINITY = 1e30
_OPTIMAL = 1  # DAQP_EXIT_OPTIMAL
_STATUS = {
    1: "solved",
    2: "solved with soft constraints",
    -1: "primal infeasible",
    -2: "cycling",
    -3: "unbounded",
    -4: "iteration limit reached",
    -5: "nonconvex",
    -6: "overdetermined initial active set",
    -7: "time limit reached",
}
#: A row is added to DAQP's working set when violated by more than this; the default (1e-6) would leave
#: rows violated by up to that much, as a first-order solver's tolerance does.
_PRIMAL_TOLERANCE = 1e-12


class KktResidual(NamedTuple):
    """How far a point and its multipliers are from meeting a QP's KKT conditions.

    Attributes:
        primal: Largest violation of a bound or row (in the units of ``x`` and of the rows).
        dual: Largest of the Lagrangian's gradient and the complementarity products (a multiplier on a row
            that is not tight, or of the wrong sign), relative to the problem's scale.
    """

    primal: float
    dual: float


class QpSolution(NamedTuple):
    """One solve of :class:`ActiveSetQp`.

    Attributes:
        x: The solution (n,), or None when the solver failed.
        row_multipliers: Multipliers of the rows (m,): positive at ``row_upper``, negative at ``row_lower``.
        status: ``"solved"`` or why not (DAQP's exit, or the KKT check that failed).
        iterations: Active-set iterations of the accepted solve.
        kkt: The residual of the returned point (``inf`` when the solver failed).
    """

    x: np.ndarray | None
    row_multipliers: np.ndarray
    status: str
    iterations: int
    kkt: KktResidual


@numba.njit(cache=True)
def kkt_residual(
    H: np.ndarray,
    f: np.ndarray,
    A: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    row_lower: np.ndarray,
    row_upper: np.ndarray,
    x: np.ndarray,
    multipliers: np.ndarray,
) -> tuple[float, float]:
    """The primal and dual residuals (see :class:`KktResidual`) of ``x`` and ``multipliers``.

    ``multipliers`` holds the bounds' (n) then the rows' (m), positive where the upper side is tight and
    negative where the lower one is; stationarity is ``H x + f + multipliers_bounds + A^T multipliers_rows = 0``.
    """
    n = x.size
    m = A.shape[0]
    primal = 0.0
    scale = 1.0
    for i in range(n):
        scale = max(scale, abs(f[i]), abs(multipliers[i]))
    for r in range(m):
        scale = max(scale, abs(multipliers[n + r]))
    dual = 0.0
    gradient = np.empty(n)
    for i in range(n):
        total = f[i] + multipliers[i]
        for j in range(n):
            total += H[i, j] * x[j]
        gradient[i] = total
    for c in range(n + m):
        if c < n:
            value = x[c]
            low, high = lower[c], upper[c]
        else:
            r = c - n
            value = 0.0
            for j in range(n):
                value += A[r, j] * x[j]
                gradient[j] += A[r, j] * multipliers[c]
            low, high = row_lower[r], row_upper[r]
        excess = max(low - value, value - high)
        if not excess <= primal:  # also NaN
            primal = excess if np.isfinite(excess) else np.inf
        y = multipliers[c]
        if y > 0.0:  # the upper side must be tight
            gap = high - value if high < INFINITY else np.inf
        elif y < 0.0:  # the lower side must be tight
            gap = value - low if low > -INFINITY else np.inf
        else:
            gap = 0.0
        product = abs(y) * max(gap, 0.0) / scale
        if not product <= dual:  # also NaN
            dual = product if np.isfinite(product) else np.inf
    for i in range(n):
        g = abs(gradient[i]) / scale
        if not g <= dual:  # also NaN
            dual = g if np.isfinite(g) else np.inf
    return primal, dual


class ActiveSetQp:
    """A DAQP workspace for QPs of one size, set up on the first solve and then only updated.

    Args:
        n: Number of variables.
        m: Number of rows of ``A`` (0 for bounds only).
        iteration_limit: Largest number of active-set iterations of one solve.
        kkt_tolerance: Largest accepted primal and dual KKT residual of a returned solution.
    """

    def __init__(self, n: int, m: int, *, iteration_limit: int = 4000, kkt_tolerance: float = 1e-9) -> None:
        self.n = n
        self.m = m
        self.iteration_limit = iteration_limit
        self.kkt_tolerance = kkt_tolerance
        self._model: daqp.Model | None = None
        self._no_rows = np.zeros((0, n))
        self._empty = np.zeros(0)
        self._bound_upper = np.empty(n + m)
        self._bound_lower = np.empty(n + m)

    def reset(self) -> None:
        """Drop the workspace: the next solve starts from an empty active set.

        DAQP starts each solve from the previous one's active set; an episode must not depend on the one
        before it (the same seed gives the same result whatever ran earlier).
        """
        self._model = None

    def solve(
        self,
        H: np.ndarray,
        f: np.ndarray,
        lower: np.ndarray,
        upper: np.ndarray,
        A: np.ndarray | None = None,
        row_lower: np.ndarray | None = None,
        row_upper: np.ndarray | None = None,
        *,
        new_H: bool = True,
    ) -> QpSolution:
        """Solve this call's QP; bounds beyond +-1e30 are none.

        Args:
            H: Cost matrix (n, n), symmetric positive definite.
            f: Linear cost (n,).
            lower: Lower bounds on ``x`` (n,).
            upper: Upper bounds on ``x`` (n,).
            A: Rows (m, n), or None when ``m`` is 0.
            row_lower: Lower bounds of the rows (m,).
            row_upper: Upper bounds of the rows (m,).
            new_H: False when ``H`` is the one of the previous solve (its factorisation is kept).

        Returns:
            The solution, checked: ``status`` is ``"solved"`` only when DAQP found an optimum and it meets
            the KKT conditions within ``kkt_tolerance``.
        """
        A = self._no_rows if A is None else A
        row_lower = self._empty if row_lower is None else row_lower
        row_upper = self._empty if row_upper is None else row_upper
        bu, bl = self._bound_upper, self._bound_lower
        n = self.n
        np.minimum(upper, INFINITY, out=bu[:n])
        np.maximum(lower, -INFINITY, out=bl[:n])
        np.minimum(row_upper, INFINITY, out=bu[n:])
        np.maximum(row_lower, -INFINITY, out=bl[n:])
        solution = self._solve_once(H, f, A, new_H)
        if solution[2] < 0 and self._model is not None:
            # A warm start from the previous active set can cycle where a cold one does not.
            self._model = None
            solution = self._solve_once(H, f, A, True)
        x, exitflag, iterations, multipliers = solution
        row_multipliers = multipliers[n:]
        if exitflag != _OPTIMAL or x is None:
            failed = KktResidual(np.inf, np.inf)
            return QpSolution(None, row_multipliers, _STATUS.get(exitflag, f"failed ({exitflag})"), iterations, failed)
        primal, dual = kkt_residual(H, f, A, bl[:n], bu[:n], bl[n:], bu[n:], x, multipliers)
        kkt = KktResidual(primal, dual)
        if not (primal <= self.kkt_tolerance and dual <= self.kkt_tolerance):
            status = f"KKT conditions not met (primal {primal:.3g}, dual {dual:.3g})"
            return QpSolution(None, row_multipliers, status, iterations, kkt)
        return QpSolution(x, row_multipliers, "solved", iterations, kkt)

    def _solve_once(
        self, H: np.ndarray, f: np.ndarray, A: np.ndarray, new_H: bool
    ) -> tuple[np.ndarray | None, int, int, np.ndarray]:
        """One DAQP solve: ``(x, exitflag, iterations, multipliers of the bounds then the rows)``."""
        model = self._model
        if model is None:
            model = daqp.Model()
            model.settings = {"primal_tol": _PRIMAL_TOLERANCE, "iter_limit": self.iteration_limit}
            exitflag, _ = model.setup(H, f, A, self._bound_upper, self._bound_lower)
            if exitflag < 0:
                return None, int(exitflag), 0, np.zeros(self.n + self.m)
            self._model = model
        else:
            exitflag = model.update(
                H=H if new_H else None, f=f, A=A if self.m else None, bupper=self._bound_upper, blower=self._bound_lower
            )
            if exitflag < 0:
                return None, int(exitflag), 0, np.zeros(self.n + self.m)
        x, _, exitflag, info = model.solve()
        return x, int(exitflag), int(info["iterations"]), info["lam"]


# Compile (or load from Numba's cache) now, at import, so that no control tick waits for the compiler.
kkt_residual(
    np.eye(1), np.zeros(1), np.zeros((1, 1)), np.zeros(1), np.ones(1), np.zeros(1), np.ones(1), np.zeros(1), np.zeros(2)
)
