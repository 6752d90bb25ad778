"""The force limit is a bound: after a grasp, no action sequence takes the force past 1.1 x the limit.

Hypothesis draws the limit (the nerve preset's 0.4 N up to 3 N), the flap's modulus and any sequence of
full-range motions with the jaw closed; the scripted expert makes the grasp first so that every example
pulls on held tissue. The peak is over every control tick of the real PyBullet episode.

Not covered, and measured: a jaw that lets go and closes again on the flap while it still swings from
the release grips moving tissue, which the tool's motion does not cause and the filter cannot prevent
(one tick at 1.07 N against a 0.4 N limit, with the tool still).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from hypothesis import HealthCheck, assume, given, settings, target
from hypothesis import strategies as st

import sim.envs
from safety.config import SafetyConfig
from sim.expert import ScriptedExpert

_BOUND = 1.10
_MOTION = st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4)
_ENVS: dict[float, object] = {}


def _env(limit_n: float):  # one environment per limit for the whole module: building one takes seconds
    if limit_n not in _ENVS:
        _ENVS[limit_n] = sim.envs.make("lift", safety_config=SafetyConfig(force_limit_n=limit_n))
    return _ENVS[limit_n]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    limit_n=st.sampled_from([0.4, 1.0, 3.0]),
    modulus_kpa=st.floats(3.0, 30.0),
    seed=st.integers(0, 10_000),
    motions=st.lists(_MOTION, min_size=10, max_size=25),
)
def test_no_action_sequence_takes_the_force_past_the_bound(
    limit_n: float, modulus_kpa: float, seed: int, motions: list[list[float]]
) -> None:
    """Peak force over every tick after the expert's grasp <= 1.1 x the limit, whatever the motions."""
    env: Any = _env(limit_n)
    observation, _ = env.reset(seed=seed, options={"tissue_youngs_modulus_kpa": modulus_kpa})
    expert = ScriptedExpert(env)
    expert.reset()
    for _ in range(sim.envs.MAX_EPISODE_STEPS):
        if env.unwrapped.scene.grasp.holding:
            break
        observation, *_ = env.step(expert(observation))
    assume(env.unwrapped.scene.grasp.holding)
    peak = 0.0
    for motion in motions:
        _, _, _, _, info = env.step(np.array([*motion, -1.0]))  # the jaw stays closed
        peak = max(peak, info["force_peak_n"])
    target(peak / limit_n)  # steer the search towards the largest peak
    assert peak <= _BOUND * limit_n, (peak, limit_n, info["force_limit_exceeded"])


def teardown_module() -> None:
    for env in _ENVS.values():
        env.close()  # type: ignore[attr-defined]
