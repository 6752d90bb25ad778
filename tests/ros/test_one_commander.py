"""One commander per arm, over real loopback DDS: ``sim-dvrk`` and ``deploy`` child processes, a rogue node.

Each test reproduces one way an arm gets two masters or leaves where the episode thinks it is: a second
deploy, a node streaming ``servo_jp`` during a deploy, an arm moved between deploys, a second console.
The deploys use a 0.5 s deadman and a 600 s policy budget (the machine is shared and loaded) and the tests
act on what the children print, never after a sleep.
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import rclpy
from rclpy.context import Context
from ros_process import start_sim_dvrk, stop, wait_until
from sensor_msgs.msg import JointState  # type: ignore[import-untyped]
from std_msgs.msg import String  # type: ignore[import-untyped]

from hardware_if.client.psm_client import PsmClient
from hardware_if.common import convert
from hardware_if.common.crtk import JOINT_NAMES, ArmTopics, event_qos, periodic_qos
from hardware_if.common.executor import make_executor
from hardware_if.deploy.report import EXIT_HOLD
from hardware_if.recording.replay import load_recording, summarize_recording
from psm_control.robot import PsmModel
from tissue_retract.faults import GATE_VARIABLE, MARK

SEED = "2"
TIMEOUT_S = 240.0
#: The task's start joints: where sim-dvrk --task lift homes and every episode starts.
START_Q = PsmModel.from_variant().home()


def _deploy(env: dict[str, str], record: Path, *extra: str, policy: str = "scripted") -> subprocess.Popen[str]:
    config = record.with_suffix(".toml")
    config.write_text("deadman_timeout_s = 0.5\n")
    command = [sys.executable, "-m", "tissue_retract", "deploy", "--policy", policy, "--target", "dvrk"]
    command += ["--task", "lift", "--seed", SEED, "--domain-id", env["ROS_DOMAIN_ID"], "--record", str(record)]
    command += ["--wait", "60", "--safety-config", str(config), "--policy-budget", "600", *extra]
    child_env = dict(env, PYTHONUNBUFFERED="1", **{GATE_VARIABLE: str(record.with_suffix(".go"))})
    return subprocess.Popen(command, env=child_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _read_until(process: subprocess.Popen[str], text: str) -> str:
    assert process.stdout is not None
    lines: list[str] = []
    for line in process.stdout:
        lines.append(line)
        if text in line:
            break
    return "".join(lines)


class RosNode:
    """A node of its own context on the test's domain: a rogue commander that also hears the arm's warnings."""

    def __init__(self, name: str) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(name, context=self.context)
        self.warnings: list[str] = []
        self.node.create_subscription(String, ArmTopics().topic("warning"), self._on_warning, event_qos())
        self.publisher = self.node.create_publisher(JointState, ArmTopics().topic("servo_jp"), periodic_qos())
        self._streaming: JointState | None = None
        self._executor = make_executor(self.context)
        self._executor.add_node(self.node)
        self._running = True
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    @property
    def name(self) -> str:
        """The node's fully qualified name, as the graph shows it."""
        return str(self.node.get_fully_qualified_name())

    def _on_warning(self, message: String) -> None:
        self.warnings.append(message.data)

    def _spin(self) -> None:
        due_s = time.monotonic()
        while self._running:
            self._executor.spin_once(timeout_sec=0.002)
            if self._streaming is not None and time.monotonic() >= due_s:
                self.publisher.publish(self._streaming)
                due_s += 0.01  # 100 Hz, as the teleoperation node of the report

    def stream_servo_jp(self, q: np.ndarray) -> None:
        """Publish ``servo_jp`` with these joints at 100 Hz from now on."""
        self._streaming = convert.joint_state(JOINT_NAMES, q)

    def close(self) -> None:
        """Stop publishing and leave the graph."""
        self._running = False
        self._thread.join(timeout=5.0)
        self._executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


@pytest.fixture
def sim(ros_env: dict[str, str]) -> Iterator[subprocess.Popen[str]]:
    """A fresh ``sim-dvrk --task lift``."""
    process = start_sim_dvrk(ros_env, "--task", "lift", "--seed", SEED)
    yield process
    stop(process)


