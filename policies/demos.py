"""Demonstrations: from a ``.npz`` file or from a task's scripted expert.

The ``.npz`` layout read here (one array per key, N episodes of T steps):

* ``obs`` (N, T + 1, obs_dim), ``achieved_goal`` (N, T + 1, goal_dim): the dict observation's entries,
  including the final observation;
* ``desired_goal`` (N, T, goal_dim) or (N, T + 1, goal_dim) or (N, goal_dim);
* ``actions`` (N, T, act_dim) in [-1, 1]; optionally ``terminal`` (N, T).

``observation`` and ``action`` are accepted as aliases of ``obs`` and ``actions``. Files are read with
``allow_pickle=False``: no code in a file is ever run.

The simulation's writer (``tissue-retract demo --task ID --episodes N --out demos.npz``) produces this
layout. Without a file, episodes are generated with the task's scripted expert (:func:`expert_for`):
the toy task's is :func:`policies.toy_env.toy_expert`; the simulation's is ``sim.expert.ScriptedExpert``.
Only successful expert episodes are kept (``info["is_success"]`` and not ``info["sim_unstable"]``).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import gymnasium as gym
import numpy as np

from policies.buffers import Episode
from policies.errors import DemonstrationError
from policies.toy_env import TOY_TASK_ID, toy_expert
from sim.expert import ScriptedExpert

__all__ = ["Controller", "ExpertFactory", "collect_demos", "expert_for", "load_demos", "rollout"]


class Controller(Protocol):
    """A scripted controller for one env: ``reset()`` at each episode start, then ``controller(obs)``."""

    def reset(self) -> None: ...

    def __call__(self, observation: dict[str, np.ndarray]) -> np.ndarray: ...


#: ``factory(env) -> Controller``: how a task's scripted expert is built for an env.
ExpertFactory = Callable[[gym.Env[Any, Any]], Controller]


class _FunctionController:
    """A stateless ``expert(env, obs)`` function as a :class:`Controller`."""

    def __init__(
        self, env: gym.Env[Any, Any], function: Callable[[gym.Env[Any, Any], dict[str, np.ndarray]], np.ndarray]
    ) -> None:
        self.env = env
        self.function = function

    def reset(self) -> None:
        """Nothing to reset."""

    def __call__(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        return self.function(self.env, observation)


def rollout(
    env: gym.Env[Any, Any], act: Callable[[dict[str, np.ndarray]], np.ndarray], seed: int | None
) -> tuple[Episode, bool]:
    """Run one episode with ``act``; returns it and whether it succeeded at its final step."""
    obs, _ = env.reset(seed=seed)
    o, ag, g, a, term = [obs["observation"]], [obs["achieved_goal"]], [], [], []
    success = False
    while True:
        action = np.asarray(act(obs), dtype=np.float32)
        g.append(obs["desired_goal"])
        obs, _, terminated, truncated, info = env.step(action)
        o.append(obs["observation"])
        ag.append(obs["achieved_goal"])
        a.append(action)
        term.append(bool(terminated))
        if terminated or truncated:
            success = bool(info.get("is_success", False)) and not info.get("sim_unstable", False)
            break
    episode = Episode(
        np.asarray(o, np.float32), np.asarray(ag, np.float32), np.asarray(g, np.float32),
        np.asarray(a, np.float32), np.asarray(term, bool),
    )  # fmt: skip
    return episode, success


def expert_for(task_id: str) -> ExpertFactory:
    """The scripted expert of a task, as a factory of controllers.

    Raises:
        DemonstrationError: No expert is known for the task.
    """
    if task_id == TOY_TASK_ID:
        return lambda env: _FunctionController(env, toy_expert)
    if task_id.startswith("TissueRetract-"):
        return ScriptedExpert
    raise DemonstrationError(
        f"no scripted expert is known for {task_id!r}: write demonstrations to a file "
        "(tissue-retract demo --task ID --episodes N --out demos.npz) and pass --demos-file demos.npz"
    )


def collect_demos(
    env: gym.Env[Any, Any], expert: ExpertFactory, count: int, seed: int, max_attempts: int | None = None
) -> list[Episode]:
    """``count`` successful expert episodes (failed ones are discarded), seeded from ``seed``.

    Raises:
        DemonstrationError: The expert did not succeed ``count`` times within ``max_attempts`` episodes.
    """
    attempts = max_attempts if max_attempts is not None else 3 * count + 10
    controller = expert(env)
    episodes: list[Episode] = []
    for i in range(attempts):
        if len(episodes) == count:
            break
        controller.reset()
        episode, success = rollout(env, controller, seed=seed + i)
        if success:
            episodes.append(episode)
    if len(episodes) < count:
        raise DemonstrationError(f"the expert succeeded in only {len(episodes)} of {attempts} episodes")
    return episodes


def load_demos(path: str | Path, count: int | None = None) -> list[Episode]:
    """Read demonstration episodes from a ``.npz`` file (the first ``count`` of them, or all).

    Raises:
        DemonstrationError: The file is missing, holds objects, or lacks a required array.
    """
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except (OSError, ValueError) as e:
        raise DemonstrationError(f"cannot read demonstrations from {path}: {e}") from e

    def pick(*names: str) -> np.ndarray:
        for name in names:
            if name in arrays:
                return np.asarray(arrays[name], dtype=np.float32)
        raise DemonstrationError(f"{path} has no array named {' or '.join(names)} (it has {sorted(arrays)})")

    obs, ag, actions = pick("obs", "observation"), pick("achieved_goal"), pick("actions", "action")
    goal = pick("desired_goal")
    n, T = actions.shape[:2]
    if obs.shape[:2] != (n, T + 1) or ag.shape[:2] != (n, T + 1):
        raise DemonstrationError(f"{path}: obs and achieved_goal must be (N, T + 1, dim) with T = {T} actions")
    if goal.ndim == 2:
        goal = np.repeat(goal[:, None, :], T, axis=1)
    goal = goal[:, :T]
    terminal = np.asarray(arrays.get("terminal", np.zeros((n, T))), dtype=bool)
    take = n if count is None else count
    if take > n:
        raise DemonstrationError(f"{path} holds {n} demonstrations, {take} were asked for")
    return [Episode(obs[i], ag[i], goal[i], actions[i], terminal[i]) for i in range(take)]
