"""Each shipped policy still does what its sidecar claims, through the full safety chain."""

from __future__ import annotations

import pytest

import sim.envs
from policies.checkpoint import load_policy
from policies.resolve import resolve_policy
from policies.shipped import shipped_claim, shipped_policy_path, shipped_tasks
from sim.evaluation import run_episode
from sim.force_sensing import SENSING_NAMES
from sim.sweep import wilson_interval

PAPER_TASKS = ("TissueRetract-Lift-v0", "TissueRetract-Target-v0", "TissueRetract-MultiSite-v0")
SHIPPED = [(task_id, sensing) for sensing in SENSING_NAMES for task_id in PAPER_TASKS]


def test_a_policy_is_shipped_for_each_paper_task_and_force_sensing() -> None:
    """Tasks I-III each have a shipped policy per force sensing, with its train command and evaluation."""
    for task_id, sensing in SHIPPED:
        assert task_id in shipped_tasks(sensing)
        claim = shipped_claim(task_id, sensing)
        assert claim.train_command.startswith("tissue-retract train")
        assert ("--force-sensing" in claim.train_command) == (sensing != "ideal")
        assert claim.ci95[0] <= claim.success_rate <= claim.ci95[1]
        env = sim.envs.make(task_id)
        meta = load_policy(shipped_policy_path(task_id, sensing), env).meta
        env.close()
        assert meta["task_id"] == task_id and meta["command"] == claim.train_command


@pytest.mark.parametrize("sensing", SENSING_NAMES)
def test_pretrained_is_the_policy_of_the_runs_force_sensing(sensing: str) -> None:
    """``--policy pretrained`` loads the policy trained on the force the run senses."""
    env = sim.envs.make("TissueRetract-Lift-v0", force_sensing=sensing)
    policy, _ = resolve_policy("pretrained", env)
    env.close()
    assert policy.meta["command"] == shipped_claim("TissueRetract-Lift-v0", sensing).train_command  # type: ignore[attr-defined]


@pytest.mark.parametrize(("task_id", "sensing"), SHIPPED)
def test_shipped_policy_evaluates_within_its_claim(task_id: str, sensing: str) -> None:
    """On 20 fresh episodes with its force sensing the policy's success interval overlaps the one it claims."""
    env = sim.envs.make(task_id, force_sensing=sensing)
    policy = load_policy(shipped_policy_path(task_id, sensing), env)
    results = [run_episode(env, policy, lambda: None, seed) for seed in range(9_100_000, 9_100_020)]
    env.close()
    successes = sum(r.success for r in results)
    low, high = wilson_interval(successes, len(results))
    claim = shipped_claim(task_id, sensing)
    assert low <= claim.ci95[1] and claim.ci95[0] <= high, (successes, claim)
    assert all(r.joint_limit_violations == 0 for r in results)
