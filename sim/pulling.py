"""An aggressive pulling policy: the expert's grasp, then full-speed pulls far past the goal.

It exists to show the retraction-force limit at work: with the
safety filter on, the chain must keep the peak force near its limit however hard the policy pulls;
with ``--no-safety`` the same pulls stretch the flap until the grip slips. Use it as
``tissue-retract evaluate --policy sim.pulling:AggressivePull``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sim.expert import ScriptedExpert

__all__ = ["AggressivePull", "SignFlipPull"]

# Where the pull heads, past the task's goal: far up and back over the pinned edge [m].
_PULL_PAST_GOAL_M = np.array([0.0, -0.06, 0.10])


class AggressivePull(ScriptedExpert):
    """Grasp as the scripted expert does, then pull at full speed towards a point 12 cm past the goal.

    Args:
        env: The environment (wrappers are looked through).
    """

    def __init__(self, env: Any) -> None:
        super().__init__(env)

    def _retract_target(self, site: np.ndarray) -> np.ndarray:
        return np.asarray(super()._retract_target(site) + _PULL_PAST_GOAL_M)

    def _move(self, delta_m: np.ndarray, jaw: float) -> np.ndarray:
        action = super()._move(delta_m, jaw)
        if self.phase in ("retract", "hold"):
            direction = action[:3] / max(float(np.abs(action[:3]).max()), 1e-9)
            action[:3] = direction  # always a full step: no slowing down near the target
        return action


class SignFlipPull(ScriptedExpert):
    """Grasp as the scripted expert does, then saturate the action and flip its sign every step.

    The direction of each pair of full steps is drawn at random (seeded per episode), so the tool keeps
    reversing at full speed: the adversary for the stopping distance of motion already under way.

    Args:
        env: The environment (wrappers are looked through).
        seed: Seed of the directions (each :meth:`reset` draws the next episode's stream from it).
    """

    def __init__(self, env: Any, seed: int = 0) -> None:
        super().__init__(env)
        self._seeds = np.random.SeedSequence(seed)
        self._rng = np.random.default_rng(self._seeds.spawn(1)[0])
        self._sign = 1.0
        self._direction = np.ones(3)

    def reset(self) -> None:
        """Start a new episode with the next stream of directions."""
        super().reset()
        self._rng = np.random.default_rng(self._seeds.spawn(1)[0])
        self._sign = 1.0

    def _move(self, delta_m: np.ndarray, jaw: float) -> np.ndarray:
        action = super()._move(delta_m, jaw)
        if self.phase in ("retract", "hold"):
            if self._sign > 0:
                self._direction = np.sign(self._rng.standard_normal(3))
            action[:3] = self._sign * self._direction
            self._sign = -self._sign
        return action
