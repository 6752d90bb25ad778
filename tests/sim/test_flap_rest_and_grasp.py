"""The flap an episode starts on is at rest, and the tissue the jaws hold moves with them."""

from __future__ import annotations

import numpy as np
import pytest

import sim.envs
from sim.expert import ScriptedExpert


@pytest.mark.parametrize("task", ["lift", "multisite"])
def test_an_episode_starts_on_a_flap_at_rest(task: str) -> None:
    """With the tool held above it, the site moves less than 0.8 mm over the first second of an episode."""
    env = sim.envs.make(task)
    try:
        drifts = []
        for seed in range(5):
            env.reset(seed=seed)
            start = env.unwrapped.site_position().copy()
            for _ in range(20):  # 1 s; the zero action holds the tool with the jaw open
                env.step(np.zeros(5))
            drifts.append(float(np.linalg.norm(env.unwrapped.site_position() - start)))
    finally:
        env.close()
    assert max(drifts) < 8e-4, drifts


def test_the_held_site_moves_with_the_jaws() -> None:
    """Grasped by the expert and lifted, the site follows the grasp point within 4 mm (5-17 mm with one node)."""
    env = sim.envs.make("lift")
    task = env.unwrapped
    try:
        lags, lifts = [], []
        for seed in range(5):
            observation, _ = env.reset(seed=seed)
            expert = ScriptedExpert(env)
            expert.reset()
            onset = None
            for _ in range(sim.envs.MAX_EPISODE_STEPS):
                observation, _, _, _, _ = env.step(expert(observation))
                if task.scene.grasp.holding and onset is None:
                    onset = (task.grasp_position().copy(), task.site_position().copy())
            if onset is None or not task.scene.grasp.holding:
                continue
            moved = task.grasp_position() - onset[0]
            lifts.append(float(moved[2]))
            lags.append(float(np.linalg.norm(moved - (task.site_position() - onset[1]))))
    finally:
        env.close()
    assert len(lifts) >= 4 and min(lifts) > 0.01, lifts
    assert max(lags) < 4e-3, lags
