"""Task III: one of the centre, left and right sites, pulled to a sampled target point."""

from __future__ import annotations

import numpy as np

from sim.envs.target import TargetEnv
from sim.tissue import SITE_NAMES

__all__ = ["MultiSiteEnv"]


class MultiSiteEnv(TargetEnv):
    """Like Task II, with the grasp site drawn per episode (the paper's Task III)."""

    def _choose_site(self, rng: np.random.Generator) -> str:
        return str(SITE_NAMES[int(rng.integers(len(SITE_NAMES)))])
