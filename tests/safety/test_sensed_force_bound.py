"""The bound on the true force the filter keeps to with an inexact force sensor (safety.force_bound)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from psm_control.commands import CartesianDelta, MeasuredState
from safety.chain import ControlChain
from safety.config import SafetyConfig
from safety.force_bound import MEASURED, TRAVEL, ForceBound, sensing_warning

_OPEN, _CLOSED = 0.6, 0.0


def test_an_exact_sensor_keeps_the_measured_force_and_the_learned_stiffness() -> None:
    """Error 0: the estimate is the measurement, with no margin and the learned stiffness."""
    bound = ForceBound(3.0, 0.0, 60.0, 0.3, 0.01)
    force = np.array([0.1, 0.2, 0.3])
    estimate = bound.update(_CLOSED, np.zeros(3), force, 812.0)
    assert estimate.source == MEASURED and estimate.margin_n == 0.0 and estimate.stiffness_n_per_m == 812.0
    assert np.array_equal(estimate.force_n, force)


def test_a_measurement_that_cannot_tell_the_limit_gives_way_to_the_travel_bound() -> None:
    """Error above the limit: once the jaws close, the force is bounded by stiffness x travel plus the held load."""
    bound = ForceBound(0.4, 2.0, 60.0, 0.1, 0.01)
    measured = np.array([0.0, 0.0, 1.5])  # a biased reading: nothing held
    assert bound.update(_OPEN, np.zeros(3), measured, 400.0).source == MEASURED
    bound.update(_CLOSED, np.array([0.01, 0.0, 0.0]), measured, 400.0)  # the grasp: travel starts here
    estimate = bound.update(_CLOSED, np.array([0.01, 0.0, 0.004]), measured, 400.0)
    assert estimate.source == TRAVEL and estimate.margin_n == 0.1 and estimate.stiffness_n_per_m == 60.0
    assert np.allclose(estimate.force_n, [0.0, 0.0, 60.0 * 0.004])
    assert bound.travel_allowed_m() == pytest.approx(0.3 / 60.0)
    for _ in range(19):  # an opened jaw may hold tissue for RELEASE_S (0.2 s)
        assert bound.update(_OPEN, np.array([0.01, 0.0, 0.004]), measured, 400.0).source == TRAVEL
        assert bound.holding
    assert bound.update(_OPEN, np.zeros(3), measured, 400.0).source == MEASURED and not bound.holding
    # Closed again within RESETTLE_S: the travel still counts from the first grasp.
    assert np.allclose(bound.update(_CLOSED, np.array([0.01, 0.0, 0.002]), measured, 400.0).force_n, [0, 0, 0.12])
    for _ in range(100):  # released for RESETTLE_S: the next grasp starts afresh
        bound.update(_OPEN, np.zeros(3), measured, 400.0)
    assert np.allclose(bound.update(_CLOSED, np.ones(3), measured, 400.0).force_n, 0.0)


def test_the_travel_bound_is_told_only_while_the_jaws_may_hold_tissue() -> None:
    """``travel_bound_n`` is the held load plus stiffness x travel while held; NaN before, after and when exact."""
    bound = ForceBound(3.0, 2.0, 60.0, 0.3, 0.01)
    bound.update(_OPEN, np.zeros(3), np.zeros(3), 400.0)
    assert np.isnan(bound.travel_bound_n)
    bound.update(_CLOSED, np.zeros(3), np.zeros(3), 400.0)
    assert bound.travel_bound_n == pytest.approx(0.3)
    bound.update(_CLOSED, np.array([0.0, 0.003, 0.004]), np.zeros(3), 400.0)
    assert bound.travel_bound_n == pytest.approx(0.3 + 60.0 * 0.005)
    for _ in range(21):
        bound.update(_OPEN, np.zeros(3), np.zeros(3), 400.0)
    assert np.isnan(bound.travel_bound_n)
    exact = ForceBound(3.0, 0.0, 60.0, 0.3, 0.01)
    exact.update(_CLOSED, np.ones(3), np.zeros(3), 400.0)
    assert np.isnan(exact.travel_bound_n)


def test_the_bound_that_leaves_more_room_is_used() -> None:
    """A small error: the measured force (with the error as margin) wins over a long travel; NaN never does."""
    bound = ForceBound(3.0, 0.5, 60.0, 0.3, 0.01)
    bound.update(_CLOSED, np.zeros(3), np.zeros(3), 400.0)
    far = np.array([0.0, 0.0, 0.04])  # 2.4 N by the travel bound
    estimate = bound.update(_CLOSED, far, np.array([0.0, 0.0, 0.3]), 400.0)
    assert estimate.source == MEASURED and estimate.margin_n == 0.5 and estimate.stiffness_n_per_m == 60.0
    near = bound.update(_CLOSED, np.array([0.0, 0.0, 0.001]), np.array([0.0, 0.0, 2.0]), 400.0)
    assert near.source == TRAVEL
    assert bound.update(_CLOSED, far, np.full(3, np.nan), 400.0).source == TRAVEL


def test_the_warning_names_the_limit_the_error_and_what_keeps_the_limit() -> None:
    """A limit at or below the sensing's error bound is warned about with its numbers; others are not."""
    nerve = SafetyConfig(
        tissue="nerve", force_sensing_error_n=8.9, tissue_stiffness_bound_n_per_m=63.0, held_load_bound_n=0.3
    )
    text = sensing_warning(nerve, "dvrk force sensing")
    assert text.startswith("WARNING: force limit 0.4 N is below the force sensing's error bound 8.90 N")
    assert "63 N/m" in text and "1.6 mm of travel" in text
    assert "What you can change: calibrate the force sensing" in text
    assert "tissue_stiffness_bound_n_per_m in a --safety-config" in text
    calibrated = sensing_warning(nerve, "dvrk-calibrated force sensing", calibrated=True)
    assert "calibrate-wrench" not in calibrated and "raise the limit" in calibrated  # calibrated already
    assert sensing_warning(dataclasses.replace(nerve, force_sensing_error_n=0.0), "ideal") == ""
    assert sensing_warning(SafetyConfig(force_sensing_error_n=1.4), "dvrk-calibrated") == ""


def test_the_chain_does_not_learn_stiffness_from_an_inexact_force() -> None:
    """With a sensing error the stiffness estimator gets no sample: its force changes would carry the error."""
    for error, learns in ((0.0, True), (1.0, False)):
        chain = ControlChain(SafetyConfig(force_sensing_error_n=error))
        q = chain.model.home()
        chain.reset(MeasuredState(q, np.zeros(6), _CLOSED, np.zeros(3), 0.0))
        lift = CartesianDelta(np.array([0.0, 0.0, 0.002]), 0.0, _CLOSED, "base")
        measured = MeasuredState(q, np.zeros(6), _CLOSED, np.zeros(3), 0.0)
        for k in range(1, 100):
            if k % 10 == 1:
                chain.set_target(lift, measured)
            command = chain.tick(measured).command
            # The held tissue pulls back harder the higher the tool goes (the tissue's force on the tool).
            measured = MeasuredState(command.q, command.qd, _CLOSED, np.array([0.0, 0.0, -0.005 * k]), k * 0.01)
        assert (chain.stiffness.updates > 0) == learns
