"""Deploying over real loopback DDS: ``sim-dvrk --task lift`` and ``deploy`` as child processes.

The deploy runs the scripted expert through the control chain with the PsmClient backend; the tests
check a whole Task I episode, a dry run that publishes nothing on motion topics, the recording and its
replay, and a hold (not a crash) when the simulated console dies mid-episode.

The deadman and the policy budget are wall-clock checks (0.05 s each by default); these tests run on a
shared, loaded machine, so their deploys use a 0.5 s deadman and a 600 s policy budget, and act on what
the deploy prints (its fault policy's line), never after a sleep. The default-timeout faults are
``tests/ros/test_faults.py``'s.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
import rclpy
from ros_process import start_sim_dvrk, stop
from sensor_msgs.msg import JointState  # type: ignore[import-untyped]

from hardware_if.client.psm_client import PsmClient
from hardware_if.common.crtk import MOTION_TOPICS, ArmTopics, periodic_qos
from hardware_if.deploy.report import EXIT_HOLD
from hardware_if.recording.replay import load_recording, summarize_recording
from hardware_if.wrench.joint_logs import read_joint_log
from tissue_retract.faults import GATE_VARIABLE, MARK

#: A seed whose Task I episode the scripted expert completes in the simulation.
SEED = "2"
DEPLOY_TIMEOUT_S = 240.0
#: Episodes of the Task I run (how often a deploy through ROS succeeds: test_rehearsal.py).
EPISODES = 1


def _deploy(
    env: dict[str, str], record: Path, *extra: str, policy: str = "scripted", gate: Path | None = None
) -> subprocess.Popen[str]:
    config = record.with_suffix(".toml")
    config.write_text("deadman_timeout_s = 0.5\n")
    command = [sys.executable, "-m", "tissue_retract", "deploy", "--policy", policy, "--target", "dvrk"]
    command += ["--task", "lift", "--seed", SEED, "--domain-id", env["ROS_DOMAIN_ID"], "--record", str(record)]
    command += ["--wait", "60", "--safety-config", str(config), "--policy-budget", "600", *extra]
    child_env = dict(env, PYTHONUNBUFFERED="1")
    if gate is not None:
        child_env[GATE_VARIABLE] = str(gate)
    return subprocess.Popen(command, env=child_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _read_until(process: subprocess.Popen[str], text: str) -> list[str]:
    """The child's lines up to the first containing ``text`` (or to its end)."""
    assert process.stdout is not None
    lines: list[str] = []
    for line in process.stdout:
        lines.append(line)
        if text in line:
            break
    return lines


@pytest.fixture
def sim(ros_env: dict[str, str]) -> Iterator[subprocess.Popen[str]]:
    """A fresh ``sim-dvrk --task lift`` for one test."""
    process = start_sim_dvrk(ros_env, "--task", "lift", "--seed", SEED)
    yield process
    stop(process)


@pytest.fixture(scope="module")
def lift_run(tmp_path_factory: pytest.TempPathFactory, ros_env: dict[str, str]) -> tuple[int, str, Path]:
    """One deploy of a Task I episode against sim-dvrk: (exit status, output, recording)."""
    record = tmp_path_factory.mktemp("deploy") / "lift.mcap"
    sim = start_sim_dvrk(ros_env, "--task", "lift", "--seed", SEED)
    try:
        deploy = _deploy(ros_env, record, "--episodes", str(EPISODES))
        output, _ = deploy.communicate(timeout=DEPLOY_TIMEOUT_S)
    finally:
        stop(sim)
    return deploy.returncode, output, record


def test_lift_episode_over_ros_succeeds(lift_run: tuple[int, str, Path]) -> None:
    """Full Task I episodes deployed over ROS through the chain against sim-dvrk --task lift succeed."""
    status, output, record = lift_run
    assert status == 0, output
    assert ": success, 50 steps" in output, output
    summary = summarize_recording(load_recording(record))
    assert summary.commands == summary.commands_sent > 0
    assert summary.holds == []
    assert summary.peak_force_n > 0.0  # the flap was lifted: the tissue force reached body/measured_cf
    assert len(summary.episodes) == EPISODES
    assert all(e["success"] and e["goal_distance_m"] <= 0.005 for e in summary.episodes), summary.episodes


