"""The dVRK's force sensing over loopback: sim-dvrk's measured_cf and a calibration fitted against it."""

from __future__ import annotations

import hashlib
import re
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import rclpy
from ros_process import start_sim_dvrk, stop, wait_until

from hardware_if.client.psm_client import PsmClient
from hardware_if.recording.replay import load_recording
from hardware_if.wrench.calibration import WrenchCalibration, read_calibration
from hardware_if.wrench.fit import MIN_IMPROVEMENT
from hardware_if.wrench.joint_logs import read_joint_log
from psm_control.effort_model import EffortRegressor


@pytest.fixture
def homed_sim(ros_env: dict[str, str]) -> Iterator[subprocess.Popen[str]]:
    """A sim-dvrk with its default force sensing (the console's estimate), enabled and homed."""
    process = start_sim_dvrk(ros_env)
    rclpy.init()
    try:
        with PsmClient("PSM1", node_name="test_force_sensing_homer", deadman_timeout_s=0.5) as client:
            client.wait_for_measurement(timeout_s=60.0)
            client.enable(timeout_s=30.0)
            client.home(timeout_s=30.0)
            measured = client.measure()
            assert np.all(np.isfinite(measured.force_n)) and np.linalg.norm(measured.force_n) > 0.05, measured
    finally:
        rclpy.shutdown()
    yield process
    output = stop(process)
    assert process.returncode == 0, output


