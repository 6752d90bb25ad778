"""Closed-form modified-DH forward kinematics, independent of any robotics library.

This is the textbook product of Craig's link transforms, written directly from the DH table. It is
the reference the Pinocchio model is checked against, and a dependency-free FK for users who only
need a pose.
"""

from __future__ import annotations

import math

import numpy as np

from psm_control.spec import PsmSpec

__all__ = ["dh_chain", "dh_tool_pose", "modified_dh_transform"]


def modified_dh_transform(alpha: float, a: float, theta: float, d: float) -> np.ndarray:
    """Return ``RotX(alpha) TransX(a) RotZ(theta) TransZ(d)`` as a 4x4 array."""
    ca, sa = math.cos(alpha), math.sin(alpha)
    ct, st = math.cos(theta), math.sin(theta)
    return np.array(
        [
            [ct, -st, 0.0, a],
            [st * ca, ct * ca, -sa, -sa * d],
            [st * sa, ct * sa, ca, ca * d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def dh_chain(spec: PsmSpec, q: np.ndarray) -> list[np.ndarray]:
    """Return the six joint frames about the RCM, ``T_rcm_i`` for i = 1..6.

    Args:
        spec: The PSM variant.
        q: Joint positions, shape (6,), in dVRK order [rad, rad, m, rad, rad, rad].
    """
    frames = []
    transform = np.eye(4)
    for joint, qi in zip(spec.joints, q, strict=True):
        if joint.kind == "revolute":
            link = modified_dh_transform(joint.alpha, joint.a, qi + joint.offset, joint.d)
        else:
            link = modified_dh_transform(joint.alpha, joint.a, joint.theta, qi + joint.offset)
        transform = transform @ link
        frames.append(transform)
    return frames


def dh_tool_pose(spec: PsmSpec, q: np.ndarray) -> np.ndarray:
    """Return the tool-tip pose about the RCM as the dVRK computes ``local/measured_cp``."""
    return dh_chain(spec, q)[-1] @ spec.tooltip_offset_matrix
