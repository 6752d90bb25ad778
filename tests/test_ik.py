"""Differential IK: convergence to a reachable goal, its residual, its bounds, and infeasible input."""

from __future__ import annotations

import numpy as np
import pytest
import qpsolvers

from psm_control.errors import InfeasibleProblemError
from psm_control.ik import DifferentialIk
from psm_control.robot import PsmModel


def _goal(model: PsmModel, q: np.ndarray) -> np.ndarray:
    return model.configuration(q).local_pose()


def test_repeated_steps_converge_to_a_reachable_goal(classic: PsmModel) -> None:
    """Iterating IK steps from home reaches a reachable goal pose to 1e-6 m and 1e-4 rad."""
    ik = DifferentialIk(eps_abs=1e-6, eps_rel=1e-6)
    target = classic.home() + np.array([0.1, -0.08, 0.02, 0.2, -0.1, 0.15])
    goal = _goal(classic, target)
    configuration = classic.configuration(classic.home())
    step = np.full(6, 0.05)
    result = None
    for _ in range(200):
        q = configuration.q
        result = ik.solve(
            configuration, goal, np.maximum(classic.lower - q, -step), np.minimum(classic.upper - q, step)
        )
        configuration.update(q + result.dq)
        if result.position_error_m < 1e-7 and result.orientation_error_rad < 1e-5:
            break
    assert result is not None
    final = ik.errors(configuration, goal)
    assert np.linalg.norm(final[:3]) < 1e-6
    assert np.linalg.norm(final[3:]) < 1e-4


def test_residual_is_the_weighted_linearised_error(classic: PsmModel) -> None:
    """The reported residual equals ||W^(1/2) (J dq - e)|| computed independently."""
    ik = DifferentialIk()
    configuration = classic.configuration(classic.home())
    goal = _goal(classic, classic.home() + np.array([0.02, 0.01, 0.005, 0.0, 0.05, 0.0]))
    lower, upper = np.full(6, -0.01), np.full(6, 0.01)  # tight: the bounds bind, the QP runs
    result = ik.solve(configuration, goal, lower, upper)
    J = configuration.local_jacobian()
    error = ik.errors(configuration, goal)
    expected = np.linalg.norm(np.sqrt(ik.weights) * (J @ result.dq - error))
    assert result.residual == pytest.approx(expected, rel=1e-9, abs=1e-12)
    assert np.all(result.dq >= lower) and np.all(result.dq <= upper)
    assert np.any(np.isclose(np.abs(result.dq), 0.01))


def test_exact_solve_agrees_with_a_rebuilt_osqp_solve(classic: PsmModel) -> None:
    """The exact solve and the naive reference (OSQP through qpsolvers, rebuilt) give the same bounded step."""
    rng = np.random.default_rng(3)
    kept, naive = DifferentialIk(eps_abs=1e-7, eps_rel=1e-7), DifferentialIk(eps_abs=1e-7, eps_rel=1e-7, naive=True)
    for _ in range(20):
        q = classic.home() + rng.uniform(-0.3, 0.3, 6) * np.array([1, 1, 0.1, 1, 1, 1])
        configuration = classic.configuration(q)
        goal = _goal(classic, q + rng.uniform(-0.1, 0.1, 6))
        lower, upper = np.full(6, -0.02), np.full(6, 0.02)
        np.testing.assert_allclose(
            kept.solve(configuration, goal, lower, upper).dq,
            naive.solve(configuration, goal, lower, upper).dq,
            atol=1e-4,
        )


def test_inconsistent_bounds_raise_the_project_error_with_the_problem(classic: PsmModel) -> None:
    """Bounds with lower above upper raise InfeasibleProblemError carrying an inspectable qpsolvers.Problem."""
    ik = DifferentialIk()
    configuration = classic.configuration(classic.home())
    lower = np.full(6, 0.01)
    upper = np.full(6, -0.01)
    with pytest.raises(InfeasibleProblemError) as info:
        ik.solve(configuration, _goal(classic, classic.home()), lower, upper)
    assert info.value.stage == "ik"
    assert isinstance(info.value.problem, qpsolvers.Problem)
    np.testing.assert_array_equal(info.value.problem.lb, lower)
