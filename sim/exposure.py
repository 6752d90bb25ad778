"""How much of the hidden tissue the camera sees, without rendering.

Sample points on the hidden tissue's top face are joined to the camera's eye; a point is exposed when
no triangle of the flap's current mesh crosses that segment (a Moller-Trumbore test). The
instrument is not counted as an occluder: it is thin and moves, and exposure is a property of the
retraction. ``tests/sim/test_exposure.py`` checks the estimate against the segmentation render.
"""

from __future__ import annotations

import numba
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
    mask = np.empty(len(points), dtype=np.bool_)
    _exposed(
        np.ascontiguousarray(points, dtype=np.float64),
        np.ascontiguousarray(eye, dtype=np.float64),
        np.ascontiguousarray(nodes, dtype=np.float64),
        np.ascontiguousarray(triangles, dtype=np.int64),
        mask,
    )
    return mask


# Compiled, and a point's search ends at the first triangle it meets: every env step asks for the exposure
# (64 points x 72 triangles), and the vectorised NumPy form of the same test cost about a tenth of the step.
@numba.njit(cache=True)
def _exposed(points: np.ndarray, eye: np.ndarray, nodes: np.ndarray, triangles: np.ndarray, mask: np.ndarray) -> None:
    for p in range(points.shape[0]):
        dx, dy, dz = eye[0] - points[p, 0], eye[1] - points[p, 1], eye[2] - points[p, 2]  # t in (0, 1)
        hit = False
        for k in range(triangles.shape[0]):
            a, b, c = triangles[k, 0], triangles[k, 1], triangles[k, 2]
            ax, ay, az = nodes[a, 0], nodes[a, 1], nodes[a, 2]
            e1x, e1y, e1z = nodes[b, 0] - ax, nodes[b, 1] - ay, nodes[b, 2] - az
            e2x, e2y, e2z = nodes[c, 0] - ax, nodes[c, 1] - ay, nodes[c, 2] - az
            px, py, pz = dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x  # d x e2
            det = e1x * px + e1y * py + e1z * pz
            if abs(det) < 1e-12:  # parallel (a NaN node falls through and fails every test below)
                continue
            inverse = 1.0 / det
            tx, ty, tz = points[p, 0] - ax, points[p, 1] - ay, points[p, 2] - az
            u = (tx * px + ty * py + tz * pz) * inverse
            if not u >= 0:
                continue
            qx, qy, qz = ty * e1z - tz * e1y, tz * e1x - tx * e1z, tx * e1y - ty * e1x  # (point - a) x e1
            v = (dx * qx + dy * qy + dz * qz) * inverse
            if not (v >= 0 and u + v <= 1):
                continue
            t = (e2x * qx + e2y * qy + e2z * qz) * inverse
            if t > 1e-6 and t < 1:
                hit = True
                break
        mask[p] = not hit


def exposed_fraction(points: np.ndarray, eye: np.ndarray, nodes: np.ndarray, triangles: np.ndarray) -> float:
    """Fraction of the sample points the camera sees past the flap."""
    mask = exposed_mask(points, eye, nodes, triangles)
    return np.count_nonzero(mask) / mask.size  # exactly the mean, in 0.3 us instead of mask.mean()'s 3 (measured)


# Compile (or load from Numba's cache) now, at import, so that no env step waits for the compiler.
exposed_mask(np.zeros((1, 3)), np.ones(3), np.eye(3), np.array([[0, 1, 2]]))
