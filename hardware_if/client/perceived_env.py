"""A simulated task seen through the endoscope (``--perception camera``).

:class:`PerceivedTask` is :class:`~hardware_if.client.registered_env.RegisteredTask` with the site registered by
the camera instead of an operator: at each reset it renders the endoscope's stereo pair of the flap at
rest (with the arm at its start pose in view) under a randomized appearance drawn from the episode seed,
and the site estimator's estimate of the episode's site becomes the registered site. From there the
episode runs as a robot without task topics runs it: the jaw-sensed grasp, the site and achieved goal
moving with the jaws once grasped, the goal given. ``info["site_error_mm"]`` is the estimate's distance
to the true site; success and every other ``info`` entry stay the simulation's truth.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym
import numpy as np

from hardware_if.client.registered_env import RegisteredTask
from sim.endoscope import Appearance
from sim.tissue import SITE_NAMES

__all__ = ["PerceivedTask", "camera_task"]

#: Mixed into the episode seed for the frame's appearance, so that it is its own stream.
_APPEARANCE_STREAM = 36


class PerceivedTask(RegisteredTask):
    """Observations whose site comes from the site estimator on the endoscope's images.

    Args:
        env: A position-goal task environment (Tasks I-III) whose endoscope is the estimator's.
        estimator: A :class:`policies.perception.SiteEstimator` (``estimate(frame)`` of the sites).
        for_training: Keep the true ``achieved_goal`` (the reward's input, see ``RegisteredTask``).

    The environment is given the estimator's endoscope, and inked sites if the estimator was trained on them.
    """

    #: Tells :func:`policies.shipped.variant_of` that the observation's site is the camera's.
    site_from_camera = True

    def __init__(self, env: gym.Env, estimator: Any, *, for_training: bool = False) -> None:
        super().__init__(env, registration_error_m=0.0, goal_source="given", for_training=for_training)
        task: Any = env.unwrapped
        # Read at each reset and render only: the next episode is built with them.
        tissue = dataclasses.replace(
            task.config.tissue, mark_sites=task.config.tissue.mark_sites or estimator.mark_sites
        )
        task.config = dataclasses.replace(task.config, endoscope=estimator.endoscope, tissue=tissue)
        self.estimator = estimator

    def _register(self, task: Any, seed: int | None, info: dict[str, Any]) -> np.ndarray:
        """The estimator's site from one stereo pair; its error to the truth goes to ``info``."""
        rng = np.random.default_rng(None if seed is None else [int(seed), _APPEARANCE_STREAM])
        frame = task.render_endoscope(Appearance.sample(rng, task.config.endoscope), rng)
        site = np.asarray(self.estimator.world_sites(frame, task.site)[SITE_NAMES.index(task.site)])
        info["site_error_mm"] = float(1000.0 * np.linalg.norm(site - task.site_position()))
        taken = getattr(self.estimator, "last_taken", "")
        if taken:  # the default estimator chose one of the two shipped ones for this flap
            info["site_estimator"] = taken
        return site


def camera_task(env: gym.Env, model: str | None = None, *, for_training: bool = False) -> PerceivedTask:
    """``env`` seen through the endoscope by the estimator ``model`` names (None: the shipped default, which
    chooses between the two shipped ones, :mod:`policies.perception.chooser`); picklable."""
    from policies.perception import load_site_estimator  # torch's network: only where the camera is used

    return PerceivedTask(env, load_site_estimator(model), for_training=for_training)
