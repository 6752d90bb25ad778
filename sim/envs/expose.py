"""Beyond the paper: retract the flap until enough of the hidden tissue is in the camera's view."""

from __future__ import annotations

from typing import Any

import numpy as np

from psm_control.errors import ConfigurationError
from sim.envs.base import TissueRetractEnv

__all__ = ["ExposeEnv"]


class ExposeEnv(TissueRetractEnv):
    """Success when the exposed fraction of the hidden tissue reaches the goal fraction.

    The goal is the one-element fraction; the achieved goal is the exposure computed by ray tests
    (:mod:`sim.exposure`), so hindsight relabelling works as for the position tasks.

    Args:
        exposure_target: Fraction of the hidden tissue to expose, in (0, 1].
        **kwargs: As :class:`TissueRetractEnv`.
    """

    goal_size = 1

    def __init__(self, *args: Any, exposure_target: float = 0.5, **kwargs: Any) -> None:
        if not 0 < exposure_target <= 1:
            raise ConfigurationError("exposure_target", exposure_target, "a fraction in (0, 1]")
        self.exposure_target = float(exposure_target)
        super().__init__(*args, **kwargs)

    def _sample_goal(self, rng: np.random.Generator, site_position: np.ndarray) -> np.ndarray:
        return np.array([self.exposure_target])

    def _achieved_goal(self) -> np.ndarray:
        return np.array([self.exposure()])

    def _reached(self, achieved: np.ndarray, desired: np.ndarray) -> np.ndarray:
        return np.asarray(achieved[..., 0] >= desired[..., 0] - 1e-9)
