"""Exact projection onto a box cut by one half-space: the safety filter's most common QP, solved directly.

    minimise 1/2 ||z - p||^2   subject to   lower <= z <= upper,   a . z <= b

Most ticks that need the filter at all have a single violated row (the tissue pulled against the force
limit, or the tip approaching one face of the workspace box). For that case the KKT conditions give the
solution in closed form, ``z(lam) = clip(p - lam a, lower, upper)`` with the row's multiplier ``lam >= 0``
chosen so that ``a . z(lam) = b``. ``a . z(lam)`` is continuous, non-increasing and linear between the
values of ``lam`` where a coordinate leaves or reaches a bound, so ``lam`` is found exactly by walking
those breakpoints in order and solving within the one segment where the row is met. OSQP reaches the
same point only to its tolerance, takes tens to thousands of iterations when the active row changes
between ticks, and costs more per call than this whole function; the filter uses OSQP for everything
this does not cover.
"""

from __future__ import annotations

import numpy as np

__all__ = ["project_onto_box_and_halfspace"]


def project_onto_box_and_halfspace(
    point: np.ndarray, normal: np.ndarray, offset: float, lower: np.ndarray, upper: np.ndarray
) -> tuple[np.ndarray, float] | None:
    """The point of ``{lower <= z <= upper, normal . z <= offset}`` closest to ``point``, and the row's multiplier.

    Args:
        point: The point to project (n,).
        normal: The half-space's normal (n,).
        offset: Its offset ``b``.
        lower: Lower bounds (n,), ``-inf`` allowed.
        upper: Upper bounds (n,), ``inf`` allowed, ``upper >= lower``.

    Returns:
        ``(z, lam)``, or None when no point of the box meets the half-space (or an input is NaN).
    """
    z = np.minimum(np.maximum(point, lower), upper)
    value = float(normal @ z)
    if value <= offset:
        return z, 0.0
    if not value > offset:  # NaN
        return None
    # Walk lam upwards through the events where a coordinate starts or stops moving (leaves or reaches
    # a bound); between events a . z(lam) falls with slope -sum(a_j^2) over the moving coordinates. The
    # slope is summed afresh from the moving set at every event, so rounding cannot leave a stopped
    # coordinate's share behind. A handful of coordinates: plain floats are several times quicker
    # than NumPy's small-array calls here.
    squares: dict[int, float] = {}
    moving: set[int] = set()
    events: list[tuple[float, int, bool]] = []  # (lam, coordinate, starts moving)
    for j, (p, a, lo, hi) in enumerate(
        zip(point.tolist(), normal.tolist(), lower.tolist(), upper.tolist(), strict=True)
    ):
        if a == 0.0:
            continue
        start, stop = ((p - hi) / a, (p - lo) / a) if a > 0.0 else ((p - lo) / a, (p - hi) / a)
        if not stop > 0.0:
            continue  # already at the bound it moves towards (or NaN): it never moves
        squares[j] = a * a
        if start > 0.0:
            events.append((start, j, True))
        else:
            moving.add(j)
        events.append((stop, j, False))
    events.sort()
    slope = -sum(squares[j] for j in moving)
    lam = 0.0
    for at, j, starts in events:
        if slope < 0.0:
            reached = value + slope * (at - lam)
            if reached <= offset:
                break
            value = reached
        lam = at
        if starts:
            moving.add(j)
        else:
            moving.discard(j)
        slope = -sum(squares[k] for k in moving)
    if not slope < 0.0:
        return None  # every coordinate is at its bound and the row is still violated: infeasible
    multiplier = lam + (value - offset) / -slope
    return np.minimum(np.maximum(point - multiplier * normal, lower), upper), multiplier
