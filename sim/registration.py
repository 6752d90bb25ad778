"""The TissueRetract tasks' Gymnasium ids, registered without importing the environments.

``import sim`` registers them; Gymnasium imports an environment's module (and with it PyBullet) only when
``gym.make`` builds one, so a command that stops at its argument checks never loads the physics.
"""

from __future__ import annotations

import gymnasium as gym

from psm_control.errors import UnknownVariantError

__all__ = ["ENTRY_POINTS", "MAX_EPISODE_STEPS", "TASK_IDS", "gym_id", "register"]

#: Episode length of every task (the paper's horizon).
MAX_EPISODE_STEPS = 50

#: Task ids (as the CLI takes them) -> Gymnasium id.
TASK_IDS: dict[str, str] = {
    "lift": "TissueRetract-Lift-v0",
    "target": "TissueRetract-Target-v0",
    "multisite": "TissueRetract-MultiSite-v0",
    "expose": "TissueRetract-Expose-v0",
}
_ALIASES = {"1": "lift", "i": "lift", "2": "target", "ii": "target", "3": "multisite", "iii": "multisite"}

#: Gymnasium id -> the environment class as ``module:Class``.
ENTRY_POINTS: dict[str, str] = {
    "TissueRetract-Lift-v0": "sim.envs.lift:LiftEnv",
    "TissueRetract-Target-v0": "sim.envs.target:TargetEnv",
    "TissueRetract-MultiSite-v0": "sim.envs.multisite:MultiSiteEnv",
    "TissueRetract-Expose-v0": "sim.envs.expose:ExposeEnv",
}


def register() -> None:
    """Register every task with Gymnasium (idempotent)."""
    for env_id, entry_point in ENTRY_POINTS.items():
        if env_id not in gym.registry:
            gym.register(env_id, entry_point=entry_point, max_episode_steps=MAX_EPISODE_STEPS)


def gym_id(task: str) -> str:
    """The Gymnasium id of a task given as a CLI id (``lift``, ``3``, ``III``) or a Gymnasium id."""
    key = task.strip().lower()
    key = _ALIASES.get(key, key)
    if key in TASK_IDS:
        return TASK_IDS[key]
    if task in TASK_IDS.values():
        return task
    raise UnknownVariantError("task", task, [*TASK_IDS, *TASK_IDS.values()])
