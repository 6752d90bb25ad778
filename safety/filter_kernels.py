"""The safety filter's per-tick arithmetic on its small arrays, compiled.

Each tick the filter merges the per-joint bounds of several limits, scales and normalises the other
limits' rows, clips the nominal command and checks it against those rows, and then measures how far the
filtered and the nominal commands are from every limit. On six joints and a few rows that is a few
hundred floating-point operations, but written with NumPy it is dozens of calls whose fixed overhead is
most of the filter's time; compiled with Numba each step is one call. The filter (``safety.filter``)
keeps the logic and the errors; these functions only compute.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = [
    "assess",
    "clip_and_count_violations",
    "merge_bounds",
    "normalise_rows",
    "solver_rows",
    "worst_row_violation",
]

_MIN_ROW_NORM = 1e-9


@numba.njit(cache=True)
def merge_bounds(
    lower_stack: np.ndarray,
    upper_stack: np.ndarray,
    scale: np.ndarray,
    tolerance: float,
    lb: np.ndarray,
    ub: np.ndarray,
) -> bool:
    """The tightest bounds per joint, divided by ``scale``, into ``lb``/``ub``.

    Returns False when a lower bound is above its upper bound by more than ``tolerance`` (or NaN);
    otherwise ``ub`` is raised to ``lb`` where rounding put it below.
    """
    consistent = True
    for j in range(scale.size):
        lo = -np.inf
        hi = np.inf
        for k in range(lower_stack.shape[0]):
            v = lower_stack[k, j]
            if v > lo or np.isnan(v):
                lo = v
            w = upper_stack[k, j]
            if w < hi or np.isnan(w):
                hi = w
        lo /= scale[j]
        hi /= scale[j]
        if not lo <= hi + tolerance:
            consistent = False
        lb[j] = lo
        ub[j] = max(hi, lo)
    return consistent


@numba.njit(cache=True)
def normalise_rows(
    G: np.ndarray, scale: np.ndarray, row_starts: np.ndarray, norm: np.ndarray, row_norm: np.ndarray
) -> None:
    """Scale ``G``'s columns in place; ``norm``: each limit's largest row norm; ``row_norm``: per row.

    Limit ``k`` owns rows ``row_starts[k]`` up to the next start (or the end).
    """
    rows, dof = G.shape
    for k in range(row_starts.size):
        first = row_starts[k]
        last = row_starts[k + 1] if k + 1 < row_starts.size else rows
        largest = 0.0
        for r in range(first, last):
            square = 0.0
            for j in range(dof):
                G[r, j] *= scale[j]
                square += G[r, j] * G[r, j]
            largest = max(largest, square)
        norm[k] = max(np.sqrt(largest), _MIN_ROW_NORM)
        for r in range(first, last):
            row_norm[r] = norm[k]


@numba.njit(cache=True)
def clip_and_count_violations(
    z_nominal: np.ndarray, lb: np.ndarray, ub: np.ndarray, G: np.ndarray, h: np.ndarray, z: np.ndarray
) -> tuple[int, int]:
    """Clip ``z_nominal`` to the bounds into ``z``; return how many rows ``G z <= h`` it violates and the first."""
    for j in range(z.size):
        z[j] = min(max(z_nominal[j], lb[j]), ub[j])
    count = 0
    first = -1
    for r in range(G.shape[0]):
        value = 0.0
        for j in range(z.size):
            value += G[r, j] * z[j]
        if value > h[r]:
            if count == 0:
                first = r
            count += 1
    return count, first


@numba.njit(cache=True)
def _largest_excess(G: np.ndarray, h: np.ndarray, z: np.ndarray, first: int, last: int) -> float:
    largest = -np.inf
    for r in range(first, last):
        value = -h[r]
        for j in range(z.size):
            value += G[r, j] * z[j]
        largest = max(largest, value)
    return largest


@numba.njit(cache=True)
def assess(
    bound_lower: np.ndarray,
    bound_upper: np.ndarray,
    dq: np.ndarray,
    dq_nominal: np.ndarray,
    G: np.ndarray,
    h: np.ndarray,
    z: np.ndarray,
    z_nominal: np.ndarray,
    row_starts: np.ndarray,
    hard_row: np.ndarray,
    bit_values: np.ndarray,
    tolerance: float,
    worst: np.ndarray,
) -> tuple[float, float, int, int]:
    """How far the filtered (``dq``, ``z``) and the nominal commands are beyond each limit.

    ``worst`` (2, limits) gets, for the filtered command (row 0) and the nominal one (row 1), each
    bound limit's largest excess over its bounds (columns first), then each other limit's largest
    ``G z - h``. Returns the filtered command's largest excess over any bound limit and over any hard
    row, and the bit masks (``bit_values`` per column) of the limits active at the filtered command
    (excess >= -tolerance) and violated by the nominal one (excess > tolerance).
    """
    n_bound = bound_lower.shape[0]
    bound_excess = -np.inf
    for k in range(n_bound):
        for row, command in ((0, dq), (1, dq_nominal)):
            largest = -np.inf
            for j in range(command.size):
                largest = max(largest, max(command[j] - bound_upper[k, j], bound_lower[k, j] - command[j]))
            worst[row, k] = largest
        bound_excess = max(bound_excess, worst[0, k])
    hard_excess = -np.inf
    rows = G.shape[0]
    for r in range(rows):
        if hard_row[r]:
            hard_excess = max(hard_excess, _largest_excess(G, h, z, r, r + 1))
    for k in range(row_starts.size):
        first = row_starts[k]
        last = row_starts[k + 1] if k + 1 < row_starts.size else rows
        worst[0, n_bound + k] = _largest_excess(G, h, z, first, last)
        worst[1, n_bound + k] = _largest_excess(G, h, z_nominal, first, last)
    active = 0
    intervened = 0
    for c in range(worst.shape[1]):
        if worst[0, c] >= -tolerance:
            active |= bit_values[c]
        if worst[1, c] > tolerance:
            intervened |= bit_values[c]
    return bound_excess, hard_excess, active, intervened


@numba.njit(cache=True)
def solver_rows(
    G: np.ndarray,
    h: np.ndarray,
    row_norm: np.ndarray,
    lb: np.ndarray,
    ub: np.ndarray,
    infinity: float,
    A: np.ndarray,
    row_upper: np.ndarray,
) -> None:
    """The rows as the solver takes them: ``G / row_norm`` into ``A``'s first columns, ``h / row_norm`` into
    ``row_upper``, or ``infinity`` for a row that no ``z`` within ``lb <= z <= ub`` can violate (the same
    solution with fewer candidates for the active set)."""
    for r in range(G.shape[0]):
        reach = 0.0
        for j in range(G.shape[1]):
            a = G[r, j] / row_norm[r]
            A[r, j] = a
            reach += abs(a) * max(abs(lb[j]), abs(ub[j]))
        offset = h[r] / row_norm[r]
        row_upper[r] = min(offset, infinity) if reach > offset else infinity


@numba.njit(cache=True)
def worst_row_violation(
    G: np.ndarray,
    h: np.ndarray,
    row_norm: np.ndarray,
    row_slack: np.ndarray,
    sigma: np.ndarray,
    z: np.ndarray,
    lb: np.ndarray,
    ub: np.ndarray,
) -> float:
    """The largest violation of a bound or a row by ``z`` and the slack ``sigma``, in normalised units.

    Row ``r`` is ``G[r] z / row_norm[r] - sigma[row_slack[r]] <= h[r] / row_norm[r]`` (no slack where
    ``row_slack[r]`` is negative); the result is <= 0 when every bound and row holds.
    """
    worst = -np.inf
    for j in range(z.size):
        worst = max(worst, lb[j] - z[j], z[j] - ub[j])
    for r in range(G.shape[0]):
        value = -h[r]
        for j in range(z.size):
            value += G[r, j] * z[j]
        value /= row_norm[r]
        if row_slack[r] >= 0:
            value -= sigma[row_slack[r]]
        if not value <= worst:  # also NaN
            worst = value
    return worst


def _compile() -> None:
    """Compile (or load from Numba's cache) for the filter's argument types now, at import, so that no
    control tick ever waits for the compiler."""
    dof, limits, rows = 2, 2, 1
    lower, upper = np.zeros((1, dof)), np.ones((1, dof))
    vector, z = np.zeros(dof), np.zeros(dof)
    G, h = np.ones((rows, dof)), np.ones(rows)
    starts = np.zeros(1, dtype=np.intp)
    merge_bounds(lower, upper, np.ones(dof), 0.0, np.zeros(dof), np.zeros(dof))
    normalise_rows(G, np.ones(dof), starts, np.ones(1), np.ones(rows))
    clip_and_count_violations(vector, vector, np.ones(dof), G, h, z)
    assess(
        lower, upper, vector, vector, G, h, z, vector, starts, np.ones(rows, dtype=np.bool_),
        np.ones(limits, dtype=np.int64), 0.0, np.zeros((2, limits)),
    )  # fmt: skip
    worst_row_violation(G, h, np.ones(rows), np.zeros(rows, dtype=np.intp), np.zeros(1), z, vector, vector)
    solver_rows(G, h, np.ones(rows), vector, vector, 1e30, np.zeros((rows, dof + 1)), np.zeros(rows))


_compile()
