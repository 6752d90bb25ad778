"""Learning algorithms and shipped policies for tissue retraction.

Importing the package registers the toy task ``TissueRetract-ToyReach-v0`` (see :mod:`policies.toy_env`).
The algorithms live in :mod:`policies.algos`, training in :mod:`policies.trainer`, checkpoints and the
deployable policy in :mod:`policies.checkpoint` (:func:`policies.checkpoint.load_policy`).
"""

from __future__ import annotations

import gymnasium as gym

from policies.config import ALGORITHMS, TrainConfig
from policies.toy_env import TOY_TASK_ID

__all__ = ["ALGORITHMS", "TOY_TASK_ID", "TrainConfig"]

if TOY_TASK_ID not in gym.registry:
    gym.register(id=TOY_TASK_ID, entry_point="policies.toy_env:ToyReachEnv", max_episode_steps=50)
