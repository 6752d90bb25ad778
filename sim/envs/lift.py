"""Task I: grasp the centre site and lift it vertically to a height."""

from __future__ import annotations

import numpy as np

from sim.envs.base import TissueRetractEnv

__all__ = ["LiftEnv"]


class LiftEnv(TissueRetractEnv):
    """Centre site lifted straight up by 12-25 mm (the paper's Task I)."""

    lift_range_m = (0.012, 0.025)

    def _sample_goal(self, rng: np.random.Generator, site_position: np.ndarray) -> np.ndarray:
        return site_position + np.array([0.0, 0.0, rng.uniform(*self.lift_range_m)])

    @classmethod
    def nominal_goal(cls, site_position: np.ndarray) -> np.ndarray:
        """The site lifted by the middle of the lift range."""
        return np.asarray(site_position, dtype=float) + np.array([0.0, 0.0, float(np.mean(cls.lift_range_m))])
