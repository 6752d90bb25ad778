"""Disturbance wrappers on a small goal env double."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from psm_control.errors import ConfigurationError, UnknownVariantError
from sim.disturbances import Disturbance, DisturbanceWrapper


class RecordingGoalEnv(gym.Env[dict[str, np.ndarray], np.ndarray]):
    """A goal env whose observation is a constant vector and which records the actions it receives."""

    def __init__(self) -> None:
        box = gym.spaces.Box(-10.0, 10.0, (3,), dtype=np.float64)
        self.observation_space = gym.spaces.Dict({"observation": box, "achieved_goal": box, "desired_goal": box})
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self.received: list[np.ndarray] = []

    def _obs(self) -> dict[str, np.ndarray]:
        return {"observation": np.ones(3), "achieved_goal": np.zeros(3), "desired_goal": np.zeros(3)}

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):  # type: ignore[override]
        super().reset(seed=seed)
        self.received = []
        return self._obs(), {}

    def step(self, action: np.ndarray):  # type: ignore[override]
        self.received.append(np.array(action))
        return self._obs(), -1.0, False, False, {}


def _run(wrapper: DisturbanceWrapper, steps: int, seed: int = 0) -> list[np.ndarray]:
    observations = [wrapper.reset(seed=seed)[0]["observation"]]
    for _ in range(steps):
        observations.append(wrapper.step(np.full(2, 0.5, dtype=np.float32))[0]["observation"])
    return observations


def test_impulse_acts_only_in_its_window() -> None:
    """An impulse offsets the observation by its magnitude for `duration` steps, then vanishes."""
    wrapper = DisturbanceWrapper(RecordingGoalEnv(), observation=(Disturbance("impulse", 0.2, 3, 2),))
    offsets = [np.linalg.norm(o - 1.0) for o in _run(wrapper, 8)]
    assert offsets == pytest.approx([0, 0, 0, 0.2, 0.2, 0, 0, 0, 0], abs=1e-12)


def test_step_persists_and_noise_is_seeded() -> None:
    """A step stays on after it starts; white noise repeats with the seed and differs across seeds."""
    step = DisturbanceWrapper(RecordingGoalEnv(), observation=(Disturbance("step", 0.1, 2),))
    assert [round(float(np.linalg.norm(o - 1.0)), 9) for o in _run(step, 5)] == [0, 0, 0.1, 0.1, 0.1, 0.1]
    noisy = DisturbanceWrapper(RecordingGoalEnv(), observation=(Disturbance("white_noise", 0.01),))
    first, again, other = _run(noisy, 5, seed=1), _run(noisy, 5, seed=1), _run(noisy, 5, seed=2)
    np.testing.assert_array_equal(np.array(first), np.array(again))
    assert not np.allclose(np.array(first), np.array(other))


def test_latency_delays_actions_and_clips_into_the_box() -> None:
    """With latency k the env receives zeros for k steps, then the actions, clipped into the action box."""
    env = RecordingGoalEnv()
    wrapper = DisturbanceWrapper(env, action=(Disturbance("step", 5.0, 0),), latency_steps=2)
    wrapper.reset(seed=0)
    clipped = [wrapper.step(np.full(2, 0.5, dtype=np.float32))[4]["disturbance_clipped"] for _ in range(4)]
    assert [float(np.abs(a).max()) for a in env.received[:2]] == [0.0, 0.0]
    assert all(np.all(np.abs(a) <= 1.0) for a in env.received)
    assert clipped[:2] == [0, 0] and max(clipped[2:]) > 0


def test_bad_disturbances_are_refused() -> None:
    """Unknown kinds, negative magnitudes and latencies raise errors naming the field."""
    with pytest.raises(UnknownVariantError, match="white_noise"):
        Disturbance("ramp", 1.0)  # type: ignore[arg-type]
    with pytest.raises(ConfigurationError, match="magnitude"):
        Disturbance("step", -1.0)
    with pytest.raises(ConfigurationError, match="latency_steps"):
        DisturbanceWrapper(RecordingGoalEnv(), latency_steps=-1)
