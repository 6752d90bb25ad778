"""The endoscope over real loopback DDS: ``sim-dvrk --endoscope`` publishes it, ``deploy --perception camera`` uses it.

sim-dvrk and deploy run as child processes. The deploys use a 0.5 s deadman and a 600 s policy budget
(a shared, loaded machine; 1 s, the most allowed, where a gated policy pauses the ticks), and act on what the
processes print or publish, never after a sleep.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import rclpy
from rclpy.node import Node
from ros_process import start_sim_dvrk, stop, wait_until
from sensor_msgs.msg import CameraInfo, Image  # type: ignore[import-untyped]

from hardware_if.common.crtk import periodic_qos
from hardware_if.common.task_topics import DEFAULT_RIG, camera_topics
from hardware_if.deploy.report import EXIT_HOLD
from hardware_if.recording.replay import load_recording, summarize_recording
from sim.endoscope import Endoscope
from tissue_retract.faults import GATE_VARIABLE, MARK

SEED = "2"
DEPLOY_TIMEOUT_S = 300.0


def _start(env: dict[str, str]) -> tuple[subprocess.Popen[str], int, np.ndarray]:
    """sim-dvrk --task lift --blind --endoscope; its render process id and the site it prints."""
    process = start_sim_dvrk(env, "--task", "lift", "--seed", SEED, "--blind", "--endoscope")
    assert process.stdout is not None
    pid, site = None, None
    for line in process.stdout:
        if line.startswith("endoscope:"):
            pid = int(re.search(r"render process (\d+)", line).group(1))  # type: ignore[union-attr]
        if line.startswith("site:"):
            site = np.array([float(v) for v in line.split()[1:4]])
            break
    assert pid is not None and site is not None
    return process, pid, site


@pytest.fixture
def endoscope_sim(ros_env: dict[str, str]) -> Iterator[tuple[subprocess.Popen[str], int, np.ndarray]]:
    started = _start(ros_env)
    yield started
    stop(started[0])


class _Watcher(Node):
    """Counts the rig's messages and keeps the last of each."""

    def __init__(self) -> None:
        super().__init__(f"endoscope_watch_{time.monotonic_ns() % 100000}")
        self.lock = threading.Lock()
        self.last: dict[str, object] = {}
        self.received_s = float("-inf")
        self.count = 0
        for key, topic in camera_topics(DEFAULT_RIG).items():
            kind = Image if key.endswith("image") else CameraInfo
            self.create_subscription(kind, topic, self._callback(key), periodic_qos())

    def _callback(self, key: str) -> object:
        def callback(message: object) -> None:
            with self.lock:
                self.last[key] = message
                self.count += 1
                self.received_s = time.monotonic()

        return callback


def test_sim_dvrk_publishes_stereo_images_and_camera_info(
    endoscope_sim: tuple[subprocess.Popen[str], int, np.ndarray],
) -> None:
    """Left and right rgb8 images of the estimator's size, with its K and the right eye's baseline in P."""
    rclpy.init()
    try:
        watcher = _Watcher()
        assert wait_until(lambda: rclpy.spin_once(watcher, timeout_sec=0.05) or watcher.count >= 40, timeout_s=120)
        with watcher.lock:
            left, right = watcher.last["left_image"], watcher.last["right_image"]
            left_info, right_info = watcher.last["left_info"], watcher.last["right_info"]
        watcher.destroy_node()
    finally:
        rclpy.shutdown()
    endoscope = Endoscope()
    for image in (left, right):
        assert (image.encoding, image.width, image.height) == ("rgb8", 128, 96)  # type: ignore[attr-defined]
        assert len(image.data) == 3 * 128 * 96  # type: ignore[attr-defined]
    assert left.header.frame_id == f"{DEFAULT_RIG}_left"  # type: ignore[attr-defined]
    np.testing.assert_allclose(np.reshape(left_info.k, (3, 3)), endoscope.intrinsics())  # type: ignore[attr-defined]
    fx = endoscope.intrinsics()[0, 0]
    assert right_info.p[3] == pytest.approx(-fx * endoscope.baseline_m)  # type: ignore[attr-defined]


def _deploy(
    env: dict[str, str], record: Path, *extra: str, policy: str, gate: Path | None = None, deadman_s: float = 0.5
) -> subprocess.Popen[str]:
    config = record.with_suffix(".toml")
    config.write_text(f"deadman_timeout_s = {deadman_s}\n")
    command = [sys.executable, "-m", "tissue_retract", "deploy", "--policy", policy, "--target", "dvrk"]
    command += ["--task", "lift", "--perception", "camera", "--domain-id", env["ROS_DOMAIN_ID"]]
    command += ["--record", str(record), "--wait", "60", "--safety-config", str(config), "--policy-budget", "600"]
    child_env = dict(env, PYTHONUNBUFFERED="1")
    if gate is not None:
        child_env[GATE_VARIABLE] = str(gate)
    return subprocess.Popen(
        [*command, *extra], env=child_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )


