"""Episode replay with hindsight goal relabelling (HER, ``future`` strategy), for agent and demonstrations.

Whole episodes are stored, so a transition's future is known when it is sampled. With probability
``her_probability`` (0.8 for k = 4) a sampled transition's goal is replaced by the achieved goal of a
uniformly chosen later step of the same episode: the goal reached after step t' for t' in [t, T - 1],
inclusive of the transition itself, exactly the semantics of Stable-Baselines3's ``HerReplayBuffer``
(``GoalSelectionStrategy.FUTURE``) and of the HER reference code. Rewards are recomputed with the
environment's batch ``compute_reward`` so that relabelled transitions are scored by the task itself.

The demonstration buffer is the same class, filled once from demonstration episodes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

__all__ = ["Batch", "Episode", "EpisodeBuffer", "RewardFn"]

#: ``compute_reward(achieved_goal, desired_goal, info)`` of a Gymnasium goal env, batch-capable.
RewardFn = Callable[[np.ndarray, np.ndarray, Any], np.ndarray]


class Episode(NamedTuple):
    """One episode of T steps.

    Attributes:
        obs: Observations, shape (T + 1, obs_dim); row T is the final observation.
        achieved_goal: Achieved goals, shape (T + 1, goal_dim).
        desired_goal: The goal in force at each step, shape (T, goal_dim).
        action: Actions in [-1, 1], shape (T, act_dim).
        terminal: Whether step t ended the episode for a reason other than the time limit, shape (T,).
    """

    obs: np.ndarray
    achieved_goal: np.ndarray
    desired_goal: np.ndarray
    action: np.ndarray
    terminal: np.ndarray


class Batch(NamedTuple):
    """Sampled transitions (raw, not normalised), each field with leading batch axis."""

    obs: np.ndarray
    goal: np.ndarray
    action: np.ndarray
    reward: np.ndarray
    next_obs: np.ndarray
    next_action: np.ndarray
    done: np.ndarray


class EpisodeBuffer:
    """A ring buffer of whole episodes with HER ``future`` sampling.

    Args:
        capacity: Capacity in transitions (rounded down to whole episodes of ``horizon`` steps).
        horizon: Longest episode [steps]; shorter episodes are stored with their length.
        obs_dim: Observation size.
        goal_dim: Goal size.
        act_dim: Action size.
    """

    def __init__(self, capacity: int, horizon: int, obs_dim: int, goal_dim: int, act_dim: int) -> None:
        self.horizon = horizon
        self.max_episodes = max(1, capacity // horizon)
        n, T = self.max_episodes, horizon
        self.obs = np.zeros((n, T + 1, obs_dim), dtype=np.float32)
        self.achieved_goal = np.zeros((n, T + 1, goal_dim), dtype=np.float32)
        self.desired_goal = np.zeros((n, T, goal_dim), dtype=np.float32)
        self.action = np.zeros((n, T, act_dim), dtype=np.float32)
        self.terminal = np.zeros((n, T), dtype=bool)
        self.length = np.zeros(n, dtype=np.int64)
        self.next_slot = 0
        self.size = 0

    def __len__(self) -> int:
        """Number of stored episodes."""
        return self.size

    @property
    def transitions(self) -> int:
        """Number of stored transitions."""
        return int(self.length[: self.size].sum())

    def add(self, episode: Episode) -> None:
        """Store an episode, overwriting the oldest when full."""
        steps = len(episode.action)
        if not 1 <= steps <= self.horizon:
            raise ValueError(f"episode of {steps} steps does not fit a buffer of horizon {self.horizon}")
        i = self.next_slot
        self.obs[i, : steps + 1] = episode.obs
        self.achieved_goal[i, : steps + 1] = episode.achieved_goal
        self.desired_goal[i, :steps] = episode.desired_goal
        self.action[i, :steps] = episode.action
        self.terminal[i, :steps] = episode.terminal
        self.length[i] = steps
        self.next_slot = (i + 1) % self.max_episodes
        self.size = min(self.size + 1, self.max_episodes)

    def sample(
        self,
        count: int,
        rng: np.random.Generator,
        reward_fn: RewardFn,
        her_probability: float,
        reward_override: float | None = None,
    ) -> Batch:
        """Sample ``count`` transitions uniformly, relabelling goals with the ``future`` strategy.

        Args:
            count: Number of transitions.
            rng: Source of randomness.
            reward_fn: The env's batch ``compute_reward``.
            her_probability: Probability that a transition's goal is relabelled.
            reward_override: If given, every reward is this constant (SQIL) and ``reward_fn`` is not called.
        """
        if self.size == 0:
            raise ValueError("cannot sample from an empty buffer")
        episode = rng.integers(0, self.size, size=count)
        length = self.length[episode]
        t = np.minimum((rng.random(count) * length).astype(np.int64), length - 1)
        goal = self.desired_goal[episode, t]
        relabel = rng.random(count) < her_probability
        if relabel.any():
            # Index t' + 1 of the achieved goals, t' uniform in [t, length - 1].
            future = t + 1 + (rng.random(count) * (length - t)).astype(np.int64)
            future = np.minimum(future, length)
            goal = np.where(relabel[:, None], self.achieved_goal[episode, future], goal)
        next_achieved = self.achieved_goal[episode, t + 1]
        if reward_override is None:
            reward = np.asarray(reward_fn(next_achieved, goal, {}), dtype=np.float32).reshape(count)
        else:
            reward = np.full(count, reward_override, dtype=np.float32)
        next_t = np.minimum(t + 1, length - 1)
        return Batch(
            obs=self.obs[episode, t],
            goal=goal,
            action=self.action[episode, t],
            reward=reward,
            next_obs=self.obs[episode, t + 1],
            next_action=self.action[episode, next_t],
            done=self.terminal[episode, t].astype(np.float32),
        )

    def episodes(self) -> list[Episode]:
        """Every stored episode (oldest first is not guaranteed)."""
        out = []
        for i in range(self.size):
            n = int(self.length[i])
            out.append(
                Episode(
                    self.obs[i, : n + 1],
                    self.achieved_goal[i, : n + 1],
                    self.desired_goal[i, :n],
                    self.action[i, :n],
                    self.terminal[i, :n],
                )
            )
        return out

    def state(self) -> dict[str, np.ndarray]:
        """The stored data as arrays (for resumable checkpoints)."""
        n = self.size
        return {
            "obs": self.obs[:n],
            "achieved_goal": self.achieved_goal[:n],
            "desired_goal": self.desired_goal[:n],
            "action": self.action[:n],
            "terminal": self.terminal[:n].astype(np.uint8),
            "length": self.length[:n],
            "cursor": np.array([self.next_slot, self.size], dtype=np.int64),
        }

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore data saved by :meth:`state`."""
        next_slot, size = (int(v) for v in state["cursor"])
        if size > self.max_episodes or state["obs"].shape[1:] != self.obs.shape[1:]:
            raise ValueError("saved replay data does not fit this buffer's capacity or shapes")
        self.obs[:size] = state["obs"]
        self.achieved_goal[:size] = state["achieved_goal"]
        self.desired_goal[:size] = state["desired_goal"]
        self.action[:size] = state["action"]
        self.terminal[:size] = state["terminal"].astype(bool)
        self.length[:size] = state["length"]
        self.next_slot, self.size = next_slot, size
