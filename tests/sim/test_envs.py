"""The Gymnasium contract of the TissueRetract environments."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pybullet as p
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from psm_control.errors import UnknownVariantError
from sim.envs import TASKS, gym_id
from tests.sim.conftest import make_env


def test_ids_registered_on_import() -> None:
    """Importing sim registers the four ids with a 50-step TimeLimit."""
    import sim  # noqa: F401

    for env_id, _ in TASKS.values():
        assert gym.spec(env_id).max_episode_steps == 50


def test_checkers_pass(task: str) -> None:
    """Gymnasium's and Stable-Baselines3's environment checkers pass on every id."""
    env = make_env(task)
    try:
        check_env(env.unwrapped, skip_render_check=True)
        sb3_check_env(env.unwrapped, warn=False)
    finally:
        env.close()


def test_compute_reward_is_batched(env: gym.Env) -> None:
    """compute_reward maps a batch of goals to a batch of 0/-1 rewards that agrees with step()."""
    obs, _ = env.reset(seed=3)
    achieved = np.repeat(obs["achieved_goal"][None], 4, axis=0)
    desired = achieved.copy()
    desired[1:, 2] += np.array([0.004, 0.006, 0.1])
    rewards = env.unwrapped.compute_reward(achieved, desired, [{}] * 4)
    assert rewards.shape == (4,)
    assert rewards.tolist() == [0.0, 0.0, -1.0, -1.0]
    obs, reward, *_ = env.step(env.action_space.sample())
    assert reward == env.unwrapped.compute_reward(obs["achieved_goal"], obs["desired_goal"], {})


def test_same_seed_same_episode() -> None:
    """Two resets with the same seed and the same actions give identical observations."""
    runs = []
    for _ in range(2):
        env = make_env("multisite")
        env.action_space.seed(5)
        obs, info = env.reset(seed=11)
        trace = [obs["observation"]]
        for _ in range(8):
            obs, *_ = env.step(env.action_space.sample())
            trace.append(obs["observation"])
        runs.append((np.array(trace), info["randomization"]))
        env.close()
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    assert runs[0][1] == runs[1][1]


def test_bad_actions_never_reach_physics(env: gym.Env) -> None:
    """NaN/inf actions are replaced by a hold and flagged; out-of-box actions are clipped and flagged."""
    env.reset(seed=0)
    tip = env.unwrapped.grasp_position()
    _, _, _, truncated, info = env.step(np.array([np.nan, np.inf, 0.0, 0.0, 1.0], dtype=np.float32))
    assert info["invalid_action"] and not truncated
    np.testing.assert_allclose(env.unwrapped.grasp_position(), tip, atol=1e-6)
    _, _, _, _, info = env.step(np.array([5.0, 0.0, 0.0, 0.0, 1.0], dtype=np.float32))
    assert info["action_clipped"] and not info["invalid_action"]
    assert np.all(np.isfinite(env.unwrapped.scene.tissue.positions()))


def test_unknown_options_list_the_valid_ones(env: gym.Env) -> None:
    """Unknown reset options and task ids raise errors that name the valid choices."""
    with pytest.raises(UnknownVariantError, match="tissue_youngs_modulus_kpa"):
        env.reset(seed=0, options={"stifness": 3.0})
    with pytest.raises(UnknownVariantError, match="multisite"):
        gym_id("task4")


def test_options_fix_parameters(env: gym.Env) -> None:
    """reset(options=...) fixes a randomization parameter, the site and the goal."""
    goal = np.array([0.0, 0.03, 0.05])
    _, info = env.reset(seed=1, options={"tissue_youngs_modulus_kpa": 12.5, "site": "left", "goal": goal})
    assert info["randomization"]["tissue_youngs_modulus_kpa"] == 12.5
    assert info["site"] == "left"
    np.testing.assert_allclose(env.unwrapped.goal, goal)


def test_unstable_simulation_truncates(env: gym.Env, monkeypatch: pytest.MonkeyPatch) -> None:
    """Non-finite or exploding tissue nodes end the episode with truncated=True and sim_unstable."""
    env.reset(seed=0)
    tissue = env.unwrapped.scene.tissue
    real = tissue.positions
    monkeypatch.setattr(tissue, "positions", lambda: real() * np.nan)
    obs, _, terminated, truncated, info = env.step(env.action_space.sample())
    assert truncated and info["sim_unstable"] and not terminated
    assert np.all(np.isfinite(obs["observation"]))
    env.reset(seed=0)
    tissue = env.unwrapped.scene.tissue
    real = tissue.positions
    monkeypatch.setattr(tissue, "positions", lambda: real() + 10.0)
    _, _, _, truncated, info = env.step(env.action_space.sample())
    assert truncated and info["sim_unstable"]


def test_two_envs_do_not_share_a_world() -> None:
    """Two environments in one process have their own physics clients and bodies."""
    first, second = make_env("lift"), make_env("lift")
    try:
        first.reset(seed=0)
        second.reset(seed=0)
        a, b = first.unwrapped, second.unwrapped
        assert a.client != b.client
        before = b.scene.tissue.positions()
        for _ in range(5):
            first.step(np.array([0.0, 0.0, -1.0, 0.0, 1.0], dtype=np.float32))
        np.testing.assert_array_equal(b.scene.tissue.positions(), before)
        assert p.getNumBodies(physicsClientId=a.client) == p.getNumBodies(physicsClientId=b.client)
    finally:
        first.close()
        second.close()


def test_async_vector_env_steps() -> None:
    """AsyncVectorEnv runs two environments in subprocesses, each with its own client."""
    envs = gym.vector.AsyncVectorEnv([lambda: make_env("target") for _ in range(2)])
    try:
        obs, _ = envs.reset(seed=[0, 1])
        for _ in range(3):
            obs, reward, _, _, _ = envs.step(envs.action_space.sample())
        assert obs["observation"].shape == (2, 18)
        assert np.all(np.isfinite(obs["observation"]))
        assert reward.shape == (2,)
    finally:
        envs.close()


def test_env_runs_through_the_control_chain() -> None:
    """By default the arm moves only through safety.chain.ControlChain, with its filter on, and info says so."""
    from safety.chain import ControlChain

    env = make_env("lift")
    try:
        env.reset(seed=0)
        assert isinstance(env.unwrapped.controller, ControlChain) and env.unwrapped.controller.safety
        start = env.unwrapped.grasp_position()
        for _ in range(3):
            _, _, _, _, info = env.step(np.array([0.0, 0.0, -1.0, 0.0, 1.0], dtype=np.float32))
        assert info["controller"].startswith("ControlChain (safety filter on")
        assert env.unwrapped.grasp_position()[2] < start[2] - 1e-4
        assert isinstance(info["interventions"], tuple) and isinstance(info["safety_stop"], bool)
        assert isinstance(info["safety_stops"], int) and info["workspace_violation_m"] == 0.0
    finally:
        env.close()


def test_safety_off_is_a_loud_ablation(capfd: pytest.CaptureFixture[str]) -> None:
    """safety=False still drives the chain, but says ABLATION on stderr and in info."""
    env = make_env("lift", safety=False)
    try:
        env.reset(seed=0)
        _, _, _, _, info = env.step(np.zeros(5, dtype=np.float32))
    finally:
        env.close()
    assert "ABLATION" in capfd.readouterr().err
    assert "ABLATION" in info["controller"] and not env.unwrapped.controller.safety


def test_a_commanded_step_is_tracked() -> None:
    """Repeated full 5 mm steps move the tip at least 3 mm per 50 ms step in steady motion (move_jp: 1.6)."""
    env = make_env("lift")
    try:
        env.reset(seed=5, options={"action_latency_steps": 0})
        configuration = env.unwrapped.scene.configuration
        tips = []
        for _ in range(8):
            env.step(np.array([1.0, 0.0, 0.0, 0.0, 1.0], dtype=np.float32))
            configuration.update(env.unwrapped.backend.q)
            tips.append(configuration.measured_pose()[:3, 3].copy())
        per_step = np.diff(np.array(tips)[:, 0])[-4:]
        assert np.all(per_step > 0.003) and np.all(per_step <= 0.005 + 1e-6)
    finally:
        env.close()


def test_workspace_violation_is_measured_against_the_chains_box() -> None:
    """info['workspace_violation_m'] is the tip's distance outside the chain's box (about the RCM), 0 inside."""
    from safety.config import SafetyConfig

    box = SafetyConfig(workspace_min_m=(-0.07, -0.07, -0.20), workspace_max_m=(0.07, 0.07, -0.15))
    env = make_env("lift", safety_config=box)
    try:
        _, info = env.reset(seed=0)
        tip_z = env.unwrapped.scene.configuration.local_pose()[2, 3]
        assert info["workspace_violation_m"] == pytest.approx(tip_z - (-0.15), abs=1e-9)
        assert info["workspace_violation_m"] > 0.01
    finally:
        env.close()
