"""The simulated dVRK over real loopback DDS: a ``sim-dvrk`` child process and a PsmClient here."""

from __future__ import annotations

import signal
import time
from collections.abc import Iterator

import numpy as np
import pytest
import rclpy
from dvrk_client import start_sim
from ros_process import SIM_BASE_XYZ, start_sim_dvrk, stop, wait_until

from hardware_if.client.psm_client import PsmClient
from psm_control.commands import JointCommand
from psm_control.robot import PsmModel


@pytest.fixture(scope="module")
def ros() -> Iterator[None]:
    """rclpy's default context for this module's clients."""
    rclpy.init()
    yield
    rclpy.shutdown()


@pytest.fixture(scope="module")
def sim(ros: None, ros_env: dict[str, str]) -> Iterator[object]:
    """A running sim-dvrk shared by the tests that do not kill it."""
    process = start_sim_dvrk(ros_env)
    yield process
    output = stop(process)
    assert process.returncode == 0, output


@pytest.fixture
def client(sim: object) -> Iterator[PsmClient]:
    """A started client of PSM1 with its first measurement in.

    Its deadman is 0.5 s: these tests are about what sim-dvrk does with commands, and on a loaded machine a
    live arm's measurement can be more than the default 0.05 s old (the default's tests are test_deadman.py
    and test_faults.py).
    """
    with PsmClient("PSM1", node_name=f"test_client_{time.monotonic_ns()}", deadman_timeout_s=0.5) as psm:
        psm.wait_for_measurement(timeout_s=30.0)
        yield psm


def _command(q: np.ndarray, jaw: float = 0.0) -> JointCommand:
    zeros = np.zeros(6)
    return JointCommand(np.asarray(q, dtype=float), zeros, zeros, jaw, time.monotonic())


def _move_and_wait(psm: PsmClient, q: np.ndarray) -> None:
    psm.move_jp(q)
    assert wait_until(lambda: np.allclose(psm.measure().q, q, atol=1e-9), timeout_s=10.0), psm.measure().q


def test_enable_and_home(client: PsmClient) -> None:
    """enable reaches ENABLED, and home ends ENABLED, homed and not busy."""
    client.enable(timeout_s=10.0)
    assert client.operating_state()[0] == "ENABLED"
    client.home(timeout_s=10.0)
    assert client.operating_state() == ("ENABLED", True, False)
    assert client.status.ok, client.status


def test_servo_jp_stream_moves_the_arm(client: PsmClient) -> None:
    """A 100 Hz servo_jp stream is followed: measured_js ends at the last command, no hold."""
    client.home(timeout_s=10.0)
    _move_and_wait(client, np.array([0.0, 0.0, 0.1, 0.0, 0.0, 0.0]))
    start = client.measure().q
    goal = start + np.array([0.2, -0.1, 0.02, 0.3, 0.1, -0.1])
    for s in np.linspace(0.0, 1.0, 60):
        client.servo_jp(_command(start + s * (goal - start), jaw=0.2))
        time.sleep(0.01)
    assert wait_until(lambda: np.allclose(client.measure().q, goal, atol=1e-9))
    assert wait_until(lambda: abs(client.measure().jaw - 0.2) < 1e-9)
    assert not client.status.holding, client.status


def test_cp_topics_follow_dvrk_frames_and_types(client: PsmClient) -> None:
    """local/measured_cp is the model's FK about the RCM; measured_cp = base @ local in PSM1_base; types are CRTK."""
    client.home(timeout_s=10.0)
    q = np.array([0.3, -0.2, 0.15, 1.0, 0.4, -0.6])
    _move_and_wait(client, q)
    expected = PsmModel.from_variant("classic").configuration(q)
    base = np.eye(4)
    base[:3, 3] = SIM_BASE_XYZ
    assert wait_until(lambda: np.allclose(client.pose("local/measured_cp")[0], expected.local_pose(), atol=1e-6))
    pair: list[np.ndarray] = []

    def one_tick_pair() -> bool:
        pair[:] = [client.pose("local/measured_cp")[0], client.pose("measured_cp")[0]]
        return np.allclose(pair[1], base @ pair[0], atol=1e-9)

    # Two topics, two messages: on a busy machine one of a tick's pair can arrive after the other while the arm
    # still creeps (2e-5 apart once), so the pair is read again until its two poses are of one tick.
    wait_until(one_tick_pair, timeout_s=30.0)
    local, measured = pair
    assert client.pose("measured_cp")[1] == "PSM1_base"
    np.testing.assert_allclose(measured, base @ local, atol=1e-9)
    types = dict(client.get_topic_names_and_types())
    assert types["/PSM1/measured_cp"] == ["geometry_msgs/msg/PoseStamped"]
    assert types["/PSM1/local/measured_cp"] == ["geometry_msgs/msg/PoseStamped"]
    assert types["/PSM1/setpoint_cp"] == ["geometry_msgs/msg/PoseStamped"]
    assert types["/PSM1/measured_js"] == ["sensor_msgs/msg/JointState"]
    assert types["/PSM1/body/measured_cf"] == ["geometry_msgs/msg/WrenchStamped"]
    assert types["/PSM1/operating_state"] == ["crtk_msgs/msg/OperatingState"]
    assert "crtk_msgs/msg/StringStamped" in types["/PSM1/state_command"]
    durability = client.get_publishers_info_by_topic("/PSM1/operating_state")[0].qos_profile.durability
    assert durability == rclpy.qos.DurabilityPolicy.TRANSIENT_LOCAL


