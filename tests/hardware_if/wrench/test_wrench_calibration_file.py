"""The calibration file: what it records of its fit, and what a deploy refuses before it records anything."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hardware_if.wrench.calibration import WrenchCalibration, read_calibration
from psm_control.errors import ConfigurationError
from tests.conftest import run_cli

#: A consistent calibration: one offset column, a 1 N bound over its held-out 0.2 N, fitted on sim-dvrk.
GOOD = WrenchCalibration("PSM1", (0,), (0.01,), 1.0, 0.5, 1.0, 2.0, 0.1, 0.2, 1000, "measured_js", "sim-dvrk")


def _file(tmp_path: Path, **changes: object) -> Path:
    data = {"kind": "wrench_calibration", **GOOD.__dict__, **changes}
    path = tmp_path / "wrench.json"
    path.write_text(json.dumps({k: v for k, v in data.items() if v is not None}))
    return path


def test_a_written_calibration_reads_back_with_its_sensing_and_console(tmp_path: Path) -> None:
    """write then read: the same calibration, with the sensing and the console it was fitted on."""
    GOOD.write(tmp_path / "w.json")
    assert read_calibration(tmp_path / "w.json", "PSM1") == GOOD
    assert GOOD.origin == "PSM1 on sim-dvrk, measured_js"


@pytest.mark.parametrize(
    ("changes", "reason"),
    [
        ({"arm": "PSM2"}, "a calibration of PSM1 (this one is PSM2's)"),
        ({"error_bound_n": 0.0, "error_bound_with_acceleration_n": 0.0}, "at least its own max_after_n"),
        ({"error_bound_n": 0.3}, "at least its own error_bound_with_acceleration_n"),
        ({"error_bound_n": 1e6}, "an error_bound_n the safety filter takes"),
        ({"error_bound_n": float("nan")}, "a finite, non-negative error_bound_n"),
        (
            {"parameters": [0.0], "error_bound_n": 0, "error_bound_with_acceleration_n": 0, "max_before_n": 0,
             "rms_before_n": 0, "rms_after_n": 0, "max_after_n": 0, "sensing": "ideal"},
            "sim-dvrk --wrench ideal",
        ),
        ({"sensing": None}, "re-run calibrate-wrench"),
        ({"console": None}, "re-run calibrate-wrench"),
    ],
)  # fmt: skip
def test_a_calibration_not_to_trust_is_refused_naming_the_file(
    tmp_path: Path, changes: dict[str, object], reason: str
) -> None:
    """Another arm's, a bound its fit contradicts or beyond the filter's, exact-force, older files: named refusals."""
    path = _file(tmp_path, **changes)
    with pytest.raises(ConfigurationError) as caught:
        read_calibration(path, "PSM1")
    assert reason in str(caught.value) and str(path) in str(caught.value), caught.value


def test_a_bound_below_the_floor_or_its_held_out_maximum_is_refused_even_for_a_check(tmp_path: Path) -> None:
    """A 0 N bound (an exact console's fit) is refused for a check on logs too, and a bound below the held-out
    maximum of the regime it covers is refused; above both, the file reads for a check."""
    zeros = dict.fromkeys(("error_bound_n", "error_bound_with_acceleration_n", "max_after_n", "rms_after_n"), 0.0)
    with pytest.raises(ConfigurationError, match=r"error_bound_n of at least 0\.5 N \(this file has 0 N\)"):
        read_calibration(_file(tmp_path, sensing="ideal", **zeros), exact_console=True)
    with pytest.raises(ConfigurationError, match="at least its own held-out max_after_retraction_speed_n"):
        read_calibration(_file(tmp_path, max_after_retraction_speed_n=0.6), exact_console=True)
    with pytest.raises(ConfigurationError, match="at least its own held-out max_after_without_acceleration_n"):
        read_calibration(_file(tmp_path, max_after_without_acceleration_n=1.5), exact_console=True)
    assert read_calibration(_file(tmp_path, max_after_retraction_speed_n=0.4), exact_console=True).samples == 1000


def test_a_file_over_one_mebibyte_is_refused_by_its_size(tmp_path: Path) -> None:
    """A calibration file is read only up to 1 MiB: a larger one is refused by its size, not parsed."""
    path = tmp_path / "huge.json"
    path.write_bytes(b" " * (2 * 1024 * 1024))
    with pytest.raises(ConfigurationError, match=r"at most 1 MiB.*this one is 2\.0 MiB"):
        read_calibration(path, "PSM1")


@pytest.mark.parametrize(
    ("changes", "reason"),
    [({"arm": "PSM2"}, "this one is PSM2's"), ({"error_bound_n": 1e6}, "(this file has 1e+06 N)")],
)
def test_deploy_refuses_a_calibration_before_it_records(
    tmp_path: Path, changes: dict[str, object], reason: str
) -> None:
    """deploy --wrench-calibration with a file not to trust: one line naming the file, exit 1, no recording."""
    path = _file(tmp_path, **changes)
    record = tmp_path / "run.mcap"
    done = run_cli(
        "deploy", "--target", "dvrk", "--policy", "scripted", "--task", "lift", "--site", "0", "0", "0.1",
        "--wrench-calibration", str(path), "--record", str(record), "--wait", "1",
    )  # fmt: skip
    assert done.returncode == 1, done.stdout + done.stderr
    assert f"--wrench-calibration='{path}'" in done.stderr and reason in done.stderr, done.stderr
    assert "Traceback" not in done.stderr, done.stderr
    assert not record.exists()
