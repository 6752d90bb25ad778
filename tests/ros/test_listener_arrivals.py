"""A ``measured_js`` judged late by when it arrived, not by when this process got round to it."""

from __future__ import annotations

import threading
import time

import pytest
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import JointState  # type: ignore[import-untyped]

from hardware_if.client.arm_listener import ArmListener
from hardware_if.client.deadman import STAMP_JUMP_S
from hardware_if.common.convert import joint_state
from hardware_if.common.crtk import JOINT_NAMES, ArmTopics, periodic_qos


@pytest.mark.parametrize("first", [False, True], ids=["a later measurement", "the first measurement"])
def test_a_callback_run_late_is_no_clock_that_jumped(first: bool) -> None:
    """The listener's process is busy for longer than the stamp-jump allowance while a message waits for its
    callback (here its own measurement hook, as a recording's write could be): the next, fresh measurement is
    not a stamp that jumped ahead, and the stream goes on without a data fault. Also when the late one is the
    first measurement it takes (a process still starting, before its clock is pinned): nothing earlier tells
    that it was late, so the fresh one after it starts the baseline afresh."""
    context = rclpy.Context()
    rclpy.init(context=context)
    arm = "PSM5"
    source = Node(f"source_{time.monotonic_ns()}", context=context)
    publisher = source.create_publisher(JointState, ArmTopics(arm).topic("measured_js"), periodic_qos())
    stop = threading.Event()

    def publish_at_100_hz() -> None:
        while not stop.is_set():
            publisher.publish(joint_state(JOINT_NAMES, [0.0, 0.0, 0.12, 0.0, 0.0, 0.0], stamp_s=time.time()))
            time.sleep(0.01)

    busy = threading.Event()  # set: the next measurement's hook keeps the listener's thread busy
    stalled: list[float] = []

    def hook(message: JointState, _at: float) -> None:
        if busy.is_set():
            busy.clear()
            time.sleep(1.5 * STAMP_JUMP_S)
            stalled.append(time.monotonic())

    publishing = threading.Thread(target=publish_at_100_hz, daemon=True)
    publishing.start()
    listener = ArmListener(arm, node_name=f"listener_{time.monotonic_ns()}", on_measured=hook, context=context)
    try:
        if first:
            busy.set()
        listener.start()
        before = listener.wait_for_measurement(timeout_s=20.0)
        busy.set()
        # Measurements stamped after the stall are taken, and no data fault is latched on the way (it raises).
        deadline = time.monotonic() + 30.0
        while listener.wait_for_measurement().stamp_s < before.stamp_s + 2.0 * STAMP_JUMP_S:
            assert time.monotonic() < deadline, "no measurement after the stall was taken"
            time.sleep(0.01)
        assert stalled, "the measurement hook never kept the listener busy"
    finally:
        stop.set()
        publishing.join()
        listener.close()
        source.destroy_node()
        rclpy.shutdown(context=context)
