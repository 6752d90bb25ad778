"""A sweep's disturbances in training: each episode draws its magnitudes from ``--vary``'s ranges.

A robustness sweep draws each trial's disturbance magnitudes from the sweep's seed and wraps the task in
a :class:`~sim.disturbances.DisturbanceWrapper` of those magnitudes. Training has episodes, not trials,
so :class:`DrawnDisturbanceWrapper` draws them itself at every reset, with the sweep's sampler
(:meth:`sim.sweep.space.ParameterRange.sample`) and the sweep's meaning of each name
(:func:`sim.robustness.disturbances`), from the disturbance wrapper's stream of the episode: the same
seed gives the same magnitudes, directions and noise, and the task's own draws are untouched.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from psm_control.errors import ConfigurationError, UnknownVariantError
from sim.disturbances import DisturbanceWrapper
from sim.robustness import DISTURBANCE_PARAMETERS, disturbances
from sim.sweep.space import ParameterRange

__all__ = ["DrawnDisturbanceWrapper"]


class DrawnDisturbanceWrapper(DisturbanceWrapper):
    """Disturb a goal env's observations and actions by magnitudes drawn anew each episode.

    The magnitudes of the episode are in ``reset``'s info as ``disturbances`` (by name) and in
    :attr:`magnitudes`.

    Args:
        env: A goal env with a dict observation holding ``observation``.
        ranges: One range per disturbance (names of :data:`sim.robustness.DISTURBANCE_PARAMETERS`).

    Raises:
        UnknownVariantError: A name that is no disturbance (the valid ones are listed).
        ConfigurationError: A range that is relative or reaches below 0.
    """

    def __init__(self, env: gym.Env[dict[str, np.ndarray], np.ndarray], ranges: Sequence[ParameterRange]) -> None:
        super().__init__(env)
        for r in ranges:
            if r.name not in DISTURBANCE_PARAMETERS:
                raise UnknownVariantError("disturbance", r.name, tuple(DISTURBANCE_PARAMETERS))
            if r.relative or r.low < 0.0:
                raise ConfigurationError(f"vary.{r.name}", r.describe(), "an absolute range of magnitudes >= 0")
        self.ranges = tuple(ranges)
        self.magnitudes: dict[str, float] = {}

    def _choose_disturbances(self) -> None:
        """Draw this episode's magnitudes, then the disturbances a sweep's trial of them would have."""
        self.magnitudes = {r.name: float(r.sample(self._rng)) for r in self.ranges}
        self.observation_disturbances, self.action_disturbances = disturbances(self.magnitudes)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Reset the env, draw this episode's magnitudes and directions from the seed."""
        obs, info = super().reset(seed=seed, options=options)
        return obs, {**info, "disturbances": dict(self.magnitudes)}
