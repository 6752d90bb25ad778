"""calibrate-wrench --check: a verdict on the file's bounds, judged inside the regimes they cover, and its exit; and
what a tare at the grasp would leave of the error."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from arm_logs import RATE_HZ, arm_bag

from psm_control.robot import PsmModel
from tests.conftest import run_cli

SAMPLES = 3000


@pytest.fixture(scope="module")
def fitted(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A calibration fitted on one log of the arm and held out on another; a third log of the same arm, and one of
    an arm whose efforts are 1.5 x as large (another arm, or a load in the jaws)."""
    folder = tmp_path_factory.mktemp("verdict")
    logs = {
        "fit": arm_bag(folder / "fit", SAMPLES, 0.0, noise=0.02),
        "held_out": arm_bag(folder / "held", SAMPLES, 1.0, noise=0.02),
        "same_arm": arm_bag(folder / "same", SAMPLES, 2.0, noise=0.02),
        "other_arm": arm_bag(folder / "other", SAMPLES, 2.0, noise=0.02, scale=1.5),
    }
    out = folder / "wrench.json"
    done = run_cli("calibrate-wrench", "--from", str(logs["fit"]), "--held-out", str(logs["held_out"]),
                   "--out", str(out))  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    return logs | {"calibration": out}


def test_a_bound_that_holds_is_said_and_exits_0(fitted: dict[str, Path], tmp_path: Path) -> None:
    """On another log of the same arm: bound_held true, the file's bounds by name, the samples outside their regime
    counted, the summary's figures kept, one verdict line, exit 0."""
    report = tmp_path / "check.json"
    done = run_cli("calibrate-wrench", "--check", str(fitted["calibration"]), "--from", str(fitted["same_arm"]),
                   "--json", str(report))  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    figures = json.loads(report.read_text())
    calibration = json.loads(fitted["calibration"].read_text())
    assert figures["bound_held"] is True
    assert figures["bound_n"] == {
        "error_bound_n": calibration["error_bound_n"],
        "error_bound_with_acceleration_n": calibration["error_bound_with_acceleration_n"],
    }
    for name in figures["bound_n"]:
        inside, outside = figures["regime_samples"][name], figures["outside_regime_samples"][name]
        assert inside > 0 and inside + outside == figures["samples"]
        assert figures["max_in_regime_n"][name] <= figures["bound_n"][name]
    for key in ("rms_before_n", "max_before_n", "rms_after_n", "max_after_n", "by_depth", "by_speed"):
        assert key in figures
    assert [line for line in done.stdout.splitlines() if line.startswith("bound held: ")], done.stdout


def test_a_bound_the_log_exceeds_is_said_and_exits_1(fitted: dict[str, Path], tmp_path: Path) -> None:
    """On a log whose efforts the calibration does not explain: bound_held false, the exceeding samples counted,
    BOUND EXCEEDED in one line, exit 1; the figures are still written."""
    report = tmp_path / "check.json"
    done = run_cli("calibrate-wrench", "--check", str(fitted["calibration"]), "--from", str(fitted["other_arm"]),
                   "--json", str(report))  # fmt: skip
    assert done.returncode == 1, done.stdout + done.stderr
    assert "Traceback" not in done.stderr
    figures = json.loads(report.read_text())
    assert figures["bound_held"] is False
    assert figures["exceeding_samples"]["error_bound_with_acceleration_n"] > 0
    line = next(line for line in done.stdout.splitlines() if line.startswith("BOUND EXCEEDED"))
    assert "error_bound_with_acceleration_n" in line and "above it" in line


def test_the_written_bounds_are_never_below_the_held_out_log_or_the_floor(fitted: dict[str, Path]) -> None:
    """The file's bounds cover what its held-out log showed in each bound's regime, and at least 0.5 N."""
    calibration = json.loads(fitted["calibration"].read_text())
    assert calibration["error_bound_with_acceleration_n"] >= max(calibration["max_after_retraction_speed_n"], 0.5)
    assert calibration["error_bound_n"] >= max(
        calibration["max_after_without_acceleration_n"], calibration["max_after_n"], 0.5
    )


def _with_tip_force(force_n: Callable[[np.ndarray], np.ndarray]) -> Callable[..., None]:
    """An ``arm_bag`` edit that adds to the efforts what a force on the tip ``force_n(t)`` (samples, 3) [N] makes:
    ``J^T [f; 0]``, so that the console's estimate reads it exactly."""

    def edit(q: np.ndarray, qd: np.ndarray, effort: np.ndarray) -> None:
        configuration = PsmModel().configuration()
        force = force_n(np.arange(len(q)) / RATE_HZ)
        for k in range(len(q)):
            configuration.update(q[k])
            effort[k] += configuration.base_jacobian()[:3].T @ force[k]

    return edit


