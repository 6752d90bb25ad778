"""Rotation matrix to unit quaternion, as the observation's tool orientation (x, y, z, w).

Eigen's own conversion (Shepperd's method, the branch on the trace and the largest diagonal element), in
NumPy: the same numbers as ``pinocchio.Quaternion(R).coeffs()``, which the observations used before.
Constructing a ``pinocchio.Quaternion`` from a matrix keeps about 80 bytes of native memory per call
(measured: 3.8 MB over 50,000 calls with pinocchio's wheel here), one call per policy step: a sweep's
workers grew by about 4 kB an episode from it alone.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["quaternion_xyzw"]


def quaternion_xyzw(rotation: np.ndarray) -> np.ndarray:
    """The unit quaternion (x, y, z, w) of a 3x3 rotation matrix, with Eigen's choice of sign."""
    m = np.asarray(rotation, dtype=float)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    q = np.empty(4)
    if trace > 0.0:
        t = math.sqrt(trace + 1.0)
        q[3] = 0.5 * t
        t = 0.5 / t
        q[0] = (m[2, 1] - m[1, 2]) * t
        q[1] = (m[0, 2] - m[2, 0]) * t
        q[2] = (m[1, 0] - m[0, 1]) * t
        return q
    i = 0
    if m[1, 1] > m[0, 0]:
        i = 1
    if m[2, 2] > m[i, i]:
        i = 2
    j, k = (i + 1) % 3, (i + 2) % 3
    t = math.sqrt(m[i, i] - m[j, j] - m[k, k] + 1.0)
    q[i] = 0.5 * t
    t = 0.5 / t
    q[3] = (m[k, j] - m[j, k]) * t
    q[j] = (m[j, i] + m[i, j]) * t
    q[k] = (m[k, i] + m[i, k]) * t
    return q
