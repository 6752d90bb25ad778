"""The exact active-set QP solver and its KKT check: answers are optima, and the check catches what is not."""

from __future__ import annotations

import numpy as np
import pytest

from psm_control.active_set import ActiveSetQp, kkt_residual


def _instance(rng: np.random.Generator, n: int = 8, m: int = 30) -> tuple[np.ndarray, ...]:
    """A filter-like QP: a diagonal cost of mixed scales, a box, and unit rows of which some cut the box."""
    H = np.diag(rng.uniform(0.5, 1e3, n))
    f = rng.normal(size=n) * np.diag(H)
    lower, upper = -rng.uniform(0.1, 1.0, n), rng.uniform(0.1, 1.0, n)
    A = rng.normal(size=(m, n))
    A /= np.linalg.norm(A, axis=1)[:, None]
    row_upper = rng.uniform(0.0, 0.5, m)  # x = 0 meets every row: feasible
    row_lower = np.full(m, -np.inf)
    return H, f, lower, upper, A, row_lower, row_upper


def test_answers_meet_the_kkt_conditions_to_rounding() -> None:
    """On random QPs with bounds and rows, every answer is feasible and optimal to 1e-12 (warm and cold alike)."""
    rng = np.random.default_rng(7)
    qp = ActiveSetQp(8, 30)
    for _ in range(500):
        H, f, lower, upper, A, row_lower, row_upper = _instance(rng)
        warm = qp.solve(H, f, lower, upper, A, row_lower, row_upper)
        assert warm.status == "solved" and warm.x is not None
        assert warm.kkt.primal <= 1e-12 and warm.kkt.dual <= 1e-12
        cold = ActiveSetQp(8, 30).solve(H, f, lower, upper, A, row_lower, row_upper)
        assert cold.x is not None
        np.testing.assert_allclose(warm.x, cold.x, atol=1e-12)


def test_the_answer_beats_every_feasible_point_nearby() -> None:
    """No feasible random perturbation of an answer has a lower cost (an optimum, checked without multipliers)."""
    rng = np.random.default_rng(11)
    qp = ActiveSetQp(8, 30)
    for _ in range(50):
        H, f, lower, upper, A, row_lower, row_upper = _instance(rng)
        x = qp.solve(H, f, lower, upper, A, row_lower, row_upper).x
        assert x is not None
        best = 0.5 * x @ H @ x + f @ x
        for _ in range(200):
            y = x + rng.normal(size=8) * 10.0 ** rng.uniform(-6, -1)
            if np.all(y >= lower) and np.all(y <= upper) and np.all(A @ y <= row_upper):
                assert 0.5 * y @ H @ y + f @ y >= best - 1e-12


def test_the_check_catches_a_point_off_the_optimum_and_wrong_multipliers() -> None:
    """Projection of (2, 2) onto x1 + x2 <= 1: exact x and multiplier pass; moved, unbalanced or wrong-signed fail."""
    H, f = np.eye(2), np.array([-2.0, -2.0])
    A = np.array([[1.0, 1.0]])
    lower, upper = np.full(2, -1e30), np.full(2, 1e30)
    row_lower, row_upper = np.array([-1e30]), np.array([1.0])
    x, multipliers = np.array([0.5, 0.5]), np.array([0.0, 0.0, 1.5])
    assert kkt_residual(H, f, A, lower, upper, row_lower, row_upper, x, multipliers) == (0.0, 0.0)
    primal, _ = kkt_residual(H, f, A, lower, upper, row_lower, row_upper, x + 1e-6, multipliers)
    assert primal == pytest.approx(2e-6)
    _, dual = kkt_residual(H, f, A, lower, upper, row_lower, row_upper, x - 1e-3, multipliers)
    assert dual > 1e-4  # the row is no longer tight, yet carries a multiplier
    _, dual = kkt_residual(H, f, A, lower, upper, row_lower, row_upper, x, np.array([0.0, 0.0, 1.4]))
    assert dual > 1e-2
    _, dual = kkt_residual(H, f, A, lower, upper, row_lower, row_upper, x, np.array([0.0, 0.0, -1.5]))
    assert dual > 1.0


def test_bounds_only_and_a_reset_give_the_same_answer() -> None:
    """With no rows (the IK's case) it is a box QP; after reset() the same data give the same answer."""
    rng = np.random.default_rng(2)
    J = rng.normal(size=(6, 6))
    H = J.T @ J + 1e-6 * np.eye(6)
    f = rng.normal(size=6)
    lower, upper = np.full(6, -0.1), np.full(6, 0.1)
    lower[0] = -np.inf
    qp = ActiveSetQp(6, 0)
    first = qp.solve(H, f, lower, upper)
    qp.reset()
    again = qp.solve(H, f, lower, upper)
    assert first.status == again.status == "solved" and first.x is not None and again.x is not None
    np.testing.assert_array_equal(first.x, again.x)
    assert np.all(first.x <= upper + 1e-12) and np.all(first.x >= lower - 1e-12)


def test_infeasible_rows_are_a_failed_solve_not_an_answer() -> None:
    """Rows that no point of the box meets give no x and say why."""
    qp = ActiveSetQp(2, 1)
    A = np.array([[1.0, 1.0]])
    solution = qp.solve(np.eye(2), np.zeros(2), np.zeros(2), np.ones(2), A, np.array([-np.inf]), np.array([-1.0]))
    assert solution.x is None
    assert solution.status == "primal infeasible"
