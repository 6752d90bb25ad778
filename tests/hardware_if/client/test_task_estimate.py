"""The task estimator: a grasp sensed by a stalled jaw, and a site that moves with the jaws while held."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hardware_if.client.task_estimate import JawGraspSensing, JawReading, TaskEstimate
from psm_control.errors import ConfigurationError

SITE = np.array([0.01, 0.02, 0.015])
GOAL = SITE + np.array([0.0, 0.0, 0.02])
SENSING = JawGraspSensing()
angles = st.floats(-0.7, 1.4)


@given(setpoint=angles, velocity=st.floats(-20.0, 20.0))
def test_a_jaw_at_its_setpoint_holds_nothing(setpoint: float, velocity: float) -> None:
    """A jaw that reached its set-point (open, closed or moving) never reads as holding tissue."""
    assert not SENSING.holding(JawReading(setpoint, velocity, setpoint))


@given(setpoint=st.floats(-0.7, 0.149), stall=st.floats(0.05, 0.6))
def test_a_closing_jaw_stalled_open_holds_tissue(setpoint: float, stall: float) -> None:
    """Asked to close, stopped at least the margin above its set-point: holding."""
    measured = setpoint + stall
    assert SENSING.holding(JawReading(measured, 0.0, setpoint))
    assert not SENSING.holding(JawReading(measured, 5.0, setpoint)), "still moving: not yet stalled"
    assert not SENSING.holding(JawReading(measured, 0.0, 0.6)), "asked to open: not a grasp"


def test_the_site_moves_with_the_jaws_while_held_and_springs_back_after() -> None:
    """While held, site and achieved goal = registered site + the grasp point's motion since the grasp."""
    estimate = TaskEstimate(SITE, GOAL)
    open_jaw, held = JawReading(0.6, 0.0, 0.6), JawReading(0.12, 0.0, 0.0)
    grasp = SITE + np.array([0.001, 0.0, 0.0])
    estimate.update(open_jaw, grasp)
    assert not estimate.grasped and np.array_equal(estimate.site, SITE)
    estimate.update(held, grasp)
    assert estimate.grasped and np.allclose(estimate.site, SITE)
    moved = np.array([0.002, -0.003, 0.012])
    estimate.update(held, grasp + moved)
    assert np.allclose(estimate.achieved_goal, SITE + moved) and np.allclose(estimate.site, SITE + moved)
    estimate.update(JawReading(0.0, 0.0, 0.0), grasp + moved)  # the tissue slipped out: the jaw closed
    assert not estimate.grasped and np.array_equal(estimate.site, SITE)
    assert np.array_equal(estimate.goal, GOAL)


@pytest.mark.parametrize("bad", [[0.0, 0.0], [np.nan, 0.0, 0.0], "here", [0.0, np.inf, 0.0]])
def test_a_site_that_is_not_three_finite_numbers_is_refused(bad: object) -> None:
    """A registration must be a point: anything else names the field and what is allowed."""
    with pytest.raises(ConfigurationError, match=r"site.*three finite coordinates"):
        TaskEstimate(bad, GOAL)  # type: ignore[arg-type]
