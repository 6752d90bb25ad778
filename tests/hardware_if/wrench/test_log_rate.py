"""A CSV log's sample rate: the layout's, unless the log's own positions and velocities say otherwise."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from arm_logs import arm_csv, arm_efforts, motion

from hardware_if.wrench.fit import (
    MIN_REGIME_SAMPLES,
    RETRACTION_TIP_SPEED_M_S,
    coverage_line,
    fit_calibration,
    prepare_log,
)
from hardware_if.wrench.joint_logs import LND_COUPLING, implied_rate_hz, read_joint_log


def _wpi_csv(path: Path, samples: int, rate_hz: float, speed: float, noise: float = 0.002) -> Path:
    """The arm's free-space log along the test motion at ``speed`` x, sampled at ``rate_hz``, as a WPI CSV."""
    q, qd, qdd = motion(samples, 0.3, rate_hz=rate_hz / speed)  # the same path, ``speed`` x as fast
    qd, qdd = qd * speed, qdd * speed**2
    effort = arm_efforts(q, qd, qdd, noise=noise)
    jaw, inverse, columns = np.zeros((samples, 1)), np.linalg.inv(LND_COUPLING), []
    for values, to_motor in ((q, inverse.T), (qd, inverse.T), (effort, LND_COUPLING)):
        full = np.hstack([values, jaw])
        full[:, 4:7] = full[:, 4:7] @ to_motor
        columns.append(full)
    np.savetxt(path, np.hstack(columns), delimiter=",")
    return path


def test_a_half_speed_log_recorded_at_half_the_rate_reads_at_its_own_rate(tmp_path: Path) -> None:
    """A WPI log whose loop ran at 100 Hz (its recording script slows the loop with the trajectory) reads at the
    100 Hz its positions and velocities imply, says so, and --rate still decides; a 200 Hz log keeps 200 Hz."""
    slow = read_joint_log(_wpi_csv(tmp_path / "half.csv", 600, 100.0, 0.5))
    assert slow.rate_hz == pytest.approx(100.0, rel=0.01)
    assert "from its positions and velocities" in slow.rate_note
    assert read_joint_log(tmp_path / "half.csv", rate_hz=200.0).rate_hz == pytest.approx(200.0)
    full = read_joint_log(arm_csv(tmp_path / "full.csv", 600, 0.3))
    assert full.rate_hz == pytest.approx(200.0) and full.rate_note == ""


def test_the_rate_is_not_inferred_from_joints_that_disagree() -> None:
    """Positions that do not follow their velocities, or joints that imply different rates, imply nothing."""
    rng = np.random.default_rng(2)
    assert implied_rate_hz(rng.normal(size=(300, 6)), rng.normal(size=(300, 6))) is None
    q, qd, _ = motion(300, 0.3, rate_hz=100.0)
    assert implied_rate_hz(q, qd) == pytest.approx(100.0, rel=0.01)
    qd[:, 2] *= 2.0  # the insertion's velocity in other units
    assert implied_rate_hz(q, qd) is None


def test_a_held_out_log_with_few_slow_samples_bounds_at_any_speed(tmp_path: Path) -> None:
    """A fast log held out with fewer than MIN_REGIME_SAMPLES samples at retraction speeds bounds the calibrated
    error by 1.25 x its largest at any speed; a slow one by 1.25 x its largest at retraction speeds."""
    for speed, few in ((4.0, True), (1.0, False)):
        log = prepare_log(read_joint_log(_wpi_csv(tmp_path / f"{speed}.csv", 600, 200.0, speed, noise=0.3)))
        calibration, error = fit_calibration("PSM1", [log], [log])
        slow = error.tip_speed_m_s <= RETRACTION_TIP_SPEED_M_S
        assert (np.count_nonzero(slow) < MIN_REGIME_SAMPLES) == few
        shown = error.after_n.max() if few else error.after_n[slow].max()
        assert calibration.error_bound_with_acceleration_n == pytest.approx(max(1.25 * shown, 0.5))
        assert calibration.error_bound_with_acceleration_n > 0.5


def test_the_coverage_line_names_speeds_poses_and_the_rate_taken(tmp_path: Path) -> None:
    """The coverage line names the logs' tip speeds, insertions and outer joints, and a rate taken from motion."""
    log = prepare_log(read_joint_log(_wpi_csv(tmp_path / "half.csv", 600, 100.0, 0.5)))
    line = coverage_line([log])
    assert line.startswith("tip speeds ") and "insertion" in line and "pitch" in line
    assert "half.csv read at 10" in line
