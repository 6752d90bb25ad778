"""The retraction-force bound in the loop: random action sequences after a grasp keep it, and passing the
limit without the filter is reported, never silent."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from safety.config import SafetyConfig
from sim.evaluation import run_episode
from sim.expert import ScriptedExpert
from sim.pulling import AggressivePull
from tests.sim.conftest import make_env

_BOUND = 1.1  # peak / limit
_STEPS_AFTER_GRASP = 8


@pytest.fixture(scope="module")
def nerve_env() -> Iterator[Any]:
    """Task I under the nerve preset (0.4 N), the smallest preset limit."""
    environment = make_env("lift", safety_config=SafetyConfig(tissue="nerve"))
    yield environment
    environment.close()


def _grasp(env: Any, seed: int, stiffness_n_per_m: float) -> float:
    """Reset and let the expert grasp; return the largest force read so far."""
    expert = ScriptedExpert(env)
    observation, _ = env.reset(seed=seed, options={"tissue_stiffness_n_per_m": stiffness_n_per_m})
    peak = 0.0
    for _ in range(30):
        observation, _, _, _, info = env.step(expert(observation))
        peak = max(peak, info["force_norm_n"])
        if env.unwrapped.scene.grasp.holding:
            break
    return peak


actions = st.lists(
    st.tuples(st.sampled_from([-1.0, -0.5, 0.5, 1.0]), st.sampled_from([-1.0, 1.0]), st.sampled_from([-1.0, 1.0])),
    min_size=_STEPS_AFTER_GRASP,
    max_size=_STEPS_AFTER_GRASP,
)


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(sequence=actions, factor=st.sampled_from([0.3, 1.0, 3.0]))
def test_random_pulls_after_a_grasp_keep_the_force_within_the_bound(
    nerve_env: Any, sequence: list[tuple[float, float, float]], factor: float
) -> None:
    """Saturating random moves of a gripping jaw never take the force past 1.1 x the 0.4 N limit."""
    peak = _grasp(nerve_env, 4301, 22.0 * factor)
    limit = nerve_env.unwrapped.controller.config.effective_force_limit_n
    assert nerve_env.unwrapped.scene.grasp.holding  # the moves below pull on held tissue
    for x, y, z in sequence:
        _, _, _, _, info = nerve_env.step(np.array([x, y, z, 0.0, -1.0], dtype=np.float32))
        peak = max(peak, info["force_norm_n"], limit + info["force_excess_n"])
    assert peak <= _BOUND * limit


def test_passing_the_limit_without_the_filter_is_counted() -> None:
    """Without the filter an aggressive pull passes the nerve limit, and the episode reports it."""
    env = make_env("target", safety=False, safety_config=SafetyConfig(tissue="nerve"))
    try:
        policy = AggressivePull(env)
        result = run_episode(env, policy, policy.reset, 4400)
    finally:
        env.close()
    assert result.peak_force_n > result.force_limit_n == pytest.approx(0.4)
    assert result.force_limit_exceeded >= 1
    assert result.max_force_excess_n > 0.0 and result.force_exceeded_s > 0.0
