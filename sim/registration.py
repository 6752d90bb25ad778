"""The TissueRetract tasks' Gymnasium ids, registered without importing the environments.

``import sim`` registers them; Gymnasium imports an environment's module (and with it PyBullet) only when
``gym.make`` builds one, so a command that stops at its argument checks never loads the physics.
"""

from __future__ import annotations

import gymnasium as gym

__all__ = ["ENTRY_POINTS", "MAX_EPISODE_STEPS", "register"]

#: Episode length of every task (the paper's horizon).
MAX_EPISODE_STEPS = 50

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
