"""Exact projection onto a box cut by one half-space: the safety filter's most common QP, solved directly.

    minimise 1/2 ||z - p||^2   subject to   lower <= z <= upper,   a . z <= b

Most ticks that need the filter at all have a single violated row (the tissue pulled against the force
limit, or the tip approaching one face of the workspace box). For that case the KKT conditions give the
solution in closed form, ``z(lam) = clip(p - lam a, lower, upper)`` with the row's multiplier ``lam >= 0``
chosen so that ``a . z(lam) = b``. ``a . z(lam)`` is continuous, non-increasing and linear between the
values of ``lam`` where a coordinate leaves or reaches a bound, so ``lam`` is found exactly by walking
those breakpoints in order and solving within the one segment where the row is met. A call into a
general QP solver costs more than this whole function (compiled with Numba: a few dozen floating-point
operations, where NumPy's per-call overhead would dominate); the filter uses the active-set solver
(:mod:`psm_control.active_set`) for everything this does not cover.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["project_onto_box_and_halfspace"]


@numba.njit(cache=True)
def project_onto_box_and_halfspace(
    point: np.ndarray, normal: np.ndarray, offset: float, lower: np.ndarray, upper: np.ndarray, z: np.ndarray
) -> float:
    """Write into ``z`` the point of ``{lower <= z <= upper, normal . z <= offset}`` closest to ``point``.

    Args:
        point: The point to project (n,).
        normal: The half-space's normal (n,).
        offset: Its offset ``b``.
        lower: Lower bounds (n,), ``-inf`` allowed.
        upper: Upper bounds (n,), ``inf`` allowed, ``upper >= lower``.
        z: Output (n,).

    Returns:
        The row's multiplier ``lam >= 0``, or NaN when no point of the box meets the half-space (or an
        input is NaN); ``z`` is then meaningless.
    """
    n = point.size
    value = 0.0
    for j in range(n):
        z[j] = min(max(point[j], lower[j]), upper[j])
        value += normal[j] * z[j]
    if value <= offset:
        return 0.0
    if not value > offset:  # NaN
        return np.nan
    # Walk lam upwards through the events where a coordinate starts or stops moving (leaves or reaches
    # a bound); between events a . z(lam) falls with slope -sum(a_j^2) over the moving coordinates. The
    # slope is summed afresh from the moving set at every event, so rounding cannot leave a stopped
    # coordinate's share behind.
    at = np.empty(2 * n)
    coordinate = np.empty(2 * n, dtype=np.int64)
    starts = np.empty(2 * n, dtype=np.bool_)
    moving = np.zeros(n, dtype=np.bool_)
    count = 0
    for j in range(n):
        a = normal[j]
        if a == 0.0:
            continue
        if a > 0.0:
            start, stop = (point[j] - upper[j]) / a, (point[j] - lower[j]) / a
        else:
            start, stop = (point[j] - lower[j]) / a, (point[j] - upper[j]) / a
        if not stop > 0.0:
            continue  # already at the bound it moves towards (or NaN): it never moves
        if start > 0.0:
            at[count], coordinate[count], starts[count] = start, j, True
            count += 1
        else:
            moving[j] = True
        at[count], coordinate[count], starts[count] = stop, j, False
        count += 1
    order = np.argsort(at[:count], kind="mergesort")
    slope = 0.0
    for j in range(n):
        if moving[j]:
            slope -= normal[j] * normal[j]
    lam = 0.0
    for e in order:
        if slope < 0.0:
            reached = value + slope * (at[e] - lam)
            if reached <= offset:
                break
            value = reached
        lam = at[e]
        moving[coordinate[e]] = starts[e]
        slope = 0.0
        for j in range(n):
            if moving[j]:
                slope -= normal[j] * normal[j]
    if not slope < 0.0:
        return np.nan  # every coordinate is at its bound and the row is still violated: infeasible
    multiplier = lam + (value - offset) / -slope
    for j in range(n):
        z[j] = min(max(point[j] - multiplier * normal[j], lower[j]), upper[j])
    return multiplier


# Compile (or load from Numba's cache) now, at import, so that no control tick waits for the compiler.
project_onto_box_and_halfspace(np.zeros(2), np.ones(2), 0.0, -np.ones(2), np.ones(2), np.zeros(2))
