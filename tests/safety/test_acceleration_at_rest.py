"""The acceleration limit treats float dust left by the smoother as rest, not as motion."""

from __future__ import annotations

import numpy as np
import pytest

from safety.limits import FilterState, JointAccelerationLimit


def _state(qd: float) -> FilterState:
    one = np.ones(1)
    return FilterState(0 * one, qd * one, np.zeros(3), np.zeros((3, 1)), np.zeros((3, 1)), np.zeros(3), 100.0, 0.01)


@pytest.mark.parametrize("dust", [-2.9e-20, 1e-12, -5e-10])
def test_dust_velocity_does_not_block_either_direction(dust: float) -> None:
    """At a velocity of float dust a joint may be sent either way (bounds and rows alike)."""
    one = np.ones(1)
    limit = JointAccelerationLimit(one, 0.01 * one, -one, one)
    lower, upper = limit.compute_joint_bounds(_state(dust))
    assert lower[0] == -np.inf and upper[0] == np.inf
    _, h = limit.compute_qp_inequalities(_state(dust))
    assert h[0] == np.inf


def test_real_motion_still_keeps_the_goal_beyond_the_stopping_point() -> None:
    """A joint really moving down must be sent at least its stopping distance further down."""
    one = np.ones(1)
    limit = JointAccelerationLimit(one, 0.01 * one, -one, one)
    lower, upper = limit.compute_joint_bounds(_state(-0.1))
    assert lower[0] == -np.inf and upper[0] == pytest.approx(-(0.1**2) / 2)
