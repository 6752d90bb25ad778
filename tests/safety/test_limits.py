"""Each safety limit alone: its rows, its per-joint bounds, and what the filter reports about it."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psm_control.robot import PsmModel
from safety.config import SafetyConfig
from safety.filter import SafetyFilter
from safety.limits import (
    FilterState,
    JointAccelerationLimit,
    JointPositionLimit,
    JointVelocityLimit,
    Limit,
    RcmInsertionLimit,
    RetractionForceLimit,
    WorkspaceBoxLimit,
)

_CONFIG = SafetyConfig()
_SPEC = _CONFIG.spec
_STEP = _CONFIG.velocity * _CONFIG.horizon_s
_MODEL = PsmModel(_SPEC)


def _state(q: np.ndarray, qd: np.ndarray | None = None, force: np.ndarray | None = None) -> FilterState:
    configuration = _MODEL.configuration(q)
    return FilterState(
        np.asarray(q, dtype=float),
        np.zeros(6) if qd is None else np.asarray(qd, dtype=float),
        configuration.measured_pose()[:3, 3],
        configuration.base_jacobian()[:3],
        np.zeros(3) if force is None else np.asarray(force, dtype=float),
        400.0,
        _CONFIG.control_period_s,
    )


def _bound_limits() -> list[Limit]:
    lower = _SPEC.lower + np.asarray(_CONFIG.position_margin)
    lower[2] = max(lower[2], _CONFIG.min_insertion_m)
    upper = _SPEC.upper - np.asarray(_CONFIG.position_margin)
    return [
        JointPositionLimit(_SPEC.lower, _SPEC.upper, np.asarray(_CONFIG.position_margin)),
        JointVelocityLimit(_CONFIG.velocity, _CONFIG.horizon_s),
        RcmInsertionLimit(_CONFIG.min_insertion_m),
        JointAccelerationLimit(_CONFIG.acceleration, _STEP, lower, upper),
    ]


joint_states = st.tuples(
    st.lists(st.floats(0.0, 1.0), min_size=6, max_size=6),
    st.lists(st.floats(-2.0, 2.0), min_size=6, max_size=6),
)


@settings(max_examples=200, deadline=None)
@given(joint_states)
def test_direct_bounds_equal_the_bounds_the_rows_say(sample: tuple[list[float], list[float]]) -> None:
    """Every joint-bound limit's direct compute_joint_bounds equals the bounds derived from its rows."""
    fraction, velocity = sample
    q = _SPEC.lower + np.asarray(fraction) * (_SPEC.upper - _SPEC.lower)
    state = _state(q, np.asarray(velocity) * _CONFIG.velocity)
    for limit in _bound_limits():
        assert limit.joint_bounds
        lower, upper = limit.compute_joint_bounds(state)
        generic_lower, generic_upper = Limit.compute_joint_bounds(limit, state)
        np.testing.assert_allclose(lower, generic_lower, err_msg=limit.name)
        np.testing.assert_allclose(upper, generic_upper, err_msg=limit.name)
        assert np.all(lower <= upper + 1e-12), limit.name


def test_position_rows_keep_the_goal_inside_the_margin() -> None:
    """Joint position rows allow exactly the room to the margin, and never forbid standing still."""
    limit = JointPositionLimit(_SPEC.lower, _SPEC.upper, np.asarray(_CONFIG.position_margin))
    q = _MODEL.home()
    G, h = limit.compute_qp_inequalities(_state(q))
    assert G.shape == (12, 6) and h.shape == (12,)
    np.testing.assert_allclose(h[:6], limit.upper - q)
    np.testing.assert_allclose(h[6:], q - limit.lower)
    q_out = q.copy()
    q_out[0] = _SPEC.upper[0]  # inside the margin: may stay or go back, not further
    lower, upper = limit.compute_joint_bounds(_state(q_out))
    assert upper[0] == 0.0 and lower[0] < 0.0


def test_velocity_rows_bound_the_step() -> None:
    """Joint velocity rows bound each step to v_max * horizon in both directions."""
    limit = JointVelocityLimit(_CONFIG.velocity, _CONFIG.horizon_s)
    G, h = limit.compute_qp_inequalities(_state(_MODEL.home()))
    np.testing.assert_allclose(h, np.concatenate([_STEP, _STEP]))
    np.testing.assert_allclose(G, np.vstack([np.eye(6), -np.eye(6)]))


def test_insertion_row_only_allows_outwards_below_the_minimum() -> None:
    """Below the minimum insertion the only allowed insertion step is outwards (dq_2 >= 0)."""
    limit = RcmInsertionLimit(_CONFIG.min_insertion_m)
    q = _MODEL.home()
    q[2] = _CONFIG.min_insertion_m - 0.001
    G, h = limit.compute_qp_inequalities(_state(q))
    assert G[0, 2] == -1.0 and h[0] == 0.0
    q[2] = _CONFIG.min_insertion_m + 0.01
    lower, _ = limit.compute_joint_bounds(_state(q))
    assert lower[2] == pytest.approx(-0.01)


