"""The offline calibration: a bag synthesised from known parameters is fitted and the parameters recovered."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from bags import write_bag

from hardware_if.wrench.calibration import read_calibration
from hardware_if.wrench.fit import check_calibration, fit_calibration, prepare_log
from hardware_if.wrench.joint_logs import read_joint_log
from psm_control.effort_model import EffortRegressor, independent_columns
from tissue_retract.cli import main

RATE_HZ = 200.0
AMPLITUDE = np.array([0.5, 0.4, 0.05, 0.8, 0.6, 0.6])
CENTRE = np.array([0.0, 0.0, 0.14, 0.0, 0.0, 0.0])


def _trajectory(frequencies_hz: np.ndarray, phase: float, seconds: float = 8.0) -> tuple[np.ndarray, ...]:
    """A smooth excitation, two sines per joint: positions, velocities and accelerations (N, 6)."""
    t = np.arange(int(seconds * RATE_HZ)) / RATE_HZ
    w = 2 * np.pi * frequencies_hz
    q = CENTRE + AMPLITUDE * (0.7 * np.sin(np.outer(t, w) + phase) + 0.3 * np.sin(np.outer(t, 2.3 * w) + 2 * phase))
    qd = AMPLITUDE * (
        0.7 * w * np.cos(np.outer(t, w) + phase) + 0.3 * 2.3 * w * np.cos(np.outer(t, 2.3 * w) + 2 * phase)
    )
    qdd = -AMPLITUDE * (
        0.7 * w**2 * np.sin(np.outer(t, w) + phase) + 0.3 * (2.3 * w) ** 2 * np.sin(np.outer(t, 2.3 * w) + 2 * phase)
    )
    return q, qd, qdd


@pytest.fixture(scope="module")
def known() -> dict[str, object]:
    """Efforts of the project's effort model with a known parameter vector, on a fit and a held-out excitation."""
    regressor = EffortRegressor()
    rng = np.random.default_rng(3)
    fit_q, fit_qd, fit_qdd = _trajectory(np.array([0.31, 0.23, 0.41, 0.37, 0.29, 0.43]), 0.0)
    rows = regressor.matrix(fit_q, fit_qd, fit_qdd)
    columns = independent_columns(rows.reshape(-1, regressor.columns))
    truth = np.zeros(regressor.columns)
    truth[columns] = rng.normal(scale=0.05, size=len(columns))
    held_q, held_qd, held_qdd = _trajectory(np.array([0.27, 0.35, 0.33, 0.45, 0.39, 0.25]), 1.0)
    return {
        "fit": (fit_q, fit_qd, rows @ truth),
        "held_out": (held_q, held_qd, regressor.matrix(held_q, held_qd, held_qdd) @ truth),
        "truth": truth,
    }


def _bag(path: Path, data: tuple[np.ndarray, ...]) -> Path:
    q, qd, effort = data
    return write_bag(path, q, qd, effort, rate_hz=RATE_HZ)


def test_a_bag_from_known_parameters_is_fitted_and_they_are_recovered(known: dict, tmp_path: Path) -> None:
    """Fitted on a bag of synthesised efforts, the identifiable parameters come back; the held-out error vanishes."""
    fit = prepare_log(read_joint_log(_bag(tmp_path / "fit", known["fit"])))
    held_out = prepare_log(read_joint_log(_bag(tmp_path / "held", known["held_out"])))
    calibration, error = fit_calibration("PSM1", [fit], [held_out])
    truth = known["truth"]
    recovered = np.zeros_like(truth)
    recovered[list(calibration.columns)] = calibration.parameters
    # Parameters are identifiable only in combinations (base parameters): the recovered ones give the
    # true efforts at states of the excited range the fit never saw (to the accelerations' filtering).
    regressor = EffortRegressor()
    rng = np.random.default_rng(4)
    w = 2 * np.pi * 0.4  # rad/s: about the excitation's middle frequency
    for _ in range(50):
        u = rng.uniform(-1, 1, (3, 6))
        rows = regressor.rows(CENTRE + AMPLITUDE * u[0], AMPLITUDE * w * u[1], AMPLITUDE * w**2 * u[2])
        np.testing.assert_allclose(rows @ recovered, rows @ truth, atol=0.1 * np.abs(rows @ truth).max())
    assert error.summary()["rms_before_n"] > 20 * error.summary()["rms_after_n"], error.summary()
    assert calibration.error_bound_with_acceleration_n >= error.summary()["max_after_n"] or np.all(
        error.tip_speed_m_s > 0.1
    )


def test_the_command_fits_checks_and_writes_the_bins(known: dict, tmp_path: Path, capsys) -> None:
    """calibrate-wrench --from/--held-out writes a calibration; --check prints and writes the error, binned."""
    fit, held = _bag(tmp_path / "fit", known["fit"]), _bag(tmp_path / "held", known["held_out"])
    out = tmp_path / "wrench.json"
    assert main(["calibrate-wrench", "--from", str(fit), "--held-out", str(held), "--out", str(out)]) == 0
    calibration = read_calibration(out)
    assert (calibration.sensing, calibration.console) == ("logs: rosbag2", "unknown")  # a bag: any console's
    report = tmp_path / "check.json"
    assert main(["calibrate-wrench", "--check", str(out), "--from", str(held), "--json", str(report)]) == 0
    printed = capsys.readouterr().out
    assert "free-space force error" in printed and "cm" in printed and "m/s" in printed
    figures = json.loads(report.read_text())
    for key in ("rms_before_n", "max_before_n", "rms_after_n", "max_after_n", "by_depth", "by_speed"):
        assert key in figures
    assert sum(row["samples"] for row in figures["by_depth"]) == figures["samples"]
    assert sum(row["samples"] for row in figures["by_speed"]) == figures["samples"]
    summary = check_calibration(calibration, [prepare_log(read_joint_log(held))]).summary()
    assert figures["rms_after_n"] == pytest.approx(summary["rms_after_n"])


def test_a_bad_log_is_an_error_message_not_a_traceback(tmp_path: Path, capsys) -> None:
    """calibrate-wrench --from a bag without the arm's topic exits 1 naming the problem."""
    q = np.zeros((20, 6))
    bag = write_bag(tmp_path / "bag", q, q, q, topic="/PSM2/measured_js")
    assert main(["calibrate-wrench", "--from", str(bag), "--out", str(tmp_path / "w.json")]) == 1
    err = capsys.readouterr().err
    assert "/PSM1/measured_js" in err and "Traceback" not in err


def test_a_fit_the_held_out_log_does_not_support_is_not_written(known: dict, tmp_path: Path, capsys) -> None:
    """Held out on another arm's efforts (as after a deploy, with a load in the jaws), the fit lowers nothing:
    calibrate-wrench exits 1 saying why and what to do, and writes no calibration."""
    regressor = EffortRegressor()
    held_q, held_qd, _ = known["held_out"]
    other = np.random.default_rng(5).normal(scale=0.05, size=regressor.columns) * (known["truth"] != 0)
    held_qdd = np.gradient(held_qd, 1.0 / RATE_HZ, axis=0)
    held = _bag(tmp_path / "held", (held_q, held_qd, regressor.matrix(held_q, held_qd, held_qdd) @ other))
    fit, out = _bag(tmp_path / "fit", known["fit"]), tmp_path / "wrench.json"
    assert main(["calibrate-wrench", "--from", str(fit), "--held-out", str(held), "--out", str(out)]) == 1
    error = capsys.readouterr().err
    assert "a calibration must be at least 1.5 x lower" in error and "no calibration written" in error, error
    assert not out.exists()
