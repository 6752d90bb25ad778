"""The model of what a dVRK senses of the tissue force (sim.force_sensing) and its calibration."""

from __future__ import annotations

import numpy as np
import pytest

import sim.envs
from hardware_if.wrench.fit import (
    MIN_IMPROVEMENT,
    FreeSpaceError,
    PreparedLog,
    check_calibration,
    fit_calibration,
    prepare_log,
)
from hardware_if.wrench.joint_logs import JointLog
from policies.resolve import resolve_policy
from psm_control.errors import UnknownVariantError
from psm_control.robot import PsmModel
from safety.config import SafetyConfig
from sim.evaluation import force_limit_summary, run_episode
from sim.force_sensing import (
    SENSING_NAMES,
    ForceSensor,
    console_force,
    error_bound_n,
    sensing_params,
    tissue_bounds,
)
from sim.randomization import DEFAULT_RANGES
from tissue_retract.cli.bench_safety import _cell_group


def _poses(rng: np.random.Generator, count: int) -> list[np.ndarray]:
    model = PsmModel()
    poses = []
    for _ in range(count):
        q = model.home() + rng.uniform(-0.4, 0.4, 6)
        q[2] = rng.uniform(0.06, 0.18)
        poses.append(q)
    return poses


def test_ideal_reports_the_exact_force() -> None:
    """The ideal preset: the measured force is the tissue force, whatever the pose and motion."""
    configuration = PsmModel().configuration()
    sensor = ForceSensor(sensing_params("ideal"))
    rng = np.random.default_rng(1)
    for q in _poses(rng, 20):
        configuration.update(q)
        force = rng.normal(0.0, 1.0, 3)
        assert np.array_equal(sensor.measure(configuration, rng.normal(0, 1, 6), force, 0.01), force)


def test_the_console_inverts_the_tissue_load_exactly() -> None:
    """pinv(J^T) J^T f = f: the console's estimate carries the tissue force and adds only what it does not model."""
    configuration = PsmModel().configuration()
    rng = np.random.default_rng(2)
    for q in _poses(rng, 20):
        configuration.update(q)
        force = rng.normal(0.0, 1.0, 3)
        jacobian = configuration.base_jacobian()
        assert np.allclose(console_force(jacobian, jacobian[:3].T @ force), force, atol=1e-9)


