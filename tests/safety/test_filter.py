"""The safety filter's answer is the QP's exact solution: every row met, the KKT conditions checked independently."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import nnls

from psm_control.robot import PsmModel
from psm_control.urdf import GRASP_FRAME
from safety.chain import default_limits
from safety.config import SafetyConfig
from safety.filter import KKT_TOLERANCE, SafetyFilter
from safety.limits import FilterState
from tissue_retract.cli import bench_chain

_CONFIG = SafetyConfig()
_STEP = _CONFIG.velocity * _CONFIG.horizon_s
_MODEL = PsmModel(_CONFIG.spec)
_FILTER = SafetyFilter(default_limits(_CONFIG), _STEP)

fractions = st.lists(st.floats(0.05, 0.95), min_size=6, max_size=6)
unit = st.floats(-1.0, 1.0)


def _state(q: np.ndarray, qd: np.ndarray, force: np.ndarray, stiffness: float) -> FilterState:
    configuration = _MODEL.configuration(q)
    return FilterState(
        q=q,
        qd=qd,
        tool_position_m=configuration.measured_pose()[:3, 3],
        tool_jacobian=configuration.base_jacobian()[:3],
        grasp_jacobian=configuration.base_jacobian(GRASP_FRAME)[:3],
        retraction_force_n=force,
        stiffness_n_per_m=stiffness,
        dt=_CONFIG.control_period_s,
        jaw_rad=0.0,
    )


def _kkt_residuals(problem: object, z: np.ndarray) -> tuple[float, float]:
    """Largest row/bound violation and stationarity residual of ``z`` with the slack that is optimal for it.

    The slack of a soft limit is the least that meets its rows at ``z``; the multipliers are the
    non-negative ones on the constraints tight at the point that best cancel the cost's gradient
    (non-negative least squares), so a point that is not the optimum leaves a residual.
    """
    P, q, G, h, lb, ub = (getattr(problem, name) for name in ("P", "q", "G", "h", "lb", "ub"))
    dof = z.size
    rows_z = G[:, :dof] @ z - h
    sigma = np.zeros(q.size - dof)
    for k in range(sigma.size):
        own = G[:, dof + k] == -1.0
        if own.any():
            sigma[k] = max(0.0, float(rows_z[own].max()))
    x = np.concatenate([z, sigma])
    row_excess = G @ x - h
    violation = max(float(row_excess.max(initial=-np.inf)), float((lb - x).max()), float((x - ub).max()))
    tight = 1e-9
    normals = [G[r] for r in np.flatnonzero(row_excess >= -tight)]
    normals += [-np.eye(x.size)[i] for i in np.flatnonzero(x - lb <= tight)]
    normals += [np.eye(x.size)[i] for i in np.flatnonzero(ub - x <= tight)]
    gradient = P @ x + q
    if not normals:
        return violation, float(np.abs(gradient).max())
    _, residual = nnls(np.array(normals).T, -gradient)
    return violation, residual / max(1.0, float(np.abs(q).max()))


@settings(max_examples=300, deadline=None)
@given(
    fraction=fractions,
    speed=st.lists(unit, min_size=6, max_size=6),
    force_direction=st.lists(unit, min_size=3, max_size=3),
    force_over_limit=st.floats(0.0, 1.5),
    pull_m=st.floats(0.0, 0.004),
    sideways=st.lists(st.floats(-0.5, 0.5), min_size=6, max_size=6),
    stiffness=st.floats(50.0, 2000.0),
)
def test_every_answer_meets_every_row_and_the_kkt_conditions(
    fraction: list[float],
    speed: list[float],
    force_direction: list[float],
    force_over_limit: float,
    pull_m: float,
    sideways: list[float],
    stiffness: float,
) -> None:
    """On random states and pulls along the held force, the filtered step meets every row to 1e-9 and is optimal."""
    q = _MODEL.lower + np.asarray(fraction) * (_MODEL.upper - _MODEL.lower)
    qd = 0.2 * np.asarray(speed) * _CONFIG.velocity
    direction = np.asarray(force_direction)
    norm = float(np.linalg.norm(direction))
    direction = direction / norm if norm > 1e-6 else np.array([0.0, 0.0, 1.0])
    force = direction * force_over_limit * _CONFIG.effective_force_limit_n
    state = _state(q, qd, force, stiffness)
    # A pull: move the held point further along the force (into the force polytope's planes), plus a sideways part.
    pull = np.linalg.lstsq(state.grasp_jacobian, direction * pull_m, rcond=None)[0]
    nominal = pull + np.asarray(sideways) * _STEP
    result = _FILTER.filter(state, nominal)
    problem = _FILTER.problem(state, nominal)
    violation, stationarity = _kkt_residuals(problem, result.dq / _STEP)
    assert violation <= KKT_TOLERANCE
    assert stationarity <= 1e-8


def test_the_benchmark_pull_is_solved_exactly_on_every_tick() -> None:
    """bench chain's pull against the force polytope: the general solver runs, and no row is left violated by 1e-9."""
    _, _, stops, paths = bench_chain._run(False, 2000, 0)
    assert stops == 0
    assert paths.ticks == 2000 and paths.solver > 100 and paths.projected > 100
    assert paths.worst_row_violation <= KKT_TOLERANCE
