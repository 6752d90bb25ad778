"""Each safety limit alone: its rows, its per-joint bounds, and what the filter reports about it."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psm_control.robot import PsmModel
from psm_control.urdf import GRASP_FRAME
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
        configuration.base_jacobian(GRASP_FRAME)[:3],
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


def _force_limit() -> RetractionForceLimit:
    return RetractionForceLimit(3.0, _CONFIG.acceleration, _CONFIG.jerk)


def test_force_rows_are_the_tangent_planes_of_the_limit_one_along_the_force() -> None:
    """Rows K u^T J_grasp dq <= F_max - u^T F, 32 unit normals, the first along F; off with the jaw open, no force."""
    limit = _force_limit()
    state = _state(_MODEL.home(), force=np.array([0.0, 2.0, 0.0]))
    G, h = limit.compute_qp_inequalities(state)
    assert G.shape == (32, 6) and h.shape == (32,)
    normals = limit.directions(state.retraction_force_n)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0)
    np.testing.assert_allclose(normals[0], [0.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(G, 400.0 * normals @ state.grasp_jacobian)
    np.testing.assert_allclose(h, 3.0 - normals @ state.retraction_force_n)
    assert h[0] == pytest.approx(1.0)
    opened = _state(_MODEL.home(), force=np.array([0.0, 0.0, 0.01]))._replace(jaw_rad=0.6)
    G, h = limit.compute_qp_inequalities(opened)
    assert np.all(G == 0.0) and np.all(h == np.inf)


@settings(max_examples=300, deadline=None)
@given(
    force=st.lists(st.floats(-4.0, 4.0), min_size=3, max_size=3),
    step=st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3),
)
def test_any_step_the_rows_allow_keeps_the_predicted_force_within_1_084_of_the_limit(
    force: list[float], step: list[float]
) -> None:
    """From a force within the limit, any grasp displacement meeting the 32 rows predicts |F + K dx| <= 1.084 F_max."""
    limit = _force_limit()
    F = np.asarray(force)
    if np.linalg.norm(F) > 3.0:
        F *= 3.0 / np.linalg.norm(F)
    normals = limit.directions(F)
    dx = np.asarray(step) * 0.01
    predicted = F + 400.0 * dx
    if np.all(normals @ predicted <= 3.0):
        assert np.linalg.norm(predicted) <= 1.084 * 3.0


def test_above_the_limit_standing_still_breaks_the_rows_and_backing_off_meets_them() -> None:
    """At 1.5 x the limit, dq = 0 violates the row along the force; a step against the force meets them all."""
    limit = _force_limit()
    state = _state(_MODEL.home(), force=np.array([0.0, 0.0, 4.5]))
    G, h = limit.compute_qp_inequalities(state)
    assert h[0] < 0.0  # standing still is not enough
    back = np.linalg.lstsq(state.grasp_jacobian, np.array([0.0, 0.0, -1.6 / 400.0]), rcond=None)[0]
    assert np.all(G @ back <= h + 1e-9)


def test_motion_under_way_counts_with_its_stopping_distance() -> None:
    """A joint moving towards more force leaves less room: its braking distance enters every row."""
    limit = _force_limit()
    still = _state(_MODEL.home(), force=np.array([0.0, 0.0, 1.0]))
    moving_qd = np.zeros(6)
    moving_qd[2] = -0.05  # insertion out of the body: the grasp point rises, along the force
    moving = still._replace(qd=moving_qd)
    _, h_still = limit.compute_qp_inequalities(still)
    h_still = h_still.copy()
    _, h_moving = limit.compute_qp_inequalities(moving)
    travel = limit.stopping_displacement(moving_qd)
    assert travel[2] < 0.0 and travel[2] == pytest.approx(
        -(0.05**2 / (2 * _CONFIG.acceleration[2]) + 0.05 * _CONFIG.acceleration[2] / (2 * _CONFIG.jerk[2]))
    )
    shift = 400.0 * limit.directions(still.retraction_force_n) @ (still.grasp_jacobian @ travel)
    np.testing.assert_allclose(h_moving, h_still - shift)
    assert h_moving[0] < h_still[0]


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
