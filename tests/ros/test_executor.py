"""The events executor starts under captured output, and a client closed mid-stream on it ends cleanly."""

from __future__ import annotations

import sys
import threading
import time

import rclpy
from rclpy.node import Node
from sensor_msgs.msg import JointState  # type: ignore[import-untyped]

from hardware_if.client.psm_client import PsmClient
from hardware_if.common.convert import joint_state
from hardware_if.common.crtk import JOINT_NAMES, ArmTopics, periodic_qos
from hardware_if.common.executor import make_executor


def test_events_executor_starts_where_stderr_has_no_descriptor() -> None:
    """Under pytest's captured stderr the events executor is made, spins a node, and stderr is left as it was."""
    context = rclpy.Context()
    rclpy.init(context=context)
    stderr = sys.stderr
    try:
        executor = make_executor(context)
        assert sys.stderr is stderr
        assert type(executor).__name__ == "EventsExecutor"
        node = Node(f"ticker_{time.monotonic_ns()}", context=context)
        ticks: list[float] = []
        node.create_timer(0.001, lambda: ticks.append(time.monotonic()))
        executor.add_node(node)
        deadline = time.monotonic() + 10.0
        while len(ticks) < 20 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        assert len(ticks) >= 20
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_client_closed_while_its_stream_runs_ends_cleanly() -> None:
    """A client closed while measured_js pours in at 2 kHz leaves no thread behind, five times in a row."""
    context = rclpy.Context()
    rclpy.init(context=context)
    arm = "PSM7"
    source = Node(f"source_{time.monotonic_ns()}", context=context)
    publisher = source.create_publisher(JointState, ArmTopics(arm).topic("measured_js"), periodic_qos())
    stop = threading.Event()

    def pour() -> None:
        q = [0.0, 0.0, 0.12, 0.0, 0.0, 0.0]
        while not stop.is_set():
            publisher.publish(joint_state(JOINT_NAMES, q, stamp_s=time.time()))
            time.sleep(0.0005)

    pourer = threading.Thread(target=pour, daemon=True)
    pourer.start()
    try:
        for k in range(5):
            client = PsmClient(arm, node_name=f"client_{k}_{time.monotonic_ns()}", context=context).start()
            client.wait_for_measurement(timeout_s=20.0)
            spinner = client._spinner
            client.close()
            client.close()  # a second close is a no-op
            assert spinner is not None and not spinner.thread.is_alive()
    finally:
        stop.set()
        pourer.join()
        source.destroy_node()
        rclpy.shutdown(context=context)
