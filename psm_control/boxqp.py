"""Exact solution of a small strictly convex quadratic program over a box: the IK's QP, compiled.

    minimise 1/2 x^T P x - b^T x   subject to   lower <= x <= upper      (P symmetric positive definite)

The IK's unconstrained minimiser ``P^-1 b`` leaves its bounds when a joint is near a limit or the step is
capped; then usually one or two coordinates sit at a bound and the others solve a smaller linear system.
The split is found with the primal-dual active-set method (Hintermueller, Ito and Kunisch, SIAM J. Optim.
13(3), 2002): a coordinate is held at a bound when a Newton step on it alone, ``x_i - g_i / P_ii``, would
cross that bound; the free ones solve their reduced system; repeat until the split stops changing. An
answer is accepted only when it meets the KKT conditions (free coordinates within their bounds, the
gradient pointing out of the box at every held one), so it is the QP's solution up to rounding. The
method is not guaranteed to settle for every ``P``; after a few rounds it gives up and the caller uses
a general solver (DAQP, :mod:`psm_control.active_set`). For six variables the whole solve is a few
hundred floating-point operations, less than the cost of one call into a general-purpose QP solver, so
it is written out here and compiled with Numba (a LAPACK call per reduced system would cost more than
its arithmetic).
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["BOUNDED", "FAILED", "UNCONSTRAINED", "solve_box_qp"]

#: Outcomes of :func:`solve_box_qp`.
UNCONSTRAINED = 0  # the unconstrained minimiser is within the bounds
BOUNDED = 1  # solved with some coordinates held at a bound
FAILED = 2  # not settled, not positive definite or not finite: use another solver

_MAX_ROUNDS = 12
_KKT_TOLERANCE = 1e-12  # relative to the gradient's scale; exact up to rounding otherwise


@numba.njit(cache=True)
def _solve_reduced(P: np.ndarray, b: np.ndarray, free: np.ndarray, x: np.ndarray) -> bool:
    """Set ``x[free]`` to solve ``P_FF x_F = b_F - P_FH x_H`` (Cholesky); False if not positive definite."""
    n = x.size
    index = np.flatnonzero(free)
    k = index.size
    L = np.zeros((k, k))
    rhs = np.empty(k)
    for a in range(k):
        i = index[a]
        total = b[i]
        for j in range(n):
            if not free[j]:
                total -= P[i, j] * x[j]
        rhs[a] = total
    for a in range(k):
        for c in range(a + 1):
            total = P[index[a], index[c]]
            for d in range(c):
                total -= L[a, d] * L[c, d]
            if a == c:
                if not total > 0.0:
                    return False
                L[a, a] = np.sqrt(total)
            else:
                L[a, c] = total / L[c, c]
    for a in range(k):  # forward substitution
        total = rhs[a]
        for d in range(a):
            total -= L[a, d] * rhs[d]
        rhs[a] = total / L[a, a]
    for a in range(k - 1, -1, -1):  # back substitution
        total = rhs[a]
        for d in range(a + 1, k):
            total -= L[d, a] * rhs[d]
        rhs[a] = total / L[a, a]
    for a in range(k):
        x[index[a]] = rhs[a]
    return True


@numba.njit(cache=True)
def solve_box_qp(P: np.ndarray, b: np.ndarray, lower: np.ndarray, upper: np.ndarray, x: np.ndarray) -> int:
    """Minimise ``1/2 x^T P x - b^T x`` over ``lower <= x <= upper`` into ``x``.

    Args:
        P: Symmetric positive definite cost matrix (n, n).
        b: Linear term (n,); the cost's linear part is ``-b``.
        lower: Lower bounds (n,), ``-inf`` allowed, ``lower <= upper``.
        upper: Upper bounds (n,), ``inf`` allowed.
        x: Output (n,).

    Returns:
        :data:`UNCONSTRAINED`, :data:`BOUNDED`, or :data:`FAILED` (``x`` is then meaningless).
    """
    n = b.size
    for i in range(n):
        if not np.isfinite(b[i]):
            return FAILED
        for j in range(n):
            if not np.isfinite(P[i, j]):
                return FAILED
    free = np.ones(n, dtype=np.bool_)
    at_upper = np.zeros(n, dtype=np.bool_)
    if not _solve_reduced(P, b, free, x):
        return FAILED
    inside = True
    for i in range(n):
        if not (x[i] >= lower[i] and x[i] <= upper[i]):
            inside = False
    if inside:
        return UNCONSTRAINED
    for i in range(n):
        if not np.isfinite(x[i]):
            return FAILED
    gradient = np.zeros(n)
    scale = 0.0
    for i in range(n):
        scale = max(scale, abs(b[i]))
    settled = False
    for _ in range(_MAX_ROUNDS):
        # The split: hold a coordinate where a Newton step on it alone would leave the box.
        changed = False
        for i in range(n):
            trial = x[i] - gradient[i] / P[i, i]
            hold_low = trial < lower[i]
            hold_high = trial > upper[i]
            now_free = not (hold_low or hold_high)
            if now_free != free[i] or hold_high != at_upper[i]:
                changed = True
            free[i] = now_free
            at_upper[i] = hold_high
        if not changed:
            settled = True
            break
        for i in range(n):
            if not free[i]:
                x[i] = upper[i] if at_upper[i] else lower[i]
        if not _solve_reduced(P, b, free, x):
            return FAILED
        for i in range(n):
            if free[i]:
                gradient[i] = 0.0
            else:
                total = -b[i]
                for j in range(n):
                    total += P[i, j] * x[j]
                gradient[i] = total
                scale = max(scale, abs(total))
    if not settled:
        return FAILED
    # KKT: free coordinates within bounds, the gradient pointing out of the box where one is held.
    tolerance = _KKT_TOLERANCE * scale
    for i in range(n):
        if not np.isfinite(x[i]):
            return FAILED
        if free[i]:
            if x[i] < lower[i] or x[i] > upper[i]:
                return FAILED
        elif at_upper[i]:
            if gradient[i] > tolerance:
                return FAILED
        elif gradient[i] < -tolerance:
            return FAILED
    return BOUNDED


# Compile (or load from Numba's cache) now, at import, so that no control tick waits for the compiler.
solve_box_qp(np.eye(2), np.ones(2), np.zeros(2), np.ones(2), np.zeros(2))