def _smooth_motion(ticks: int, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """A Lissajous motion (q, qd) whose accelerations stay within the chain's default limits."""
    t_s = np.arange(ticks) * dt_s
    amplitude = np.array([0.4, 0.4, 0.05, 0.6, 0.6, 0.6])
    frequency = np.array([3.1, 2.3, 3.0, 6.0, 5.1, 4.3])  # rad/s
    q = PsmModel().home() + amplitude * np.sin(np.outer(t_s, frequency))
    q[:, 2] = 0.12 + amplitude[2] * np.sin(frequency[2] * t_s)
    return q, amplitude * frequency * np.cos(np.outer(t_s, frequency))


def test_dvrk_free_space_force_is_off_by_a_pose_dependent_error_within_its_bound() -> None:
    """dvrk in free space, moving within the chain's limits: never zero, changes with the motion, within
    error_bound_n; the calibrated bound far smaller, ideal zero."""
    configuration = PsmModel().configuration()
    bound = error_bound_n(sensing_params("dvrk"))
    sensor = ForceSensor(sensing_params("dvrk"), np.random.default_rng(3))
    dt_s = 0.01
    q, qd = _smooth_motion(600, dt_s)
    readings = []
    for k in range(len(q)):
        configuration.update(q[k])
        readings.append(sensor.measure(configuration, qd[k], np.zeros(3), dt_s))
    magnitudes = np.linalg.norm(readings, axis=1)
    assert magnitudes.min() > 0.05 and magnitudes.max() <= bound
    assert np.ptp(np.asarray(readings), axis=0).max() > 1.0  # moves with the pose and motion by newtons
    assert 0.0 < error_bound_n(sensing_params("dvrk-calibrated")) < bound / 3
    assert error_bound_n(sensing_params("ideal")) == 0.0


def test_the_bound_follows_the_chains_acceleration_limits() -> None:
    """The uncalibrated bound shrinks with the chain's acceleration limits (its inertia part), never below
    what the arm's gravity and friction give at rest."""
    full = error_bound_n(sensing_params("dvrk"))
    gentle = error_bound_n(sensing_params("dvrk"), SafetyConfig(acceleration_limit=(1.0, 1.0, 0.1, 4.0, 4.0, 4.0)))
    assert gentle < 0.7 * full
    assert gentle > 1.0


def test_calibrated_sensing_leaves_the_residual_and_the_tracking_errors_inertia() -> None:
    """dvrk-calibrated: an arm that tracks the commanded acceleration reads only the residual (as the same draw
    of dvrk's, less the arm's efforts); a tracking error adds the inertia of its acceleration."""
    configuration = PsmModel().configuration()
    calibrated = ForceSensor(sensing_params("dvrk-calibrated"), np.random.default_rng(7))
    lagging = ForceSensor(sensing_params("dvrk-calibrated"), np.random.default_rng(7))
    dt_s = 0.01
    q, qd = _smooth_motion(200, dt_s)
    tracked, lagged = [], []
    for k in range(len(q)):
        configuration.update(q[k])
        tracked.append(np.linalg.norm(calibrated.measure(configuration, qd[k], np.zeros(3), dt_s, qd[k])))
        lagged.append(np.linalg.norm(lagging.measure(configuration, qd[k], np.zeros(3), dt_s, 0.5 * qd[k])))
    assert max(tracked) < 3.0 * error_bound_n(sensing_params("dvrk-calibrated"))
    assert float(np.sqrt(np.mean(np.square(lagged)))) > 1.5 * float(np.sqrt(np.mean(np.square(tracked))))


def test_sensing_scale_scales_every_error_term() -> None:
    """force_sensing_scale 0 makes the dvrk model exact; 2 doubles its error (the same residual draw)."""
    configuration = PsmModel().configuration()
    configuration.update(np.array([0.2, -0.1, 0.1, 0.1, 0.2, 0.0]))
    params = sensing_params("dvrk")
    zero = ForceSensor(params.scaled(0.0))
    assert zero.params.exact and np.allclose(zero.measure(configuration, np.zeros(6), np.ones(3), 0.01), np.ones(3))
    assert params.scaled(1.0) is params
    qd = np.array([0.1, -0.2, 0.01, 0.3, 0.1, -0.1])
    once = ForceSensor(params, np.random.default_rng(8)).measure(configuration, qd, np.zeros(3), 0.0)
    twice = ForceSensor(params.scaled(2.0), np.random.default_rng(8)).measure(configuration, qd, np.zeros(3), 0.0)
    np.testing.assert_allclose(twice, 2.0 * once)
    assert error_bound_n(params.scaled(2.0)) == pytest.approx(2.0 * error_bound_n(params), rel=0.05)


def test_unknown_sensing_is_named() -> None:
    """An unknown preset lists the known ones."""
    with pytest.raises(UnknownVariantError, match="dvrk-calibrated"):
        sensing_params("perfect")
    assert SENSING_NAMES == ("ideal", "dvrk", "dvrk-calibrated")


def test_tissue_bounds_follow_the_ranges() -> None:
    """The stiffness bound is 2.64 E t at the stiffest range end; three times E, three times the bound."""
    stiffness, load = tissue_bounds(DEFAULT_RANGES)
    assert stiffness == pytest.approx(2.64 * 14e3 * 3e-3)
    assert 0.2 < load < 0.4
    stiffer = dict(DEFAULT_RANGES, tissue_youngs_modulus_kpa=(18.0, 42.0))
    assert tissue_bounds(stiffer)[0] == pytest.approx(3 * stiffness)
    # SafetyConfig's defaults (safety/ cannot import sim/) are the task flap's bounds, the load rounded up.
    assert SafetyConfig().tissue_stiffness_bound_n_per_m == pytest.approx(stiffness)
    assert load <= SafetyConfig().held_load_bound_n < load + 0.01


def test_calibration_fit_removes_the_models_errors() -> None:
    """Fitted on one free-space motion of the dvrk model over the workspace, the calibration leaves on another
    what the dvrk-calibrated preset says it leaves (the identification's residual, within 10 %): at least
    MIN_IMPROVEMENT x less than the console's error."""
    configuration = PsmModel().configuration()
    amplitude = np.array([0.5, 0.4, 0.04, 0.8, 0.6, 0.6])
    w = 2 * np.pi * np.array([0.13, 0.17, 0.11, 0.19, 0.23, 0.29])

    def trajectory(preset: str, phase: float) -> PreparedLog:
        t_s = np.arange(3000) * 0.01
        q = amplitude * np.sin(np.outer(t_s, w) + phase)
        q[:, 2] += 0.12
        qd = amplitude * w * np.cos(np.outer(t_s, w) + phase)
        sensor = ForceSensor(sensing_params(preset), np.random.default_rng(6))  # the same residual for both presets
        efforts = []
        for k in range(len(t_s)):
            configuration.update(q[k])
            efforts.append(sensor.efforts(configuration, qd[k], np.zeros(3), 0.01))
        return prepare_log(JointLog("sim", "live", t_s, q, qd, np.array(efforts)))

    calibration, _ = fit_calibration("PSM1", [trajectory("dvrk", 0.0)], [trajectory("dvrk", 1.0)])
    left = check_calibration(calibration, [trajectory("dvrk-calibrated", 1.0)])  # its console error: the residual
    residual = FreeSpaceError._rms(left.before_n)
    assert calibration.rms_after_n == pytest.approx(residual, rel=0.1), (calibration.rms_after_n, residual)
    assert calibration.rms_before_n >= MIN_IMPROVEMENT * calibration.rms_after_n, calibration
    assert calibration.error_bound_n >= calibration.error_bound_with_acceleration_n >= calibration.max_after_n


@pytest.mark.parametrize("sensing", ["ideal", "dvrk"])
def test_episodes_hold_the_true_force_against_the_travel_bound(sensing: str) -> None:
    """With the dvrk model the expert's true force stays within the travel bound it lifts under; exact: no bound."""
    env = sim.envs.make("target", force_sensing=sensing)
    try:
        act, reset = resolve_policy("scripted", env)
        results = [run_episode(env, act, reset, seed) for seed in range(2)]
    finally:
        env.close()
    assert all(r.success for r in results)
    ratios = [r.peak_force_over_travel_bound for r in results]
    worst = force_limit_summary([r.to_dict() for r in results])["worst_force_over_travel_bound"]
    if sensing == "ideal":
        assert ratios == [None, None] and worst is None
    else:
        assert all(ratio is not None and 0.0 < ratio <= 1.0 for ratio in ratios), ratios
        assert worst == max(r for r in ratios if r is not None)


def test_the_tissue_bounds_hold_where_bench_safety_came_nearest_them() -> None:
    """bench safety's nearest cell (SignFlipPull, MultiSite, bowel 5 N, dvrk sensing): within the travel bound."""
    rows = _cell_group("multisite", "bowel", True, ("sim.pulling:SignFlipPull",), 1, 91, "dvrk")
    assert [row["stiffness"] for row in rows] == [0.3, 1.0, 3.0]
    assert all(row["ratio"] <= 1.10 and row["force_over_travel_bound"] <= 1.0 for row in rows), rows
    assert max(row["force_over_travel_bound"] for row in rows) > 0.5  # the travel bound was in force, held to
