"""A tiny deterministic goal-reaching task with the tissue tasks' interface, and its scripted expert.

``TissueRetract-ToyReach-v0`` moves a point in a 3-D box towards a goal. It has exactly the spaces and
contract of the TissueRetract goal envs: dict observation (``observation``, ``achieved_goal``,
``desired_goal``), action Box(-1, 1, (5,)) read as (dx, dy, dz, dyaw, jaw), sparse reward 0 / -1,
batch-capable ``compute_reward``, ``info["is_success"]``, 50-step time limit. It runs at tens of
thousands of steps per second, so it measures the learning code's own overhead and makes a quick
smoke test of ``tissue-retract train`` on any machine.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

__all__ = ["TOY_TASK_ID", "ToyReachEnv", "toy_expert"]

#: The registered id of the toy task.
TOY_TASK_ID = "TissueRetract-ToyReach-v0"


class ToyReachEnv(gym.Env[dict[str, Any], np.ndarray]):
    """Move a point to a goal inside a box.

    Args:
        step_size_m: Largest displacement per step and axis [m] (action 1).
        half_extent_m: Half side of the workspace box [m].
        threshold_m: Success distance [m].
    """

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012

    def __init__(self, step_size_m: float = 0.05, half_extent_m: float = 0.3, threshold_m: float = 0.05) -> None:
        self.step_size_m = step_size_m
        self.half_extent_m = half_extent_m
        self.threshold_m = threshold_m
        box = spaces.Box(-half_extent_m, half_extent_m, (3,), dtype=np.float32)
        self.observation_space: spaces.Dict = spaces.Dict(
            {
                "observation": spaces.Box(-np.inf, np.inf, (4,), dtype=np.float32),
                "achieved_goal": box,
                "desired_goal": box,
            }
        )
        self.action_space = spaces.Box(-1.0, 1.0, (5,), dtype=np.float32)
        self._pos = np.zeros(3, dtype=np.float32)
        self._goal = np.zeros(3, dtype=np.float32)
        self._jaw = 1.0

    def _obs(self) -> dict[str, np.ndarray]:
        return {
            "observation": np.append(self._pos, np.float32(self._jaw)).astype(np.float32),
            "achieved_goal": self._pos.copy(),
            "desired_goal": self._goal.copy(),
        }

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        super().reset(seed=seed)
        h = self.half_extent_m
        self._pos = self.np_random.uniform(-h, h, 3).astype(np.float32)
        self._goal = self.np_random.uniform(-h, h, 3).astype(np.float32)
        self._jaw = 1.0
        return self._obs(), {"is_success": self._success()}

    def _success(self) -> bool:
        return bool(np.linalg.norm(self._pos - self._goal) < self.threshold_m)

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        a = np.clip(np.asarray(action, dtype=np.float32), -1.0, 1.0)
        h = self.half_extent_m
        self._pos = np.clip(self._pos + self.step_size_m * a[:3], -h, h).astype(np.float32)
        self._jaw = -1.0 if a[4] < 0 else 1.0
        obs = self._obs()
        info = {"is_success": self._success()}
        reward = float(self.compute_reward(obs["achieved_goal"], obs["desired_goal"], info))
        return obs, reward, False, False, info

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        """0 where the achieved goal is within the threshold of the desired goal, -1 elsewhere (batch-capable)."""
        d = np.linalg.norm(np.asarray(achieved_goal) - np.asarray(desired_goal), axis=-1)
        return -(d >= self.threshold_m).astype(np.float32)


def toy_expert(env: gym.Env[Any, Any], obs: dict[str, np.ndarray]) -> np.ndarray:
    """The scripted expert: head straight for the goal at full speed, jaw closed."""
    base = env.unwrapped
    step = getattr(base, "step_size_m", 0.05)
    delta = (obs["desired_goal"] - obs["achieved_goal"]) / step
    action = np.zeros(5, dtype=np.float32)
    action[:3] = np.clip(delta, -1.0, 1.0)
    action[4] = -1.0
    return action