def test_calibrate_wrench_fits_the_arm_or_refuses_by_name(
    homed_sim: subprocess.Popen[str], ros_env: dict[str, str], tmp_path: Path
) -> None:
    """calibrate-wrench against sim-dvrk: the excitation runs its course (the console's free-space force is
    error, not a tissue's: taken for one, the force limit steers the tool out of the workspace box) and the
    fit lowers the held-out free-space RMS error. At MIN_IMPROVEMENT x or more (2.6-3.6 x measured on the
    2-core machine) it writes a file that reads; below it, which a machine loaded by the whole suite can cause
    (late set-points make the kinematic console's accelerations jerk, as a loaded control computer would a
    real arm's), it refuses by name and writes nothing. Either way the excitation it recorded (--record) is a
    bag of both trajectories, and the offline fit of the bag tells the same. sim-dvrk's console is the
    identified real arm's with its residual, which no calibration removes."""
    out = tmp_path / "wrench.json"
    bag = tmp_path / "excitation"
    command = [sys.executable, "-m", "tissue_retract", "calibrate-wrench", "--domain-id", ros_env["ROS_DOMAIN_ID"]]
    result = subprocess.run(
        [*command, "--out", str(out), "--duration", "20", "--wait", "60", "--record", str(bag)],
        env=ros_env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    output = result.stdout + result.stderr
    match = re.search(r"\((\d+) samples\): before RMS ([\d.]+) N, max [\d.]+ N; after RMS ([\d.]+) N", result.stdout)
    assert match is not None, output
    held_out_samples, before, after = int(match.group(1)), float(match.group(2)), float(match.group(3))
    assert before > after, output
    assert f"excitation recorded to {bag}" in result.stdout, output
    log = read_joint_log(bag)  # both excitations one after the other
    assert log.layout == "rosbag2" and len(log.t_s) > held_out_samples, (len(log.t_s), held_out_samples)
    if before >= MIN_IMPROVEMENT * after:
        assert result.returncode == 0, output
        calibration = read_calibration(out, "PSM1")
        assert (calibration.sensing, calibration.console) == ("measured_js", "sim-dvrk"), calibration
        assert "(fitted on PSM1 on sim-dvrk, measured_js)" in result.stdout, output
        assert calibration.rms_before_n == pytest.approx(before, abs=1e-3)
        assert 0.0 < calibration.error_bound_with_acceleration_n <= calibration.error_bound_n
        assert calibration.max_after_n <= calibration.error_bound_n
        # The bound a deploy trusts covers the held-out error as a deploy computes it (the chain's commanded
        # acceleration, the console's velocity), not only as the fit does.
        deployed = re.search(r"as a deploy computes it .*?: largest held-out error ([\d.]+) N", result.stdout)
        assert deployed is not None, output
        assert calibration.error_bound_with_acceleration_n >= 1.25 * float(deployed.group(1)) - 1e-3, output
    else:
        assert result.returncode == 1 and not out.exists(), output
        assert "a calibration must be at least 1.5 x lower" in result.stderr, output
        assert "no calibration written" in result.stderr, output
    offline = tmp_path / "offline.json"
    refit = subprocess.run(
        [sys.executable, "-m", "tissue_retract", "calibrate-wrench", "--from", str(bag), "--out", str(offline)],
        env=ros_env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    match = re.search(r"console RMS ([\d.]+) N, max [\d.]+ N; calibrated RMS ([\d.]+) N", refit.stdout)
    assert match is not None, refit.stdout + refit.stderr
    assert float(match.group(1)) > float(match.group(2)), refit.stdout
    assert refit.returncode == (0 if offline.exists() else 1), refit.stdout + refit.stderr


@pytest.mark.slow
def test_calibrate_wrench_needs_an_enabled_arm(ros_env: dict[str, str], tmp_path: Path) -> None:
    """A disabled console: calibrate-wrench commands nothing, says what to do, exits 1, writes no file."""
    process = start_sim_dvrk(ros_env)
    try:
        command = [sys.executable, "-m", "tissue_retract", "calibrate-wrench", "--domain-id", ros_env["ROS_DOMAIN_ID"]]
        result = subprocess.run(
            [*command, "--out", str(tmp_path / "w.json"), "--wait", "20"],
            env=ros_env,
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
        )
    finally:
        stop(process)
    assert result.returncode == 1, result.stdout + result.stderr
    assert "tissue-retract ready-arm --arm PSM1 enables and homes it" in result.stderr
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "w.json").exists()
    assert wait_until(lambda: process.poll() is not None, timeout_s=10.0)


def test_a_calibration_that_overflows_holds_the_arm_and_replay_reads_the_recording(
    ros_env: dict[str, str], tmp_path: Path
) -> None:
    """Finite but huge parameters give a force that is no measurement: a named hold, nothing sent, a readable run
    whose meta names the sensing the deploy used: dvrk-calibrated, with the file, its digest and its bounds."""
    offset_column = EffortRegressor().friction_start + 3 * 2 + 2  # the insertion's effort offset
    calibration = WrenchCalibration("PSM1", (offset_column,), (1e300,), 1.0, 1.0, 1.0, 2.0, 0.1, 0.2, 1000)
    calibration.write(tmp_path / "wrench.json")
    (tmp_path / "deadman.toml").write_text("deadman_timeout_s = 0.5\n")  # a loaded machine: see test_deploy.py
    record = tmp_path / "run.mcap"
    sim = start_sim_dvrk(ros_env, "--task", "lift")
    try:
        command = [sys.executable, "-m", "tissue_retract", "deploy", "--policy", "scripted", "--target", "dvrk"]
        command += ["--task", "lift", "--task-topics", "--wrench-calibration", str(tmp_path / "wrench.json")]
        command += ["--safety-config", str(tmp_path / "deadman.toml"), "--record", str(record), "--wait", "60"]
        command += ["--domain-id", ros_env["ROS_DOMAIN_ID"]]
        deploy = subprocess.run(command, env=ros_env, capture_output=True, text=True, timeout=300)
    finally:
        stop(sim)
    output = deploy.stdout + deploy.stderr
    assert deploy.returncode == 4, output
    assert "HOLD: invalid data: measured_js effort: the calibrated force" in output, output
    assert "(fitted on PSM1 on an unknown console, measured_js); the filter trusts the force to 1 N" in output, output
    assert "Warning" not in output and "Traceback" not in output, output
    assert "enable and home" not in output, output  # held before anything reached the console
    assert "commands: 0 computed, sent 0" in output or "sent 0" in output, output
    replay = subprocess.run(
        [sys.executable, "-m", "tissue_retract", "replay", str(record)], capture_output=True, text=True, timeout=120
    )
    assert replay.returncode == 0, replay.stdout + replay.stderr
    assert "hold: invalid data: measured_js effort" in replay.stdout, replay.stdout
    path = (tmp_path / "wrench.json").resolve()
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    assert (
        f"force sensing: dvrk-calibrated, calibrated by {path} (sha256 {digest}; error bound 1.000 N, 1.000 N with "
        "the acceleration); the safety filter was given a sensing error of 1.000 N"
    ) in replay.stdout, replay.stdout
    sensing = load_recording(record).meta["sensing"]
    assert (sensing["force_sensing"], sensing["force_sensing_error_n"]) == ("dvrk-calibrated", 1.0), sensing
    assert sensing["wrench_calibration"]["path"] == str(path) and sensing["wrench_calibration"]["sha256"] == digest


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_stopped_calibration_exits_128_plus_the_signal_with_one_plain_line(
    homed_sim: subprocess.Popen[str], ros_env: dict[str, str], tmp_path: Path, sig: signal.Signals
) -> None:
    """SIGINT or SIGTERM mid-excitation: exit 130 or 143, one line naming the signal and the stage, no file."""
    out = tmp_path / "wrench.json"
    command = [sys.executable, "-m", "tissue_retract", "calibrate-wrench", "--domain-id", ros_env["ROS_DOMAIN_ID"]]
    process = subprocess.Popen(
        [*command, "--out", str(out), "--duration", "60", "--wait", "60"],
        env=ros_env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert process.stdout is not None
    lines = []
    for line in process.stdout:
        lines.append(line)
        if "excitation 1 of 2" in line:
            break
    assert lines and "excitation 1 of 2" in lines[-1], "".join(lines)
    process.send_signal(sig)
    output, errors = process.communicate(timeout=120)
    assert process.returncode == 128 + sig, "".join(lines) + output + errors
    assert errors.strip().splitlines() == [
        f"tissue-retract calibrate-wrench: stopped by {sig.name} during excitation 1 of 2: no calibration written; "
        "the arm holds where it is"
    ], errors
    assert not out.exists()


@pytest.mark.slow
def test_an_exact_console_is_refused_live_and_offline_and_deploys_as_a_force_sensor(
    ros_env: dict[str, str], tmp_path: Path
) -> None:
    """Against sim-dvrk --wrench ideal (every joint effort 0 in free space, a force sensor's measured_cf),
    calibrate-wrench exits 1 saying the console reports the exact force and needs no calibration, names
    --force-sensor, and writes none; the bag it recorded, fitted offline, is refused the same way. The deploy
    that message names finishes the retraction on that console: the filter trusts the force to the declared
    bound, --policy pretrained takes the exact-sensing policy, and the recording names the sensing."""
    process = start_sim_dvrk(ros_env, "--wrench", "ideal", "--task", "lift")
    try:
        rclpy.init()
        try:
            with PsmClient("PSM1", node_name="test_exact_console_homer", deadman_timeout_s=0.5) as client:
                client.wait_for_measurement(timeout_s=60.0)
                client.enable(timeout_s=30.0)
                client.home(timeout_s=30.0)
        finally:
            rclpy.shutdown()
        out, bag = tmp_path / "wrench.json", tmp_path / "excitation"
        command = [sys.executable, "-m", "tissue_retract", "calibrate-wrench", "--domain-id", ros_env["ROS_DOMAIN_ID"]]
        live = subprocess.run(
            [*command, "--out", str(out), "--duration", "5", "--wait", "60", "--record", str(bag)],
            env=ros_env,
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
        )
        recording, config = tmp_path / "sensor.mcap", tmp_path / "safety.toml"
        config.write_text("deadman_timeout_s = 0.5\n")  # as the other deploys here: a loaded machine lags
        deploy = [sys.executable, "-m", "tissue_retract", "deploy", "--policy", "pretrained", "--target", "dvrk"]
        deploy += ["--task", "lift", "--domain-id", ros_env["ROS_DOMAIN_ID"], "--force-sensor", "0.2"]
        deploy += ["--safety-config", str(config), "--policy-budget", "600"]
        deployed = subprocess.run(
            [*deploy, "--wait", "60", "--record", str(recording)],
            env=ros_env,
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
        )
    finally:
        stop(process)
    output = live.stdout + live.stderr
    assert live.returncode == 1 and not out.exists(), output
    assert "reports the exact force" in live.stderr and "needs no calibration" in live.stderr, output
    assert "deploy with --force-sensor N" in live.stderr, output
    said = deployed.stdout + deployed.stderr
    assert deployed.returncode == 0 and "success: 100 % (1 of 1)" in deployed.stdout, said
    assert "the filter trusts the force to 0.2 N (--force-sensor" in deployed.stdout, said
    assert "policy: the shipped one trained on ideal force sensing" in deployed.stdout, said
    assert "WARNING" not in said and "never exceeded beyond the force sensing's 0.20 N error bound" in said, said
    meta = load_recording(recording).meta
    assert meta["sensing"]["force_sensing"] == "force-sensor", meta
    assert meta["sensing"]["force_sensing_error_n"] == 0.2, meta
    assert "Traceback" not in output
    offline = subprocess.run(
        [sys.executable, "-m", "tissue_retract", "calibrate-wrench", "--from", str(bag), "--out", str(out)],
        env=ros_env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert offline.returncode == 1 and not out.exists(), offline.stdout + offline.stderr
    assert "every effort in this log is 0" in offline.stderr, offline.stderr
