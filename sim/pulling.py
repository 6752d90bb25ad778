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
    """Grasp as the scripted expert does, then full-scale motions whose direction flips every step.

    The hardest input for a filter that predicts one step ahead: every step asks for the largest motion
    and reverses the one under way, yaw included, with the jaw kept closed.

    Args:
        env: The environment (wrappers are looked through).
    """

    def __init__(self, env: Any) -> None:
        super().__init__(env)
        self._sign = 1.0

    def reset(self) -> None:
        super().reset()
        self._sign = 1.0

    def __call__(self, observation: dict[str, np.ndarray] | None = None) -> np.ndarray:
        action = super().__call__(observation)
        if self.phase not in ("retract", "hold"):
            return action
        self._sign = -self._sign
        return np.array([self._sign, -self._sign, self._sign, self._sign, -1.0])