@pytest.mark.slow
def test_deploy_completes_episodes_from_the_images_alone(
    endoscope_sim: tuple[subprocess.Popen[str], int, np.ndarray], ros_env: dict[str, str], tmp_path: Path
) -> None:
    """With no task topics and no registration, two episodes run to their end on a site seen within 6 mm, each
    saying which shipped estimator saw it, toward the goal given with --goal (the one sim-dvrk printed)."""
    console, _, true_site = endoscope_sim
    assert console.stdout is not None
    goal = next(line.split()[1:4] for line in console.stdout if line.startswith("goal: "))  # after the site line
    record = tmp_path / "camera.mcap"
    deploy = _deploy(ros_env, record, "--episodes", "2", "--image-timeout", "5", "--goal", *goal, policy="pretrained")
    output, _ = deploy.communicate(timeout=DEPLOY_TIMEOUT_S)
    assert deploy.returncode == 0, output
    assert f"goal {' '.join(goal)} (no task topics)" in output
    assert len(re.findall(r"site seen at \S+ \S+ \S+ by (?:pink|any-colour) \(", output)) == 2, output
    assert "shipped one trained on dvrk force sensing (dvrk/TissueRetract-Lift-v0" in output  # the console's force
    seen = [np.array([float(v) for v in m.split()]) for m in re.findall(r"site seen at (\S+ \S+ \S+)", output)]
    assert len(seen) == 2
    assert 1000 * np.linalg.norm(seen[0] - true_site) < 6.0, (seen[0], true_site)
    summary = summarize_recording(load_recording(record))
    assert summary.holds == [] and len(summary.episodes) == 2
    assert all(e["steps"] == 50 for e in summary.episodes), summary.episodes


def test_killing_the_image_stream_holds(
    endoscope_sim: tuple[subprocess.Popen[str], int, np.ndarray], ros_env: dict[str, str], tmp_path: Path
) -> None:
    """The render process killed mid-episode: the deploy's next observation finds the images stale and holds."""
    _, render_pid, _ = endoscope_sim
    record, gate = tmp_path / "killed.mcap", tmp_path / "go"
    deploy = _deploy(
        ros_env, record, "--image-timeout", "2", policy="tissue_retract.faults:Gate", gate=gate, deadman_s=1.0
    )
    assert deploy.stdout is not None
    lines = []
    for line in deploy.stdout:  # the policy waits at step 3, mid-episode, until the gate opens
        lines.append(line)
        if MARK in line:
            break
    assert any(MARK in line for line in lines), "".join(lines)
    os.kill(render_pid, signal.SIGKILL)
    rclpy.init()
    try:  # the gate opens once this test has itself gone 3 s without an image: the stream is dead
        watcher = _Watcher()
        assert wait_until(
            lambda: rclpy.spin_once(watcher, timeout_sec=0.05) or time.monotonic() - watcher.received_s > 3.0,
            timeout_s=60,
        )
        watcher.destroy_node()
    finally:
        rclpy.shutdown()
    gate.touch()
    output, _ = deploy.communicate(timeout=DEPLOY_TIMEOUT_S)
    assert deploy.returncode == EXIT_HOLD, "".join(lines) + output
    assert "stale: endoscope images" in output, output
    holds = summarize_recording(load_recording(record)).holds
    assert holds and "stale" in holds[0], holds


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_killed_render_process_is_said_plainly_and_the_console_goes_on(
    endoscope_sim: tuple[subprocess.Popen[str], int, np.ndarray], sig: signal.Signals
) -> None:
    """The render process stopped by a signal while it publishes: one plain line from sim-dvrk, no traceback."""
    process, render_pid, _ = endoscope_sim
    rclpy.init()
    try:  # the render process is publishing: a signal now lands between two publishes
        watcher = _Watcher()
        assert wait_until(lambda: rclpy.spin_once(watcher, timeout_sec=0.05) or watcher.count >= 8, timeout_s=120)
        watcher.destroy_node()
    finally:
        rclpy.shutdown()
    os.kill(render_pid, sig)
    assert process.stdout is not None
    said = threading.Event()
    lines: list[str] = []

    def read() -> None:
        for line in process.stdout:  # type: ignore[union-attr]
            lines.append(line)
            if f"render process {render_pid} ended ({sig.name})" in line:
                said.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    assert said.wait(timeout=60), "".join(lines)
    assert process.poll() is None  # the console goes on
    process.send_signal(signal.SIGINT)
    assert process.wait(timeout=30) == 0
    reader.join(timeout=10)
    output = "".join(lines)
    assert "Traceback" not in output and "RCLError" not in output, output