def test_replay_prints_summary_and_plot(lift_run: tuple[int, str, Path], tmp_path: Path) -> None:
    """replay on a deploy's MCAP prints its summary and writes a non-empty plot."""
    _, _, record = lift_run
    plot = tmp_path / "run.png"
    done = subprocess.run(
        [sys.executable, "-m", "tissue_retract", "replay", str(record), "--plot", str(plot)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    for text in ("commands:", "peak force:", "tracking error", "success=True"):
        assert text in done.stdout, done.stdout
    assert plot.stat().st_size > 1000


def test_dry_run_publishes_nothing_on_motion_topics(
    sim: subprocess.Popen[str], ros_env: dict[str, str], tmp_path: Path
) -> None:
    """After ``ready-arm`` (enable, home, to the start), a dry run sends nothing on motion topics, and
    reports and records."""
    record = tmp_path / "dry.mcap"
    counts = dict.fromkeys(MOTION_TOPICS, 0)
    ready = subprocess.run(
        [sys.executable, "-m", "tissue_retract", "ready-arm", "--wait", "60"],
        env=ros_env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert ready.returncode == 0, ready.stdout + ready.stderr
    assert "PSM1: at the episodes' start" in ready.stdout and "ready" in ready.stdout
    rclpy.init()
    try:
        # The watcher only listens: a node with command publishers would be another commander to the deploy.
        with PsmClient("PSM1", node_name=f"dry_run_watch_{time.monotonic_ns()}", listen_only=True) as psm:
            topics = ArmTopics("PSM1")
            lock = threading.Lock()

            def counter(name: str) -> Callable[[JointState], None]:
                def callback(_: JointState) -> None:
                    with lock:
                        counts[name] += 1

                return callback

            from geometry_msgs.msg import PoseStamped  # type: ignore[import-untyped]

            for name in MOTION_TOPICS:
                kind = PoseStamped if name.endswith("_cp") else JointState
                psm.create_subscription(kind, topics.topic(name), counter(name), periodic_qos())
            deploy = _deploy(ros_env, record, "--dry-run")
            output, _ = deploy.communicate(timeout=DEPLOY_TIMEOUT_S)
            time.sleep(0.5)
    finally:
        rclpy.shutdown()
    assert deploy.returncode == 0, output
    assert counts == dict.fromkeys(MOTION_TOPICS, 0), counts
    assert "dry run (nothing published on motion topics)" in output
    assert "PSM1: operating state ENABLED, homed" in output
    assert "would have sent" in output and "predicted peak force" in output
    recording = load_recording(record)
    summary = summarize_recording(recording)
    assert summary.dry_run and summary.commands > 0 and summary.commands_sent == 0
    assert recording.report["commands_sent"] == 0


def test_dry_run_on_a_fresh_console_says_at_once_what_it_waits_for(
    sim: subprocess.Popen[str], ros_env: dict[str, str], tmp_path: Path
) -> None:
    """A dry run on a DISABLED arm prints the state it sees and how to enable and home before it waits; when the
    wait ends, it says that it commanded nothing (nothing holds an arm a dry run never commanded)."""
    # The wait covers discovery (up to DISCOVERY_S on this machine, longer when it is loaded) and then expires.
    deploy = _deploy(ros_env, tmp_path / "dry.mcap", "--dry-run", "--wait", "10")
    output, _ = deploy.communicate(timeout=DEPLOY_TIMEOUT_S)
    assert deploy.returncode == EXIT_HOLD, output
    lines = output.splitlines()
    state = next(i for i, line in enumerate(lines) if "PSM1: operating state" in line)
    assert lines[state].endswith("operating state DISABLED, not homed"), lines[state]
    hint = lines[state + 1]
    assert (
        "waiting up to 10 s" in hint
        and "never enables or homes" in hint
        and "tissue-retract ready-arm --arm PSM1" in hint
    ), hint
    assert "nan" not in output.lower(), output
    assert "the arm is held" not in output and "HOLD: not ready: " in output, output
    assert "it commanded nothing: the arm is as the console left it" in output, output


def test_killing_sim_dvrk_mid_episode_holds_and_reports(
    sim: subprocess.Popen[str], ros_env: dict[str, str], tmp_path: Path
) -> None:
    """Killing sim-dvrk mid-episode makes deploy hold, say why, record it and exit with status 4."""
    record = tmp_path / "killed.mcap"
    gate = tmp_path / "go"
    deploy = _deploy(ros_env, record, policy="tissue_retract.faults:Gate", gate=gate)
    lines = _read_until(deploy, MARK)  # the policy waits at step 3, mid-episode, until the gate opens
    assert any(MARK in line for line in lines), "".join(lines)
    sim.send_signal(signal.SIGKILL)
    sim.wait(timeout=30)
    gate.touch()
    rest, _ = deploy.communicate(timeout=DEPLOY_TIMEOUT_S)
    output = "".join(lines) + rest
    assert deploy.returncode == EXIT_HOLD, output
    assert "the arm is held" in output and "HOLD:" in output, output
    assert "Traceback" not in output, output
    holds = summarize_recording(load_recording(record)).holds
    assert holds and any(reason in holds[0] for reason in ("stale", "publisher gone")), holds


def test_ctrl_c_stops_deploy_cleanly(sim: subprocess.Popen[str], ros_env: dict[str, str], tmp_path: Path) -> None:
    """Ctrl-C mid-episode stops commanding between two ticks, reports, records it and exits 130.

    The signal is sent once the deploy has ticked: its policy prints a line at step 3 (after the ticks of
    steps 0-2) and then never returns, so the episode cannot end before the signal, whatever the load.
    """
    record = tmp_path / "interrupted.mcap"
    deploy = _deploy(ros_env, record, policy="tissue_retract.faults:Hang")
    lines = _read_until(deploy, MARK)
    assert any(MARK in line for line in lines), "".join(lines)
    deploy.send_signal(signal.SIGINT)
    rest, _ = deploy.communicate(timeout=DEPLOY_TIMEOUT_S)
    output = "".join(lines) + rest
    assert deploy.returncode == 130, output
    assert "interrupted (Ctrl-C)" in output and "Traceback" not in output, output
    summary = summarize_recording(load_recording(record))
    assert "Ctrl-C" in summary.holds
    assert summary.commands_sent > 0  # it had commanded the arm before the signal


def test_a_dvrk_deploys_recording_is_a_joint_log_with_efforts(lift_run: tuple[int, str, Path]) -> None:
    """A deploy to a dVRK records each tick's joint efforts with its joints: calibrate-wrench --from reads it."""
    _, _, record = lift_run
    log = read_joint_log(record)
    assert log.layout == "recording" and len(log.t_s) > 10
    assert np.all(np.isfinite(log.effort)) and np.abs(log.effort).max() > 0.0  # sim-dvrk sends efforts