def test_the_check_says_what_a_tare_at_the_grasp_would_leave(fitted: dict[str, Path], tmp_path: Path) -> None:
    """An error that stays put (a constant 1.5 N on the tip) is in the untared error but not in its change over a
    one-way pull; one that drifts (1.5 N/s) is in the change, in proportion to the pull's length. The same motion:
    the same pairs of samples."""

    def check(name: str, force_n: Callable[[np.ndarray], np.ndarray] | None) -> list[dict]:
        edit = _with_tip_force(force_n) if force_n is not None else None
        log = arm_bag(tmp_path / name, SAMPLES, 2.0, noise=0.002, edit=edit)
        report = tmp_path / f"{name}.json"
        done = run_cli(
            "calibrate-wrench", "--check", str(fitted["calibration"]), "--from", str(log), "--json", str(report)
        )
        assert "a tare at the grasp would leave the error's change over a one-way pull" in done.stdout, done.stdout
        return json.loads(report.read_text())["error_change_one_way"]

    clean = check("clean", None)
    offset = check("steady", lambda t: np.tile([1.5, 0.0, 0.0], (len(t), 1)))
    drift = check("drift", lambda t: np.outer(1.5 * t, [0.0, 1.0, 0.0]))
    assert [row["lag_s"] for row in clean] == [0.2, 0.5, 1.0, 2.0]
    for plain, put, moved in zip(clean, offset, drift, strict=True):
        assert plain["pairs"] > 0 and put["pairs"] == moved["pairs"] == plain["pairs"], (plain, put, moved)
        assert put["rms_change_n"] == pytest.approx(plain["rms_change_n"], rel=1e-6)
        assert put["max_change_n"] == pytest.approx(plain["max_change_n"], rel=1e-6)
        assert put["max_error_n"] > plain["max_error_n"] + 1.0
        assert abs(moved["max_change_n"] - 1.5 * plain["lag_s"]) <= plain["max_change_n"] + 1e-9


def test_the_check_says_how_each_joints_friction_differs(fitted: dict[str, Path], tmp_path: Path) -> None:
    """A log of the same arm with 0.1 N m more Coulomb friction on the pitch than the file's: the check reads +0.1
    on the pitch (half the difference of its mean error moving forward and back) and about none on the other
    joints, and the force that makes at the tip; a log of the arm as fitted reads about none anywhere."""

    def more_pitch_friction(q: np.ndarray, qd: np.ndarray, effort: np.ndarray) -> None:
        effort[:, 1] += 0.1 * np.sign(qd[:, 1])

    def check(name: str, edit: Callable[..., None] | None) -> dict[str, dict]:
        log = arm_bag(tmp_path / name, SAMPLES, 2.0, noise=0.002, edit=edit)
        report = tmp_path / f"{name}.json"
        done = run_cli(
            "calibrate-wrench", "--check", str(fitted["calibration"]), "--from", str(log), "--json", str(report)
        )
        assert "friction against the file's, by joint" in done.stdout, done.stdout
        return {row["joint"]: row for row in json.loads(report.read_text())["friction_shift"]}

    same, more = check("same", None), check("more", more_pitch_friction)
    assert list(same) == ["yaw", "pitch", "insertion", "roll", "wrist_pitch", "wrist_yaw"]
    for joint, row in same.items():
        assert row["samples_forward"] > 100 and row["samples_back"] > 100, row
        assert abs(row["shift"]) < 0.01, row
        assert abs(more[joint]["shift"] - (0.1 if joint == "pitch" else 0.0)) < 0.01, more[joint]
    assert more["pitch"]["unit"] == "N m" and more["insertion"]["unit"] == "N"
    assert more["pitch"]["tip_force_n"] > 10 * same["pitch"]["tip_force_n"] > 0.0


def test_bench_sensing_says_what_the_arms_own_parameters_leave(fitted: dict[str, Path], tmp_path: Path) -> None:
    """bench sensing with the calibration: beside the calibrated error, what the identified arm's exact parameters
    leave on the log. On a log of that arm's efforts they leave as little as the calibration fitted on another of its
    logs, and much less than on a log of an arm whose efforts are 1.5 x as large; the column is in the table and the
    JSON."""
    report = tmp_path / "bench.json"
    done = run_cli("bench", "sensing", "--from", str(fitted["same_arm"]), str(fitted["other_arm"]), "--calibration",
                   str(fitted["calibration"]), "--draws", "1", "--json", str(report))  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    logs = json.loads(report.read_text())["logs"]
    same, other = (logs[str(fitted[name])]["calibrated"] for name in ("same_arm", "other_arm"))
    for entry in (same, other):
        assert entry["columns"][-1] == "wpi-psm, exact", entry["columns"]
    exact, calibrated = same["rms_n"]["wpi-psm, exact"], same["rms_n"]["logged, calibrated"]
    assert 0.0 < exact <= 1.2 * calibrated  # on the arm's own log, as little as the calibration fitted on it leaves
    assert other["rms_n"]["wpi-psm, exact"] > 2 * exact
    assert "wpi-psm, exact" in done.stdout
