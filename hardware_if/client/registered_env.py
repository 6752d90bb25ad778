"""A simulated task seen as a robot with no perception stack sees it (``evaluate --blind``).

:class:`RegisteredTask` wraps a task environment and replaces what a camera would supply with
:class:`~hardware_if.client.task_estimate.TaskEstimate`: the site an operator registered (the true site plus a
registration error of ``registration_error_m`` in a random direction, drawn per episode from the episode
seed), the goal the operator was given (the episode's true goal, as ``sim-dvrk --blind`` prints it, or
the task's nominal goal about the registered site), and a grasp sensed by a jaw that stalls on the flap
(:meth:`sim.grasp.GraspParams.measured_jaw`). The policy's observation carries these estimates and the
stalled jaw angle; success, forces and every ``info`` entry stay the simulation's truth, so an evaluation
scores the policy by the true distance of the site to the goal.

The scripted expert reads the environment itself, not the observation, and sees the truth: blind
figures are meaningful for policies that act on the observation (checkpoints, ``module:callable``).

For training (``train --blind``) the wrapper draws the registration distance per episode, uniformly up
to ``registration_error_m``, and leaves the observation's ``achieved_goal`` true: a learner recomputes
its reward (and HER its relabelled rewards) from ``achieved_goal`` and ``desired_goal``, so it is
rewarded by where the tissue really is, while everything the policy acts on (the observation vector
and the desired goal) is what the robot would have. The policy can then learn what the estimate gets
wrong in a way it can see (the flap stretching between the jaws and the site) instead of stopping where
the estimate says the goal is.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from hardware_if.client.task_estimate import JawReading, TaskEstimate
from psm_control.errors import ConfigurationError

__all__ = ["GOAL_SOURCES", "RegisteredTask"]

#: Where the goal comes from: the episode's true goal (given to the operator) or the nominal one.
GOAL_SOURCES = ("given", "nominal")

# The layout of the task observation vector (see sim.envs.base): tip (3), quaternion (4), jaw (1),
# site (3), site - tip (3), force (3), grasped (1).
_TIP, _JAW, _SITE, _TO_SITE, _GRASPED = slice(0, 3), 7, slice(8, 11), slice(11, 14), 17


class RegisteredTask(gym.Wrapper):
    """Observations from a registration and the jaw instead of the simulation's ground truth.

    Args:
        env: A position-goal task environment (Tasks I-III).
        registration_error_m: Distance of the registered site from the true site [m].
        goal_source: ``given`` (the true goal) or ``nominal`` (:func:`sim.envs.nominal_goal` about the
            registered site).
        for_training: Draw the registration distance uniformly in ``[0, registration_error_m]`` per
            episode and keep the true ``achieved_goal`` (the reward's input; see the module notes).
    """

    def __init__(
        self,
        env: gym.Env,
        *,
        registration_error_m: float = 0.002,
        goal_source: str = "given",
        for_training: bool = False,
    ) -> None:
        super().__init__(env)
        if not 0 <= registration_error_m <= 0.05:
            raise ConfigurationError("registration_error_m", registration_error_m, "a distance in [0, 0.05] m")
        if goal_source not in GOAL_SOURCES:
            raise ConfigurationError("goal_source", goal_source, f"one of {', '.join(GOAL_SOURCES)}")
        task: Any = env.unwrapped
        nominal_goal = getattr(task, "nominal_goal", None)
        if nominal_goal is None or nominal_goal(np.zeros(3)) is None:
            raise ConfigurationError("task", env.spec.id if env.spec else env, "a task whose goal is a place (I-III)")
        self.registration_error_m = float(registration_error_m)
        self.goal_source = goal_source
        self.for_training = for_training
        self.estimate: TaskEstimate | None = None

    def reset(self, **kwargs: Any) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Reset the task and register its site (with the error) and goal."""
        observation, info = self.env.reset(**kwargs)
        task: Any = self.env.unwrapped
        site = self._register(task, kwargs.get("seed"), info)
        goal = task.goal if self.goal_source == "given" else task.nominal_goal(site)
        self.estimate = TaskEstimate(site, goal)
        info["registered_site"] = site
        return self._estimated(observation), info

    def _register(self, task: Any, seed: int | None, info: dict[str, Any]) -> np.ndarray:
        """The site as registered [m]: the true one, ``registration_error_m`` off in a seeded direction."""
        rng = np.random.default_rng(seed)
        direction = rng.standard_normal(3)
        distance = self.registration_error_m * (rng.uniform() if self.for_training else 1.0)
        return np.asarray(task.site_position() + distance * direction / np.linalg.norm(direction))

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Step the task; the observation carries the estimate, ``info`` the truth."""
        observation, reward, terminated, truncated, info = self.env.step(action)
        return self._estimated(observation), float(reward), terminated, truncated, info

    def _estimated(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        task: Any = self.env.unwrapped
        if self.estimate is None:
            raise RuntimeError("call reset() before step()")
        jaw = task.config.grasp.measured_jaw(task.backend.jaw, task.scene.grasp.holding)
        # The simulated jaw reaches its set-point within a control tick (it is not lagged, see
        # sim.backend) and a stalled one does not move: at the end of a policy step it is still.
        self.estimate.update(JawReading(jaw, 0.0, float(task.backend.jaw)), task.grasp_position())
        vector = np.array(observation["observation"], dtype=float)
        site = self.estimate.site
        vector[_JAW] = jaw
        vector[_SITE] = site
        vector[_TO_SITE] = site - vector[_TIP]
        vector[_GRASPED] = float(self.estimate.grasped)
        achieved = observation["achieved_goal"] if self.for_training else self.estimate.achieved_goal
        return {
            "observation": vector.astype(np.float32),
            "achieved_goal": np.asarray(achieved, dtype=np.float32),
            "desired_goal": self.estimate.goal.astype(np.float32),
        }
