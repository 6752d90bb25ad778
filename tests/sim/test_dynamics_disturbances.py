"""Dynamics disturbances: encoder offset, base registration error and tracking lag."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from psm_control.errors import ConfigurationError
from sim.randomization import DYNAMICS_PARAMETERS, Randomizer
from sim.robustness import ALIASES
from tests.sim.conftest import make_env

_ZERO = dict.fromkeys(DYNAMICS_PARAMETERS, 0.0)
_ACTIONS = [np.array([0.3, -0.2, 1.0, 0.0, 1.0]), np.array([-0.5, 0.4, -0.6, 0.0, -1.0])] * 2


@pytest.fixture
def lift() -> Any:
    """A Task I environment, closed after the test."""
    environment = make_env("lift")
    yield environment
    environment.close()


def _rollout(env: Any, seed: int, options: dict[str, float] | None = None) -> list[np.ndarray]:
    obs, info = env.reset(seed=seed, options=options)
    trace = [*obs.values(), info["q"]]
    for action in _ACTIONS:
        obs, reward, _, _, info = env.step(action)
        trace += [*obs.values(), info["q"], np.array([reward, info["force_norm_n"]])]
    return trace


def test_sampling_leaves_the_episode_stream_alone() -> None:
    """The dynamics parameters come from their own stream: other draws and the generator are untouched."""
    plain, disturbed = np.random.default_rng(7), np.random.default_rng(7)
    a = Randomizer().sample(plain)
    b = Randomizer({"joint_offset_rad": (0.01, 0.05), "tracking_lag": (0.2, 0.8)}).sample(disturbed)
    assert {k: v for k, v in a.items() if k not in DYNAMICS_PARAMETERS} == {
        k: v for k, v in b.items() if k not in DYNAMICS_PARAMETERS
    }
    assert plain.bit_generator.state == disturbed.bit_generator.state
    assert all(a[name] == 0.0 for name in DYNAMICS_PARAMETERS)
    assert 0.01 <= b["joint_offset_rad"] <= 0.05 and 0.2 <= b["tracking_lag"] <= 0.8


def test_defaults_equal_explicit_zeros(lift: Any) -> None:
    """A default episode is bit-identical to one with the three parameters fixed at 0."""
    default = _rollout(lift, 11)
    zero = _rollout(lift, 11, _ZERO)
    assert len(default) == len(zero)
    for x, y in zip(default, zero, strict=True):
        np.testing.assert_array_equal(x, y)


def test_joint_offset_changes_the_measurement_not_the_joints(lift: Any) -> None:
    """An encoder offset shifts what the controller measures; the true joints at reset are unchanged."""
    lift.reset(seed=5)
    env = lift.unwrapped
    q_true, tip = env.backend.q.copy(), env._observation()["observation"][:3]
    np.testing.assert_array_equal(env.backend.measure().q, q_true)
    lift.reset(seed=5, options={"joint_offset_rad": 0.02})
    np.testing.assert_array_equal(env.backend.q, q_true)
    offset = env.backend.measure().q - env.backend.q
    assert np.all(offset != 0.0)
    assert np.all(np.abs(offset[[0, 1, 3, 4, 5]]) < 0.2) and abs(offset[2]) < 0.002  # insertion in m
    assert not np.allclose(env._observation()["observation"][:3], tip, atol=1e-5)
    # Commands are reached in the encoders' terms: after a step the measurement still carries the offset.
    lift.step(_ACTIONS[0])
    np.testing.assert_allclose(env.backend.measure().q - env.backend.q, offset, atol=1e-12)


def test_tracking_lag_slows_the_achieved_motion(lift: Any) -> None:
    """With a lag the joints move less per step for the same commands, and still converge."""
    moves = {}
    for lag in (0.0, 0.9):
        _, info = lift.reset(seed=3, options={"tracking_lag": lag})
        before = info["q"]
        _, _, _, _, info = lift.step(np.array([0.0, 0.0, 1.0, 0.0, 1.0]))
        moves[lag] = float(np.linalg.norm(info["q"] - before))
    assert moves[0.0] > 1e-4
    assert moves[0.9] < 0.9 * moves[0.0]
    env = lift.unwrapped
    for _ in range(10):
        lift.step(np.zeros(5))
    np.testing.assert_allclose(env.backend.q, env.backend.q_target, atol=1e-6)


def test_base_error_shifts_the_reported_tool_pose(lift: Any) -> None:
    """A base registration error moves the reported tool position by its norm; the site stays true."""
    plain, _ = lift.reset(seed=9)
    shifted, info = lift.reset(seed=9, options={"base_error_m": 0.004})
    np.testing.assert_array_equal(info["q"], lift.unwrapped.backend.q)
    tip_shift = shifted["observation"][:3] - plain["observation"][:3]
    assert np.linalg.norm(tip_shift) == pytest.approx(0.004, rel=1e-3)
    np.testing.assert_array_equal(shifted["observation"][8:11], plain["observation"][8:11])  # site
    np.testing.assert_array_equal(shifted["achieved_goal"], plain["achieved_goal"])


@pytest.mark.parametrize(
    ("name", "bounds"),
    [("joint_offset_rad", (-0.01, 0.0)), ("base_error_m", (-0.001, 0.001)), ("tracking_lag", (0.0, 1.0))],
)
def test_out_of_range_values_are_refused(lift: Any, name: str, bounds: tuple[float, float]) -> None:
    """Negative magnitudes and lags of 1 or more are refused, as ranges and as reset options."""
    with pytest.raises(ConfigurationError):
        Randomizer({name: bounds})
    bad = bounds[0] if bounds[0] < 0 else bounds[1]
    with pytest.raises(ConfigurationError):
        lift.reset(seed=0, options={name: bad})


def test_sweep_short_names() -> None:
    """The sweep knows the short names."""
    assert ALIASES["joint_offset"] == "joint_offset_rad" and ALIASES["base_error"] == "base_error_m"
