"""The exact one-row projection against the optimality conditions and against OSQP."""

from __future__ import annotations

import numpy as np
import pytest
import qpsolvers
from scipy import sparse

from safety.halfspace import project_onto_box_and_halfspace


def _project(
    point: np.ndarray, normal: np.ndarray, offset: float, lower: np.ndarray, upper: np.ndarray
) -> tuple[np.ndarray, float] | None:
    z = np.full(point.size, np.nan)
    lam = project_onto_box_and_halfspace(point, normal, offset, lower, upper, z)
    return None if np.isnan(lam) else (z, lam)


def _instance(rng: np.random.Generator, n: int = 6) -> tuple[np.ndarray, np.ndarray, float, np.ndarray, np.ndarray]:
    lower = -rng.uniform(0.0, 1.0, n)
    upper = rng.uniform(0.0, 1.0, n)
    lower[rng.random(n) < 0.1] = -np.inf
    upper[rng.random(n) < 0.1] = np.inf
    normal = rng.normal(size=n) * (rng.random(n) > 0.2)  # some coordinates the row does not involve
    point = rng.normal(scale=1.5, size=n)
    offset = float(rng.normal(scale=0.5))
    return point, normal, offset, lower, upper


def test_the_projection_meets_the_kkt_conditions() -> None:
    """z = clip(p - lam a), lam >= 0, a.z <= b, lam (a.z - b) = 0: necessary and sufficient for this QP."""
    rng = np.random.default_rng(7)
    solved = infeasible = 0
    for _ in range(5000):
        point, normal, offset, lower, upper = _instance(rng)
        result = _project(point, normal, offset, lower, upper)
        involved = normal != 0
        lowest = np.where(normal > 0, lower, upper)[involved]
        least = float(np.sum(normal[involved] * lowest))  # the row's smallest value over the box
        if result is None:
            assert least > offset - 1e-12  # no point of the box meets the row
            infeasible += 1
            continue
        z, lam = result
        solved += 1
        assert np.all(z >= lower) and np.all(z <= upper)
        assert lam >= 0.0
        assert normal @ z <= offset + 1e-9
        assert lam == 0.0 or abs(normal @ z - offset) <= 1e-9
        np.testing.assert_allclose(z, np.clip(point - lam * normal, lower, upper), atol=1e-12)
    assert solved > 3000 and infeasible > 50


# qpsolvers calls OSQP's solve() without raise_error, which OSQP warns about on every call.
@pytest.mark.filterwarnings("ignore::PendingDeprecationWarning")
def test_the_projection_matches_osqp_solved_tightly() -> None:
    rng = np.random.default_rng(11)
    for _ in range(200):
        point, normal, offset, lower, upper = _instance(rng)
        result = _project(point, normal, offset, lower, upper)
        if result is None:
            continue
        reference = qpsolvers.solve_qp(
            sparse.eye(6, format="csc"), -point, sparse.csc_matrix(normal[None, :]), np.array([offset]),
            lb=lower, ub=upper,
            solver="osqp", eps_abs=1e-10, eps_rel=1e-10, max_iter=200_000, polishing=True, verbose=False,
        )  # fmt: skip
        assert reference is not None
        np.testing.assert_allclose(result[0], reference, atol=1e-6)


@pytest.mark.parametrize("bad", ["point", "normal"])
def test_nan_gives_none_or_a_finite_answer_never_nan(bad: str) -> None:
    point, normal = np.ones(6), np.ones(6)
    if bad == "point":
        point[2] = np.nan
    else:
        normal[2] = np.nan
    result = _project(point, normal, 0.0, -np.ones(6), np.ones(6))
    assert result is None or np.all(np.isfinite(result[0]))
