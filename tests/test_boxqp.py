"""The IK's exact box-constrained QP against the optimality conditions and against OSQP."""

from __future__ import annotations

import numpy as np
import pytest
import qpsolvers
from scipy import sparse

from psm_control.active_set import ActiveSetQp
from psm_control.boxqp import BOUNDED, FAILED, UNCONSTRAINED, solve_box_qp


def _instance(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """An IK-like problem: J^T W J + damping with joints of very different scales, and a box near x0."""
    J = rng.normal(size=(6, 6)) * rng.uniform(0.01, 1.0, size=6)
    P = (J.T * np.array([1.0, 1.0, 1.0, 0.01, 0.01, 0.01])) @ J + 1e-6 * np.eye(6)
    b = rng.normal(size=6) * 0.01
    centre, half = rng.normal(size=6) * 0.01, rng.uniform(0.0, 0.02, size=6)
    lower, upper = centre - half, centre + half
    lower[rng.random(6) < 0.1] = -np.inf
    upper[rng.random(6) < 0.1] = np.inf
    return P, b, lower, upper


def test_bounded_answers_meet_the_kkt_conditions() -> None:
    """Within the bounds; zero gradient where free, pointing out of the box where held: the optimum."""
    rng = np.random.default_rng(3)
    outcomes = {UNCONSTRAINED: 0, BOUNDED: 0, FAILED: 0}
    x = np.empty(6)
    for _ in range(5000):
        P, b, lower, upper = _instance(rng)
        outcome = solve_box_qp(P, b, lower, upper, x)
        outcomes[outcome] += 1
        if outcome == FAILED:
            continue
        assert np.all(x >= lower) and np.all(x <= upper)
        gradient = P @ x - b
        scale = max(np.abs(b).max(), np.abs(P @ x).max())
        at_lower, at_upper = x == lower, x == upper
        free = ~(at_lower | at_upper)
        assert np.all(np.abs(gradient[free]) <= 1e-9 * scale)
        assert np.all(gradient[at_lower] >= -1e-9 * scale)
        assert np.all(gradient[at_upper] <= 1e-9 * scale)
    assert outcomes[BOUNDED] > 4000 and outcomes[FAILED] < 250


# qpsolvers calls OSQP's solve() without raise_error, which OSQP warns about on every call.
@pytest.mark.filterwarnings("ignore::PendingDeprecationWarning")
def test_answers_match_osqp_solved_tightly() -> None:
    rng = np.random.default_rng(5)
    x = np.empty(6)
    compared = 0
    for _ in range(300):
        P, b, lower, upper = _instance(rng)
        if solve_box_qp(P, b, lower, upper, x) == FAILED:
            continue
        reference = qpsolvers.solve_qp(
            sparse.csc_matrix(P), -b, lb=lower, ub=upper, solver="osqp",
            eps_abs=1e-12, eps_rel=1e-12, max_iter=200_000, polishing=True, verbose=False,
        )  # fmt: skip
        assert reference is not None
        reference = np.clip(reference, lower, upper)

        def cost(z: np.ndarray, P: np.ndarray = P, b: np.ndarray = b) -> float:
            return float(0.5 * z @ P @ z - b @ z)

        assert cost(x) <= cost(reference) + 1e-15
        compared += 1
    assert compared > 250


def test_the_unconstrained_minimiser_is_kept_when_it_is_inside() -> None:
    P = np.diag([2.0, 4.0])
    x = np.empty(2)
    assert solve_box_qp(P, np.array([1.0, 1.0]), -np.ones(2), np.ones(2), x) == UNCONSTRAINED
    np.testing.assert_allclose(x, [0.5, 0.25])
    assert solve_box_qp(P, np.array([4.0, 1.0]), -np.ones(2), np.ones(2), x) == BOUNDED
    np.testing.assert_allclose(x, [1.0, 0.25])


@pytest.mark.parametrize(
    ("P", "b"),
    [
        (np.array([[1.0, 0.0], [0.0, -1.0]]), np.ones(2)),  # not positive definite
        (np.eye(2), np.array([np.nan, 1.0])),
        (np.array([[np.inf, 0.0], [0.0, 1.0]]), np.ones(2)),
    ],
)
def test_bad_problems_are_reported_failed_for_another_solver(P: np.ndarray, b: np.ndarray) -> None:
    x = np.empty(2)
    assert solve_box_qp(P, b, -np.ones(2), np.ones(2), x) == FAILED


def test_the_problems_it_gives_up_on_are_solved_exactly_by_the_ik_fallback() -> None:
    """Every instance the box QP reports FAILED is solved by the IK's fallback (DAQP), feasible and KKT to 1e-12."""
    rng = np.random.default_rng(3)
    fallback = ActiveSetQp(6, 0)
    x = np.empty(6)
    failed = 0
    for _ in range(5000):
        P, b, lower, upper = _instance(rng)
        if solve_box_qp(P, b, lower, upper, x) != FAILED:
            continue
        failed += 1
        solution = fallback.solve(P, -b, lower, upper)
        assert solution.status == "solved" and solution.x is not None
        assert solution.kkt.primal <= 1e-12 and solution.kkt.dual <= 1e-12
    assert failed > 20
