"""The scripted expert and the episode evaluation."""

from __future__ import annotations

import numpy as np

from policies.resolve import resolve_policy
from sim.evaluation import FAILURE_CLASSES, run_episode, summarize
from sim.expert import ScriptedExpert
from tests.sim.conftest import make_env


def test_expert_succeeds_on_every_task(task: str) -> None:
    """The scripted expert reaches and holds the goal in a few episodes of each task."""
    env = make_env(task)
    try:
        policy, reset = resolve_policy("scripted", env)
        results = [run_episode(env, policy, reset, seed) for seed in (900, 901, 902)]
    finally:
        env.close()
    assert all(r.success and r.failure_class == "none" for r in results)
    assert all(r.peak_force_n > 0 for r in results)


def test_random_policy_failures_are_classified() -> None:
    """Random actions fail, each failure gets one known class, and the summary counts them."""
    env = make_env("lift")
    try:
        policy, reset = resolve_policy("random", env)
        env.action_space.seed(0)
        results = [run_episode(env, policy, reset, seed) for seed in range(3)]
    finally:
        env.close()
    summary = summarize(results, elapsed_s=1.0)
    assert {r.failure_class for r in results} <= set(FAILURE_CLASSES)
    assert sum(summary["failure_classes"].values()) == 3
    for key in ("success_rate", "ci95", "episodes", "peak_force_n", "grip_losses", "tissue_damage", "sim_unstable"):
        assert key in summary


def test_the_lag_blind_expert_succeeds_at_three_steps_of_latency_without_reading_them() -> None:
    """With three actions in flight the lag-blind expert's actions do not depend on them, and it still grasps
    and carries the flap to the goal (its demonstrations are what a learner that cannot see the lag can
    imitate)."""
    env = make_env("multisite")
    try:
        expert = ScriptedExpert(env, lag_blind=True)
        results = []
        for seed in (910, 911):
            obs, _ = env.reset(seed=seed, options={"action_latency_steps": 3})
            assert len(env.unwrapped._pending) == 3
            expert.reset()
            success = False
            while True:
                action = expert(obs)
                if expert.phase in ("approach", "retract"):
                    pending = list(env.unwrapped._pending)
                    env.unwrapped._pending.clear()  # what it would do were nothing in flight
                    unaware = expert(obs)
                    env.unwrapped._pending.extend(pending)
                    assert np.array_equal(action, unaware)
                obs, _, terminated, truncated, info = env.step(action)
                if terminated or truncated:
                    success = bool(info["is_success"])
                    break
            results.append(success)
    finally:
        env.close()
    assert all(results)