def test_cartesian_goals_refused_below_45_mm(client: PsmClient) -> None:
    """servo_cp and move_cp are refused with an error while insertion < 45 mm, and followed past it."""
    client.home(timeout_s=10.0)
    _move_and_wait(client, np.array([0.1, 0.1, 0.03, 0.0, 0.0, 0.0]))
    pose, _ = client.pose("measured_cp")
    goal = pose.copy()
    goal[:3, 3] += [0.0, 0.0, 0.005]
    errors_before = len(client.errors)
    assert client.servo_cp(goal) and client.move_cp(goal)
    assert wait_until(lambda: len(client.errors) >= errors_before + 2)
    assert all("45 mm" in text and "refused" in text for text in client.errors[errors_before:])
    time.sleep(0.1)
    np.testing.assert_allclose(client.measure().q, [0.1, 0.1, 0.03, 0.0, 0.0, 0.0], atol=1e-12)

    _move_and_wait(client, np.array([0.1, 0.1, 0.12, 0.0, 0.0, 0.0]))
    pose, _ = client.pose("measured_cp")
    goal = pose.copy()
    goal[:3, 3] += [0.003, 0.0, 0.004]
    assert client.servo_cp(goal)
    assert wait_until(lambda: np.allclose(client.pose("measured_cp")[0][:3, 3], goal[:3, 3], atol=1e-5))


def test_killing_sim_dvrk_mid_stream_makes_the_client_hold(ros: None, ros_env: dict[str, str]) -> None:
    """When sim-dvrk dies mid-stream the client stops forwarding, holds, and reports why; nothing raises.

    The deadman is 0.5 s here, not the default 0.05 s: on a loaded machine a live arm's measurement can
    be 0.05 s old, and this test is about a dead one (the default is test_faults.py's).
    """
    process = start_sim_dvrk(ros_env, "--arm", "PSM2")
    faults = []
    sent = 0

    def stream() -> None:
        nonlocal sent
        psm.servo_jp(_command(q + np.array([0.0001 * sent, 0, 0, 0, 0, 0])))
        sent += 1
        time.sleep(0.01)

    try:
        with PsmClient("PSM2", on_fault=faults.append, deadman_timeout_s=0.5) as psm:
            psm.wait_for_measurement(timeout_s=30.0)
            psm.home(timeout_s=10.0)
            q = psm.measure().q
            for _ in range(30):
                stream()
            assert not psm.status.holding, psm.status
            process.send_signal(signal.SIGKILL)
            process.wait(timeout=10.0)
            assert wait_until(lambda: stream() or psm.status.holding, timeout_s=30.0), psm.status
            status = psm.status
            assert status.holding and not status.ok
            assert status.reason.startswith(("stale", "publisher gone")), status.reason
            assert faults and faults[0].reason == status.reason
            assert psm.measure().q.shape == (6,)
    finally:
        stop(process, signal.SIGKILL)


def test_sim_dvrk_stops_cleanly_on_ctrl_c(ros_env: dict[str, str]) -> None:
    """SIGINT (Ctrl-C) once sim-dvrk serves ends it with exit status 0, no traceback and no callback error."""
    # Signalled after its start-up line, not after a sleep: on a loaded machine a sleep can end while
    # Python is still importing, where Ctrl-C is a KeyboardInterrupt traceback by design. At 1 kHz the
    # signal most often arrives while a callback runs.
    sim = start_sim(int(ros_env["ROS_DOMAIN_ID"]), "--arm", "PSM3", "--rate", "1000")
    status = sim.stop(signal.SIGINT)
    output = sim.output()
    assert status == 0, output
    assert "Traceback" not in output and "Exception in" not in output, output
