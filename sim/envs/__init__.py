"""The TissueRetract environments, one class per task, registered with Gymnasium on ``import sim``."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from psm_control.errors import UnknownVariantError
from sim.envs.base import EnvConfig, TissueRetractEnv
from sim.envs.expose import ExposeEnv
from sim.envs.lift import LiftEnv
from sim.envs.multisite import MultiSiteEnv
from sim.envs.target import TargetEnv
from sim.registration import MAX_EPISODE_STEPS, TASK_IDS, gym_id, register

__all__ = [
    "MAX_EPISODE_STEPS",
    "TASKS",
    "EnvConfig",
    "ExposeEnv",
    "LiftEnv",
    "MultiSiteEnv",
    "TargetEnv",
    "TissueRetractEnv",
    "make",
    "nominal_goal",
    "register",
]

#: Task ids (as the CLI takes them) -> (Gymnasium id, class).
TASKS: dict[str, tuple[str, type[TissueRetractEnv]]] = {
    "lift": (TASK_IDS["lift"], LiftEnv),
    "target": (TASK_IDS["target"], TargetEnv),
    "multisite": (TASK_IDS["multisite"], MultiSiteEnv),
    "expose": (TASK_IDS["expose"], ExposeEnv),
}


def make(task: str, **kwargs: Any) -> Any:
    """``gym.make`` for a task given by any of its names."""
    register()
    return gym.make(gym_id(task), **kwargs)


def nominal_goal(task: str, site_position: np.ndarray) -> np.ndarray:
    """The goal a task sets for a site when none is given: the middle of its goal range [m].

    Raises:
        UnknownVariantError: The task's goal is not a place (``expose``: a fraction of exposed tissue).
    """
    env_id = gym_id(task)
    cls = next(cls for known, cls in TASKS.values() if known == env_id)
    goal = cls.nominal_goal(site_position)
    if goal is None:
        places = [name for name, (_, c) in TASKS.items() if c.nominal_goal(np.zeros(3)) is not None]
        raise UnknownVariantError("task with a goal position", task, places)
    return goal
