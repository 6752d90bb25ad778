"""The tasks' Gymnasium registration, which ``import sim`` does without loading PyBullet."""

from __future__ import annotations

import subprocess
import sys

import gymnasium as gym

from sim.envs import TASKS
from sim.registration import ENTRY_POINTS, MAX_EPISODE_STEPS


def test_every_task_is_registered_at_its_class() -> None:
    """The light table names exactly the environment classes that sim.envs.TASKS holds."""
    assert {env_id: f"{cls.__module__}:{cls.__name__}" for env_id, cls in TASKS.values()} == ENTRY_POINTS
    for env_id in ENTRY_POINTS:
        assert gym.spec(env_id).max_episode_steps == MAX_EPISODE_STEPS


def test_import_sim_registers_the_tasks_without_pybullet() -> None:
    """A fresh ``import sim`` registers every task and leaves PyBullet unloaded."""
    probe = (
        "import sys, gymnasium as gym, sim\n"
        "print(all(i in gym.registry for i in sys.argv[1:]), 'pybullet' in sys.modules)"
    )
    done = subprocess.run([sys.executable, "-c", probe, *ENTRY_POINTS], capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["True", "False"]
