"""A deploy's recording names the force sensing it used: the simulation's preset, or the dVRK's with its calibration."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from hardware_if.deploy.meta import recording_meta
from hardware_if.deploy.options import DeployOptions
from hardware_if.deploy.run import deploy
from hardware_if.recording.replay import load_recording, summarize_recording
from hardware_if.wrench.calibration import WrenchCalibration
from psm_control.errors import ConfigurationError
from sim.force_sensing import error_bound_n, sensing_params


def test_a_sim_deploy_records_its_force_sensing_preset(tmp_path: Path) -> None:
    """deploy --target sim --force-sensing dvrk-calibrated: the meta says dvrk-calibrated, the error bound the
    filter was given (the preset's), no calibration file, and no stale top-level sensing keys; replay says so."""
    record = tmp_path / "run.mcap"
    options = DeployOptions(policy="scripted", target="sim", record=record, force_sensing="dvrk-calibrated")
    deploy(options, echo=lambda line: None)
    rec = load_recording(record)
    sensing = rec.meta["sensing"]
    assert sensing["force_sensing"] == "dvrk-calibrated", rec.meta
    assert sensing["force_sensing_error_n"] == pytest.approx(error_bound_n(sensing_params("dvrk-calibrated")))
    assert sensing["wrench_calibration"] is None
    assert "force_sensing" not in rec.meta and "wrench_calibration" not in rec.meta, rec.meta
    lines = summarize_recording(rec).lines()
    assert "force sensing: dvrk-calibrated (simulated); the safety filter was given a sensing error of 7.212 N" in (
        lines
    ), lines


def test_a_calibrated_dvrk_deploy_names_the_calibration_file_and_its_bounds(tmp_path: Path) -> None:
    """A dVRK deploy with a calibration: the meta says dvrk-calibrated with the file's path, digest and bounds
    and the error the filter was given, never ``ideal``; without one it says dvrk (the console's measured_cf)."""
    calibration = WrenchCalibration("PSM1", (0,), (0.5,), 4.0, 2.5, 3.0, 9.0, 0.8, 1.9, 1000)
    path = tmp_path / "wrench.json"
    calibration.write(path)
    options = DeployOptions(
        policy="scripted",
        target="dvrk",
        record=tmp_path / "run.mcap",
        force_sensing_error_n=2.5,
        force_sensing_source=f"dvrk measured_js efforts, calibrated by {path}",
        wrench_calibration=calibration,
        wrench_calibration_path=path,
        wrench_calibration_sha256=hashlib.sha256(path.read_bytes()).hexdigest(),
    )
    sensing = recording_meta(options)["sensing"]
    assert sensing["force_sensing"] == "dvrk-calibrated" and sensing["force_sensing_error_n"] == 2.5
    file = sensing["wrench_calibration"]
    assert file["path"] == str(path) and file["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    assert (file["error_bound_n"], file["error_bound_with_acceleration_n"]) == (4.0, 2.5)
    uncalibrated = DeployOptions(
        policy="scripted", target="dvrk", record=tmp_path / "b.mcap", force_sensing_error_n=9.0
    )
    assert recording_meta(uncalibrated)["sensing"] == {
        "force_sensing": "dvrk",
        "force_sensing_error_n": 9.0,
        "source": "dvrk measured_cf, uncompensated",
        "wrench_calibration": None,
    }


def test_a_force_sensor_deploy_names_it_and_its_bound_is_checked_with_the_options(tmp_path: Path) -> None:
    """deploy --force-sensor: the meta says force-sensor with the declared bound; the options refuse a sensor
    without a finite bound > 0, on the simulation, or beside a calibration, whoever builds them."""
    common = {"policy": "scripted", "record": tmp_path / "run.mcap"}
    options = DeployOptions(target="dvrk", force_sensing_error_n=0.2, force_sensor=True, **common)
    sensing = recording_meta(options)["sensing"]
    assert (sensing["force_sensing"], sensing["force_sensing_error_n"]) == ("force-sensor", 0.2)
    calibration = WrenchCalibration("PSM1", (0,), (0.5,), 4.0, 2.5, 3.0, 9.0, 0.8, 1.9, 1000)
    for field, extra in (
        ("force_sensing_error_n", {"target": "dvrk", "force_sensing_error_n": 0.0, "force_sensor": True}),
        ("force_sensing_error_n", {"target": "dvrk", "force_sensing_error_n": float("nan")}),
        ("force_sensor", {"target": "dvrk", "force_sensor": True}),
        ("force_sensor", {"target": "sim", "force_sensing_error_n": 0.2, "force_sensor": True}),
        ("force_sensor", {"target": "dvrk", "force_sensing_error_n": 0.2, "force_sensor": True,
                          "wrench_calibration": calibration}),
    ):  # fmt: skip
        with pytest.raises(ConfigurationError) as refused:
            DeployOptions(**common, **extra)
        assert refused.value.field == field, (extra, refused.value)