def test_second_deploy_refuses_and_the_first_holds(ros_env: dict[str, str], tmp_path: Path) -> None:
    """A second deploy on an arm being commanded refuses before sending anything; the first holds; no success."""
    sim = start_sim_dvrk(ros_env, "--task", "lift", "--seed", SEED)
    try:
        first_record, second_record = tmp_path / "first.mcap", tmp_path / "second.mcap"
        first = _deploy(ros_env, first_record, policy="tissue_retract.faults:Gate")
        head = _read_until(first, MARK)  # mid-episode 0: the policy waits at step 3 until its gate opens
        assert MARK in head, head
        second = _deploy(ros_env, second_record, "--seed", "5")
        second_output, _ = second.communicate(timeout=TIMEOUT_S)
        first_record.with_suffix(".go").touch()
        rest, _ = first.communicate(timeout=TIMEOUT_S)
    finally:
        console = stop(sim)
    first_output = head + rest
    assert second.returncode == EXIT_HOLD, second_output
    assert f"HOLD: another commander: /psm1_deploy_{first.pid} publishes /PSM1/servo_jp" in second_output
    second_summary = summarize_recording(load_recording(second_record))
    assert second_summary.commands_sent == 0 and not second_summary.episodes
    assert "(seed 5)" not in console, console  # the second deploy's reset never reached the console
    assert first.returncode == EXIT_HOLD, first_output
    # The second was in the graph for a moment: named when its name arrived before it left.
    assert "HOLD: another commander: " in first_output, first_output
    assert "success=True" not in first_output + second_output
    assert "Traceback" not in first_output + second_output


def test_rogue_servo_jp_publisher_holds_naming_it(
    sim: subprocess.Popen[str], ros_env: dict[str, str], tmp_path: Path
) -> None:
    """A node streaming servo_jp during a deploy: the deploy holds naming it, the console warns of two sources."""
    record = tmp_path / "rogue.mcap"
    deploy = _deploy(ros_env, record, policy="tissue_retract.faults:Gate")
    head = _read_until(deploy, MARK)
    assert MARK in head, head
    rogue = RosNode(f"teleop_{time.monotonic_ns()}")
    name = rogue.name
    try:
        rogue.stream_servo_jp(START_Q + np.array([0.25, 0.0, 0.0, 0.0, 0.0, 0.0]))
        # The console saw commands from both (the deploy's still open publisher and the rogue's) ...
        assert wait_until(lambda: any(name in w for w in rogue.warnings), 60.0), rogue.warnings
        record.with_suffix(".go").touch()
        rest, _ = deploy.communicate(timeout=TIMEOUT_S)
    finally:
        rogue.close()
    output = head + rest
    warning = next(w for w in rogue.warnings if name in w)
    assert "commands from 2 publishers" in warning and f"/psm1_deploy_{deploy.pid}" in warning, warning
    # ... and the deploy held, naming the rogue.
    assert deploy.returncode == EXIT_HOLD, output
    assert f"HOLD: another commander: {name} publishes /PSM1/servo_jp" in output, output
    summary = summarize_recording(load_recording(record))
    assert any(name in hold for hold in summary.holds), summary.holds
    assert "Traceback" not in output


@pytest.mark.slow
def test_arm_moved_between_deploys_goes_back_to_its_start(
    sim: subprocess.Popen[str], ros_env: dict[str, str], tmp_path: Path
) -> None:
    """An arm moved off the episode's start: a dry run holds saying so, a deploy moves it back and succeeds."""
    context = Context()
    rclpy.init(context=context)
    try:
        with PsmClient("PSM1", node_name=f"colleague_{time.monotonic_ns()}", context=context) as colleague:
            colleague.wait_for_measurement(60.0)
            colleague.enable(30.0)
            colleague.home(30.0)
            moved = START_Q + np.array([0.25, 0.0, 0.0, 0.0, 0.0, 0.0])
            colleague.move_jp(moved)
            assert wait_until(lambda: abs(colleague.measure().q[0] - moved[0]) < 1e-3, 60.0)
    finally:
        rclpy.shutdown(context=context)
    dry = _deploy(ros_env, tmp_path / "dry.mcap", "--dry-run")
    dry_output, _ = dry.communicate(timeout=TIMEOUT_S)
    assert dry.returncode == EXIT_HOLD, dry_output
    assert "HOLD: not at start: episode 0: yaw is 0.2" in dry_output
    run = _deploy(ros_env, tmp_path / "run.mcap")
    output, _ = run.communicate(timeout=TIMEOUT_S)
    assert run.returncode == 0, output
    assert "episode 0: yaw is 0.2" in output and "moving the arm back" in output
    assert ": success, 50 steps" in output, output


def test_second_sim_dvrk_refuses_to_start(sim: subprocess.Popen[str], ros_env: dict[str, str]) -> None:
    """A second sim-dvrk for an arm already served on the domain refuses to start, naming the first."""
    context = Context()
    rclpy.init(context=context)
    try:
        with PsmClient("PSM1", node_name=f"look_{time.monotonic_ns()}", listen_only=True, context=context) as look:
            look.wait_for_measurement(60.0)  # the first console serves the arm
    finally:
        rclpy.shutdown(context=context)
    second = start_sim_dvrk(ros_env)
    output, _ = second.communicate(timeout=120.0)
    assert second.returncode == 1, output
    assert "/PSM1 is already served on this ROS domain by /psm1_sim_dvrk: one console per arm" in output, output
    assert "Traceback" not in output
    assert sim.poll() is None  # the first one still serves
