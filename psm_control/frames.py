"""The RCM-to-base transform, applied to points and to Jacobian rows each control tick.

The chain and the verifier both carry tool-tip positions (and the chain the tip's Jacobian) from the
RCM frame into the base frame every tick. In the simulation the base rotation is the identity; a product
with the identity is exact, so skipping it changes nothing and saves a small matrix product per call.
"""

from __future__ import annotations

import numpy as np

__all__ = ["BaseTransform"]


class BaseTransform:
    """``x_base = R x_rcm + t`` for a 4x4 pose of the RCM in the base frame.

    Args:
        transform_rcm_to_base: 4x4 homogeneous transform (already validated by the caller).

    Attributes:
        transform_base_to_rcm: The inverse 4x4 transform, computed once (the chain takes every policy
            step's goal back into the RCM frame with it).
    """

    __slots__ = ("_identity", "rotation", "transform_base_to_rcm", "translation")

    def __init__(self, transform_rcm_to_base: np.ndarray) -> None:
        transform = np.asarray(transform_rcm_to_base, dtype=float)
        self.rotation = transform[:3, :3].copy()
        self.translation = transform[:3, 3].copy()
        self._identity = bool(np.array_equal(self.rotation, np.eye(3)))
        self.transform_base_to_rcm = np.linalg.inv(transform)

    def point(self, point_rcm: np.ndarray) -> np.ndarray:
        """A point (3,) in the base frame (a new array)."""
        return (point_rcm if self._identity else self.rotation @ point_rcm) + self.translation

    def vectors(self, rows_rcm: np.ndarray) -> np.ndarray:
        """Direction vectors or Jacobian rows (3, ...) expressed in the base axes (no translation)."""
        return rows_rcm if self._identity else self.rotation @ rows_rcm
