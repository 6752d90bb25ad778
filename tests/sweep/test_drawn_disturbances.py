"""Disturbances drawn per episode from --vary's ranges (training's), on a small goal env double."""

from __future__ import annotations

import numpy as np
import pytest

from psm_control.errors import ConfigurationError, UnknownVariantError
from sim.drawn_disturbances import DrawnDisturbanceWrapper
from sim.robustness import parse_vary
from tests.sweep.test_disturbances import RecordingGoalEnv


def _episode(wrapper: DrawnDisturbanceWrapper, seed: int, steps: int = 6) -> tuple[dict[str, float], np.ndarray]:
    observations = []
    obs, info = wrapper.reset(seed=seed)
    observations.append(obs["observation"])
    for _ in range(steps):
        observations.append(wrapper.step(np.full(2, 0.5, dtype=np.float32))[0]["observation"])
    return info["disturbances"], np.array(observations)


def test_each_episode_draws_its_magnitudes_within_the_ranges_from_its_seed() -> None:
    """Magnitudes lie in their ranges, differ between seeds, and a seed repeats its magnitudes and observations."""
    ranges = parse_vary("obs_white_m=0.001:0.002,obs_step_m=0.01:0.02,action_white=0:0.1")
    wrapper = DrawnDisturbanceWrapper(RecordingGoalEnv(), ranges)
    drawn = {seed: _episode(wrapper, seed) for seed in range(20)}
    for magnitudes, _ in drawn.values():
        assert set(magnitudes) == {"obs_white_m", "obs_step_m", "action_white"}
        assert 0.001 <= magnitudes["obs_white_m"] <= 0.002 and 0.01 <= magnitudes["obs_step_m"] <= 0.02
    assert len({m["obs_white_m"] for m, _ in drawn.values()}) == 20
    again, observations = _episode(wrapper, 7)
    assert again == drawn[7][0]
    np.testing.assert_array_equal(observations, drawn[7][1])
    assert np.all(np.abs(observations - 1.0) > 0)  # the constant observation of the double, disturbed


def test_zero_ranges_leave_the_observations_and_actions_as_they_are() -> None:
    """With every magnitude 0 the policy sees the env's observation and the env receives the action."""
    env = RecordingGoalEnv()
    wrapper = DrawnDisturbanceWrapper(env, parse_vary("obs_white_m=0,obs_impulse_m=0,action_step=0"))
    _, observations = _episode(wrapper, 3)
    np.testing.assert_array_equal(observations, np.ones_like(observations))
    np.testing.assert_array_equal(np.array(env.received), np.full((6, 2), 0.5))


def test_unseeded_resets_go_on_from_the_last_seed() -> None:
    """Without a seed each reset draws anew from the stream the last seed started: two such runs agree."""
    runs = []
    for _ in range(2):
        wrapper = DrawnDisturbanceWrapper(RecordingGoalEnv(), parse_vary("obs_white_m=0.001:0.002"))
        wrapper.reset(seed=5)
        runs.append([wrapper.reset()[1]["disturbances"]["obs_white_m"] for _ in range(3)])
    assert runs[0] == runs[1] and len(set(runs[0])) == 3


def test_what_is_no_disturbance_range_is_refused() -> None:
    """A randomization parameter, a multiple or a negative magnitude is refused, naming what is allowed."""
    with pytest.raises(UnknownVariantError, match="obs_white_m"):
        DrawnDisturbanceWrapper(RecordingGoalEnv(), parse_vary("stiffness=0.5:2x"))
    (relative,) = parse_vary("stiffness=0.5:2x")
    with pytest.raises(ConfigurationError, match="magnitudes >= 0"):
        DrawnDisturbanceWrapper(RecordingGoalEnv(), [relative.__class__("action_white", 0.5, 2.0, relative=True)])
    with pytest.raises(ConfigurationError, match="magnitudes >= 0"):
        parse_vary("obs_white_m=-0.001:0.001")
