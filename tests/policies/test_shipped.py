"""Each shipped policy still does what its sidecar claims, through the full safety chain."""

from __future__ import annotations

from typing import Any

import pytest

import sim.envs
from hardware_if.client.perceived_env import camera_task
from policies.checkpoint import load_policy
from policies.resolve import resolve_policy
from policies.shipped import CAMERA, shipped_claim, shipped_policy_path, shipped_tasks
from sim.evaluation import run_episode
from sim.force_sensing import SENSING_NAMES
from sim.sweep import wilson_interval

PAPER_TASKS = ("TissueRetract-Lift-v0", "TissueRetract-Target-v0", "TissueRetract-MultiSite-v0")
VARIANTS = (*SENSING_NAMES, CAMERA)
SHIPPED = [(task_id, variant) for variant in VARIANTS for task_id in PAPER_TASKS]


def _environment(task_id: str, variant: str) -> Any:
    """The task as the variant's policy observes it: with its force sensing, or the site from the camera."""
    if variant == CAMERA:
        return camera_task(sim.envs.make(task_id))
    return sim.envs.make(task_id, force_sensing=variant)


def test_a_policy_is_shipped_for_each_paper_task_and_variant() -> None:
    """Tasks I-III each have a shipped policy per variant, with its train command and evaluation."""
    for task_id, variant in SHIPPED:
        assert task_id in shipped_tasks(variant)
        claim = shipped_claim(task_id, variant)
        assert claim.train_command.startswith("tissue-retract train")
        assert ("--force-sensing" in claim.train_command) == (variant in SENSING_NAMES and variant != "ideal")
        assert ("--perception camera" in claim.train_command) == (variant == CAMERA)
        assert claim.ci95[0] <= claim.success_rate <= claim.ci95[1]
        env = sim.envs.make(task_id)
        other_task = claim.trained_on_task != task_id
        meta = load_policy(shipped_policy_path(task_id, variant), env, allow_other_task=other_task).meta
        env.close()
        assert meta["task_id"] == claim.trained_on_task and meta["command"] == claim.train_command
        assert claim.trained_on_task in PAPER_TASKS


@pytest.mark.parametrize("variant", VARIANTS)
def test_pretrained_is_the_policy_of_what_the_run_observes(variant: str) -> None:
    """``--policy pretrained`` loads the policy trained on the force the run senses and the site it sees."""
    env = _environment("TissueRetract-Lift-v0", variant)
    policy, _ = resolve_policy("pretrained", env)
    env.close()
    assert policy.meta["command"] == shipped_claim("TissueRetract-Lift-v0", variant).train_command  # type: ignore[attr-defined]


@pytest.mark.parametrize(("task_id", "variant"), SHIPPED)
def test_shipped_policy_evaluates_within_its_claim(task_id: str, variant: str) -> None:
    """On 20 fresh episodes as its variant observes them the policy's success interval overlaps its claim."""
    env = _environment(task_id, variant)
    policy, _ = resolve_policy("pretrained", env)
    results = [run_episode(env, policy, lambda: None, seed) for seed in range(9_100_000, 9_100_020)]
    env.close()
    successes = sum(r.success for r in results)
    low, high = wilson_interval(successes, len(results))
    claim = shipped_claim(task_id, variant)
    assert low <= claim.ci95[1] and claim.ci95[0] <= high, (successes, claim)
    assert all(r.joint_limit_violations == 0 for r in results)
