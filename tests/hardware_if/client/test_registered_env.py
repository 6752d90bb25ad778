"""RegisteredTask: the simulation observed as a robot without perception observes it."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import sim.envs
from hardware_if.client.registered_env import RegisteredTask
from sim.expert import ScriptedExpert

#: A Task I seed the scripted expert grasps and lifts.
SEED = 3


@pytest.fixture
def blind_lift() -> Any:
    env = RegisteredTask(sim.envs.make("lift"), registration_error_m=0.002)
    yield env
    env.close()


def test_the_registered_site_is_the_given_distance_from_the_true_one(blind_lift: Any) -> None:
    """At reset the observed site is the true site moved by exactly the registration error."""
    for seed in range(5):
        observation, info = blind_lift.reset(seed=seed)
        true_site = blind_lift.unwrapped.site_position()
        assert np.linalg.norm(info["registered_site"] - true_site) == pytest.approx(0.002, abs=1e-9)
        assert np.allclose(observation["observation"][8:11], info["registered_site"], atol=1e-6)
        assert np.allclose(observation["desired_goal"], blind_lift.unwrapped.goal, atol=1e-6)


def test_the_jaw_senses_every_grasp_the_simulation_makes(blind_lift: Any) -> None:
    """Along an expert episode the jaw-sensed grasp flag equals the simulation's grasp at every step."""
    expert = ScriptedExpert(blind_lift)
    observation, _ = blind_lift.reset(seed=SEED)
    expert.reset()
    held_steps, agreed = 0, 0
    for _ in range(sim.envs.MAX_EPISODE_STEPS):
        observation, _, _, _, info = blind_lift.step(expert(observation))
        held_steps += int(info["grasped"])
        agreed += int(bool(observation["observation"][17]) == info["grasped"])
        if info["grasped"]:
            assert observation["observation"][7] == pytest.approx(blind_lift.unwrapped.config.grasp.stall_rad)
    assert held_steps >= 10, "the expert held the flap"
    assert agreed == sim.envs.MAX_EPISODE_STEPS


def test_success_is_the_simulation_s_truth(blind_lift: Any) -> None:
    """info['is_success'] is the true site's distance to the goal, not the estimate's."""
    blind_lift.reset(seed=SEED)
    _, _, _, _, info = blind_lift.step(np.zeros(5))
    task = blind_lift.unwrapped
    truth = np.linalg.norm(task.site_position() - task.goal) <= task.config.success_threshold_m
    assert info["is_success"] == truth


def test_for_training_the_reward_sees_the_truth_and_the_policy_the_estimate() -> None:
    """for_training: the registration distance is drawn within the bound, achieved_goal (what a learner
    computes its reward from) is the true site, and the policy's inputs are still the estimate."""
    env = RegisteredTask(sim.envs.make("lift"), registration_error_m=0.003, for_training=True)
    try:
        distances = []
        for seed in range(6):
            observation, info = env.reset(seed=seed)
            task = env.unwrapped
            distances.append(float(np.linalg.norm(info["registered_site"] - task.site_position())))
            assert np.allclose(observation["observation"][8:11], info["registered_site"], atol=1e-6)
            observation, _, _, _, _ = env.step(np.zeros(5))
            assert np.allclose(observation["achieved_goal"], task.site_position(), atol=1e-6)
            assert np.allclose(observation["observation"][8:11], info["registered_site"], atol=1e-6)
        assert all(0.0 <= d <= 0.003 + 1e-12 for d in distances)
        assert len({round(d, 9) for d in distances}) == len(distances), "a new distance every episode"
    finally:
        env.close()


@pytest.mark.parametrize("observed", [True, False])
def test_the_observing_expert_carries_the_observed_site_to_the_goal(observed: bool) -> None:
    """``observed=True`` ends with the registered site on the goal, the privileged expert with the true one.

    The registration is 4 mm off, so whichever site the expert steers, the other ends about that far away.
    """
    env = RegisteredTask(sim.envs.make("lift"), registration_error_m=0.004)
    try:
        expert = ScriptedExpert(env, observed=observed)
        observation, _ = env.reset(seed=SEED)
        expert.reset()
        for _ in range(sim.envs.MAX_EPISODE_STEPS):
            observation, _, _, _, _ = env.step(expert(observation))
        task = env.unwrapped
        seen_m = float(np.linalg.norm(observation["achieved_goal"] - task.goal))
        true_m = float(np.linalg.norm(task.site_position() - task.goal))
    finally:
        env.close()
    steered_m, other_m = (seen_m, true_m) if observed else (true_m, seen_m)
    assert steered_m < 0.0015
    assert other_m > 0.0025
