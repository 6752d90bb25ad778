"""Task II: grasp the centre site and pull it to a sampled target point."""

from __future__ import annotations

import numpy as np

from sim.envs.base import TissueRetractEnv

__all__ = ["TargetEnv"]

#: Target offsets from the site (x sideways, y back towards the pinned edge, z up) [m].
TARGET_LOW_M = np.array([-0.008, -0.015, 0.012])
TARGET_HIGH_M = np.array([0.008, 0.0, 0.025])


class TargetEnv(TissueRetractEnv):
    """Centre site to a target drawn uniformly in a box up and back from it (the paper's Task II)."""

    def _sample_goal(self, rng: np.random.Generator, site_position: np.ndarray) -> np.ndarray:
        return site_position + rng.uniform(TARGET_LOW_M, TARGET_HIGH_M)

    @classmethod
    def nominal_goal(cls, site_position: np.ndarray) -> np.ndarray:
        """The site moved to the middle of the target box."""
        return np.asarray(site_position, dtype=float) + 0.5 * (TARGET_LOW_M + TARGET_HIGH_M)
