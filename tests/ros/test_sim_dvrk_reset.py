"""A task scene reset in the simulated console, in-process over loopback DDS: the arm's state keeps coming."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Int64

from hardware_if.common.crtk import ArmTopics, periodic_qos
from hardware_if.common.executor import make_executor
from hardware_if.common.task_topics import task_topic
from hardware_if.console.sim_dvrk import SimulatedPsm
from hardware_if.console.sim_task import TaskArm, TaskTopics

#: measured_js messages the client must receive while one reset runs (5 periods: the deadman's timeout).
_DURING_RESET = 5


class GatedResetArm(TaskArm):
    """The lift scene, whose next reset lasts until the test opens the gate (a reset on a loaded host)."""

    def __init__(self) -> None:
        super().__init__("lift", seed=0)
        self.entered = threading.Event()
        self.gate = threading.Event()

    def reset_scene(self, seed: int) -> np.ndarray:
        if seed > 0:  # the constructor's own reset is not gated
            self.entered.set()
            self.gate.wait(timeout=30.0)
        return super().reset_scene(seed)


class Client(Node):
    """Counts measured_js and reads the reset count; sends resets."""

    def __init__(self, context: rclpy.Context) -> None:
        super().__init__(f"client_{time.monotonic_ns()}", context=context)
        self.measured = 0
        self.resets = -1
        self.arrived = threading.Condition()
        self.create_subscription(JointState, ArmTopics("PSM4").topic("measured_js"), self._on_js, periodic_qos())
        self.create_subscription(Int64, task_topic("PSM4", "resets"), self._on_resets, periodic_qos())
        self.reset = self.create_publisher(Int64, task_topic("PSM4", "reset"), periodic_qos())

    def _on_js(self, _message: JointState) -> None:
        with self.arrived:
            self.measured += 1
            self.arrived.notify_all()

    def _on_resets(self, message: Int64) -> None:
        with self.arrived:
            self.resets = int(message.data)
            self.arrived.notify_all()


@pytest.fixture
def console() -> Iterator[tuple[GatedResetArm, Client]]:
    """A SimulatedPsm (PSM4) on a gated lift scene with its task topics, and a client, spun in a thread."""
    context = rclpy.Context()
    rclpy.init(context=context)
    arm = GatedResetArm()
    sim = SimulatedPsm("PSM4", arm_model=arm, base_frame=arm.base_frame, homing_settle_s=0.0, context=context)
    topics = TaskTopics(sim, arm)
    client = Client(context)
    executor = make_executor(context)
    executor.add_node(sim)
    executor.add_node(client)
    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.05)

    thread = threading.Thread(target=spin, daemon=True)
    thread.start()
    yield arm, client
    arm.gate.set()
    stop.set()
    thread.join(timeout=5.0)
    topics.close()
    executor.shutdown()
    sim.destroy_node()
    client.destroy_node()
    rclpy.shutdown(context=context)
    arm.close()


def test_measured_js_keeps_coming_while_the_scene_resets(console: tuple[GatedResetArm, Client]) -> None:
    """While a scene reset runs, measured_js keeps arriving; the count changes only after the reset ends."""
    arm, client = console
    with client.arrived:
        assert client.arrived.wait_for(lambda: client.resets == 0, timeout=20.0), "no reset count from the console"
    client.reset.publish(Int64(data=7))
    assert arm.entered.wait(timeout=20.0), "the reset never started"
    with client.arrived:
        before = client.measured
        kept_coming = client.arrived.wait_for(lambda: client.measured >= before + _DURING_RESET, timeout=10.0)
        assert client.resets == 0, "the count changed before the reset ended"
    arm.gate.set()
    assert kept_coming, f"measured_js stopped during the scene reset ({client.measured - before} messages)"
    with client.arrived:
        assert client.arrived.wait_for(lambda: client.resets == 1, timeout=20.0), "the reset never finished"
    assert arm.episode_seed == 7
