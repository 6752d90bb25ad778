"""How much of the hidden tissue the camera sees, without rendering.

Sample points on the hidden tissue's top face are joined to the camera's eye; a point is exposed when
no triangle of the flap's current mesh crosses that segment (a vectorised Moller-Trumbore test). The
instrument is not counted as an occluder: it is thin and moves, and exposure is a property of the
retraction. ``tests/sim/test_exposure.py`` checks the estimate against the segmentation render.
"""

from __future__ import annotations

import numpy as np

__all__ = ["exposed_fraction", "exposed_mask", "surface_samples"]


def surface_samples(centre: np.ndarray, half_extents: np.ndarray, count_per_side: int = 8) -> np.ndarray:
    """A grid of points (count^2, 3) on the top face of a box, inset by half a cell [m]."""
    u = (np.arange(count_per_side) + 0.5) / count_per_side * 2.0 - 1.0
    gx, gy = np.meshgrid(u * half_extents[0], u * half_extents[1])
    top = centre[2] + half_extents[2] + 1e-4
    return np.stack([centre[0] + gx.ravel(), centre[1] + gy.ravel(), np.full(gx.size, top)], axis=1)


def exposed_mask(points: np.ndarray, eye: np.ndarray, nodes: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Boolean (P,): True where the segment from a point to the eye crosses no triangle."""
    a, b, c = (nodes[triangles[:, k]] for k in range(3))
    e1, e2 = b - a, c - a  # (T, 3)
    direction = eye[None, :] - points  # (P, 3), segment parameter t in (0, 1)
    pvec = np.cross(direction[:, None, :], e2[None, :, :])  # (P, T, 3)
    det = np.einsum("tk,ptk->pt", e1, pvec)
    safe = np.where(np.abs(det) < 1e-12, np.nan, det)
    tvec = points[:, None, :] - a[None, :, :]
    u = np.einsum("ptk,ptk->pt", tvec, pvec) / safe
    qvec = np.cross(tvec, e1[None, :, :])
    v = np.einsum("pk,ptk->pt", direction, qvec) / safe
    t = np.einsum("tk,ptk->pt", e2, qvec) / safe
    with np.errstate(invalid="ignore"):
        hit = (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-6) & (t < 1)
    return np.asarray(~hit.any(axis=1))


def exposed_fraction(points: np.ndarray, eye: np.ndarray, nodes: np.ndarray, triangles: np.ndarray) -> float:
    """Fraction of the sample points the camera sees past the flap."""
    return float(exposed_mask(points, eye, nodes, triangles).mean())
