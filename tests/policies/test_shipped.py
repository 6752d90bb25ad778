"""Each shipped policy still does what its sidecar claims, through the full safety chain."""

from __future__ import annotations

import pytest

import sim.envs
from policies.checkpoint import load_policy
from policies.shipped import shipped_claim, shipped_policy_path, shipped_tasks
from sim.evaluation import run_episode
from sim.sweep import wilson_interval

PAPER_TASKS = ("TissueRetract-Lift-v0", "TissueRetract-Target-v0", "TissueRetract-MultiSite-v0")


def test_a_policy_is_shipped_for_each_paper_task() -> None:
    """Tasks I-III each have a shipped policy with a recorded train command and evaluation."""
    assert set(PAPER_TASKS) <= set(shipped_tasks())
    for task_id in PAPER_TASKS:
        claim = shipped_claim(task_id)
        assert claim.train_command.startswith("tissue-retract train")
        assert claim.ci95[0] <= claim.success_rate <= claim.ci95[1]
        env = sim.envs.make(task_id)
        meta = load_policy(shipped_policy_path(task_id), env).meta
        env.close()
        assert meta["task_id"] == task_id and meta["command"] == claim.train_command


@pytest.mark.parametrize("task_id", PAPER_TASKS)
def test_shipped_policy_evaluates_within_its_claim(task_id: str) -> None:
    """On 20 fresh episodes the policy's success interval overlaps the interval it claims."""
    env = sim.envs.make(task_id)
    policy = load_policy(shipped_policy_path(task_id), env)
    results = [run_episode(env, policy, lambda: None, seed) for seed in range(9_100_000, 9_100_020)]
    env.close()
    successes = sum(r.success for r in results)
    low, high = wilson_interval(successes, len(results))
    claim = shipped_claim(task_id)
    assert low <= claim.ci95[1] and claim.ci95[0] <= high, (successes, claim)
    assert all(r.joint_limit_violations == 0 for r in results)
