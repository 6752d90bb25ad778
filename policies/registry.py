"""The tasks Gymnasium knows: a task named by its id or short name, registered on first use.

Its own module so that both the trainer and the collectors' worker processes (which start with an empty
registry) can use it without importing each other.
"""

from __future__ import annotations

import contextlib
import importlib

import gymnasium as gym

from psm_control.errors import UnknownVariantError

__all__ = ["ensure_registered"]


def ensure_registered(task_id: str) -> str:
    """Make a task known to Gymnasium, importing the simulation package only when needed.

    Returns:
        The Gymnasium id: ``task_id`` itself, or the simulation's id for a short name (``lift``, ``III``).

    Raises:
        UnknownVariantError: No such task after importing ``sim``.
    """
    importlib.import_module("policies")
    if task_id in gym.registry:
        return task_id
    with contextlib.suppress(ImportError):
        sim_envs = importlib.import_module("sim.registration")  # the ids, without the environments
        if task_id not in gym.registry:
            with contextlib.suppress(UnknownVariantError):
                return str(sim_envs.gym_id(task_id))
    if task_id not in gym.registry:
        known = sorted(k for k in gym.registry if k.startswith("TissueRetract-"))
        raise UnknownVariantError("task", task_id, known)
    return task_id