def test_acceleration_row_keeps_the_goal_beyond_the_stopping_distance() -> None:
    """A moving joint's goal is at least min(v^2 / 2a, step, room) ahead; a resting joint is free."""
    lower_q = _SPEC.lower + np.asarray(_CONFIG.position_margin)
    upper_q = _SPEC.upper - np.asarray(_CONFIG.position_margin)
    limit = JointAccelerationLimit(_CONFIG.acceleration, _STEP, lower_q, upper_q)
    qd = np.zeros(6)
    qd[0] = 0.5
    qd[1] = -0.5
    lower, upper = limit.compute_joint_bounds(_state(_MODEL.home(), qd))
    distance = min(0.25 / (2 * _CONFIG.acceleration[0]), _STEP[0])
    assert lower[0] == pytest.approx(distance) and upper[0] == np.inf
    assert upper[1] == pytest.approx(-min(0.25 / (2 * _CONFIG.acceleration[1]), _STEP[1])) and lower[1] == -np.inf
    assert np.all(np.isinf(lower[2:])) and np.all(np.isinf(upper[2:]))


def test_workspace_rows_are_a_control_barrier() -> None:
    """Workspace rows are J dq <= gamma (hi - x) and -J dq <= gamma (x - lo)."""
    limit = WorkspaceBoxLimit(np.asarray(_CONFIG.workspace_min_m), np.asarray(_CONFIG.workspace_max_m), 0.5)
    state = _state(_MODEL.home())
    G, h = limit.compute_qp_inequalities(state)
    np.testing.assert_allclose(G[:3], state.tool_jacobian)
    np.testing.assert_allclose(G[3:], -state.tool_jacobian)
    np.testing.assert_allclose(h[:3], 0.5 * (np.asarray(_CONFIG.workspace_max_m) - state.tool_position_m))
    np.testing.assert_allclose(h[3:], 0.5 * (state.tool_position_m - np.asarray(_CONFIG.workspace_min_m)))
    assert limit.soft and not limit.joint_bounds


def test_force_row_predicts_the_force_a_step_adds() -> None:
    """The force row is K n^T J dq <= F_max - |F|, and unused below the smallest trusted force."""
    limit = RetractionForceLimit(3.0)
    G, h = limit.compute_qp_inequalities(_state(_MODEL.home(), force=np.array([0.0, 0.0, 0.01])))
    assert np.all(G == 0.0) and h[0] == np.inf
    state = _state(_MODEL.home(), force=np.array([0.0, 2.0, 0.0]))
    G, h = limit.compute_qp_inequalities(state)
    np.testing.assert_allclose(G[0], 400.0 * state.tool_jacobian[1])
    assert h[0] == pytest.approx(1.0)


def test_limit_report_says_active_and_how_much_the_nominal_violated() -> None:
    """Limit.report flags the nominal's violation with its size and an active row at the filtered step."""
    limit = JointVelocityLimit(_CONFIG.velocity, _CONFIG.horizon_s)
    G, h = limit.compute_qp_inequalities(_state(_MODEL.home()))
    nominal = np.zeros(6)
    nominal[0] = _STEP[0] + 0.01
    filtered = np.zeros(6)
    filtered[0] = _STEP[0]
    report = limit.report(G, h, nominal, filtered, 1e-9)
    assert report.intervened and report.active
    assert report.nominal_violation == pytest.approx(0.01)
    quiet = limit.report(G, h, np.zeros(6), np.zeros(6), 1e-9)
    assert not quiet.intervened and not quiet.active and quiet.nominal_violation == 0.0


def test_filter_reports_each_limit_and_the_amount_it_changed() -> None:
    """Through the filter, only the violated limit intervenes, by the amount the nominal exceeded it."""
    from safety.chain import default_limits

    safety_filter = SafetyFilter(default_limits(_CONFIG), _STEP, eps=1e-6)
    state = _state(_MODEL.home())
    nominal = np.zeros(6)
    nominal[3] = 1.5 * _STEP[3]  # roll: only the velocity (step) bound is in the way
    result = safety_filter.filter(state, nominal)
    reports = {report.name: report for report in result.reports}
    assert result.interventions == ("joint_velocity",)
    assert reports["joint_velocity"].active
    assert reports["joint_velocity"].nominal_violation == pytest.approx(0.5 * _STEP[3])
    assert result.dq[3] == pytest.approx(_STEP[3])
    assert result.change == pytest.approx(0.5)  # in units of the joint's step
    assert not result.solved  # the clip was already optimal


def test_filter_solution_meets_the_soft_rows_when_it_can() -> None:
    """A nominal step out of the workspace is projected back: the box rows hold, no slack is used."""
    from safety.chain import default_limits

    safety_filter = SafetyFilter(default_limits(_CONFIG), _STEP, eps=1e-6)
    q = _MODEL.home()
    q[2] = 0.07  # the tip a few millimetres below the box's top face
    state = _state(q)
    nominal = np.zeros(6)
    nominal[2] = -_STEP[2]  # pull the shaft out by a full step: through the face
    result = safety_filter.filter(state, nominal)
    box = WorkspaceBoxLimit(np.asarray(_CONFIG.workspace_min_m), np.asarray(_CONFIG.workspace_max_m))
    G, h = box.compute_qp_inequalities(state)
    assert np.all(G @ result.dq <= h + 1e-6)
    reports = {report.name: report for report in result.reports}
    assert reports["workspace_box"].intervened and reports["workspace_box"].slack == pytest.approx(0.0, abs=1e-9)
    naive = SafetyFilter(default_limits(_CONFIG), _STEP, eps=1e-6, naive=True).filter(state, nominal)
    np.testing.assert_allclose(naive.dq, result.dq, atol=1e-3 * float(_STEP.max()))
