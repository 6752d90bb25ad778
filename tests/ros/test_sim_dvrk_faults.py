"""The simulated console's faults, in-process over loopback DDS: a SimulatedPsm whose arm cannot follow, and one
whose clock on measured_js goes wrong (--stamp-fault)."""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest
import rclpy
from crtk_msgs.msg import OperatingState, StringStamped
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from ros_process import wait_until
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from hardware_if.common.crtk import JOINT_NAMES, ArmTopics, event_qos, periodic_qos
from hardware_if.console.arm_model import ArmSample, KinematicArm
from hardware_if.console.sim_dvrk import SimulatedPsm
from hardware_if.console.stamp_fault import JUMP_S, PAST_S, StampFault


class BlockedInsertion(KinematicArm):
    """A kinematic arm whose insertion joint is blocked at 0 (a collision the servo cannot overcome)."""

    def step(self, dt_s: float) -> ArmSample:
        sample = super().step(dt_s)
        q = sample.q.copy()
        q[2] = 0.0
        return sample._replace(q=q)


class Operator(Node):
    """What a client sees: operating states and errors; what it sends: state commands and move_jp."""

    def __init__(self, arm: str, context: rclpy.Context) -> None:
        super().__init__(f"operator_{time.monotonic_ns()}", context=context)
        t = ArmTopics(arm).topic
        self.states: list[OperatingState] = []
        self.errors: list[str] = []
        self.create_subscription(OperatingState, t("operating_state"), self.states.append, event_qos())
        self.create_subscription(String, t("error"), lambda m: self.errors.append(m.data), event_qos())
        self.command = self.create_publisher(StringStamped, t("state_command"), event_qos())
        self.move = self.create_publisher(JointState, t("move_jp"), periodic_qos())

    def state(self) -> tuple[str, bool, bool]:
        last = self.states[-1] if self.states else OperatingState()
        return last.state, last.is_homed, last.is_busy


@pytest.fixture
def console() -> Iterator[tuple[SimulatedPsm, Operator]]:
    """A SimulatedPsm (PSM5, blocked insertion, no homing delay) and an operator node, spun in a thread."""
    context = rclpy.Context()
    rclpy.init(context=context)
    sim = SimulatedPsm("PSM5", arm_model=BlockedInsertion(), homing_settle_s=0.0, context=context)
    operator = Operator("PSM5", context=context)
    executor = MultiThreadedExecutor(context=context)
    executor.add_node(sim)
    executor.add_node(operator)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    yield sim, operator
    executor.shutdown()
    thread.join(timeout=5.0)  # before the context goes: a spin still waiting on it raises in its thread
    sim.destroy_node()
    operator.destroy_node()
    rclpy.shutdown(context=context)


def _send(operator: Operator, command: str) -> None:
    operator.command.publish(StringStamped(string=command))


def test_tracking_error_trips_to_fault_and_enable_recovers(console: tuple[SimulatedPsm, Operator]) -> None:
    """Insertion held back by more than 50 mm -> FAULT with an error naming the joint; enable recovers."""
    sim, operator = console
    assert wait_until(lambda: operator.command.get_subscription_count() > 0 and operator.states, timeout_s=30.0)
    _send(operator, "home")
    assert wait_until(lambda: operator.state() == ("ENABLED", True, False), timeout_s=30.0), operator.states
    assert wait_until(lambda: operator.move.get_subscription_count() > 0, timeout_s=30.0)
    goal = JointState(name=list(JOINT_NAMES))
    goal.position = [0.0, 0.0, 0.2, 0.0, 0.0, 0.0]
    operator.move.publish(goal)
    assert wait_until(lambda: operator.state()[0] == "FAULT", timeout_s=30.0), operator.states
    assert not operator.state()[2]
    assert wait_until(lambda: any("tracking error" in e and "'insertion'" in e for e in operator.errors), 10.0)
    setpoint_at_fault = sim._setpoint_q[2]
    assert 0.05 < setpoint_at_fault < 0.2  # stopped at the trip, not at the goal

    errors = len(operator.errors)
    operator.move.publish(goal)
    assert wait_until(lambda: len(operator.errors) > errors, 10.0)
    assert "not ready" in operator.errors[-1]  # a FAULT arm refuses motion

    _send(operator, "enable")
    assert wait_until(lambda: operator.state()[0] == "ENABLED", timeout_s=30.0)
    np.testing.assert_allclose(sim._setpoint_q, np.zeros(6), atol=1e-12)  # recovered where the arm is


class Listener(Node):
    """What a client receives on measured_js (each stamp with its arrival on the wall clock) and on warning."""

    def __init__(self, arm: str, context: rclpy.Context) -> None:
        super().__init__(f"listener_{time.monotonic_ns()}", context=context)
        t = ArmTopics(arm).topic
        self.lock = threading.Lock()
        self.arrivals: list[tuple[float, float]] = []
        self.warnings: list[str] = []
        self.create_subscription(JointState, t("measured_js"), self._on_measured, periodic_qos())
        self.create_subscription(String, t("warning"), lambda m: self.warnings.append(m.data), event_qos())
        self.servo = self.create_publisher(JointState, t("servo_jp"), periodic_qos())

    def _on_measured(self, message: JointState) -> None:
        stamp = message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec
        with self.lock:
            self.arrivals.append((stamp, time.time()))

    def since(self, start: int) -> list[tuple[float, float]]:
        with self.lock:
            return self.arrivals[start:]


@pytest.mark.parametrize("mode", ["frozen", "past", "jump"])
def test_stamp_fault_breaks_the_measured_js_clock_after_the_nth_servo_command(mode: str) -> None:
    """sim-dvrk's --stamp-fault: measured_js is stamped with the console's clock until the N-th servo_jp; then
    frozen repeats the last message, past stamps 5 s in the past, jump stamps 1 h ahead once and repeats it."""
    context = rclpy.Context()
    rclpy.init(context=context)
    fault = StampFault(mode, after_commands=3)
    sim = SimulatedPsm("PSM6", homing_settle_s=0.0, context=context, stamp_fault=fault)
    listener = Listener("PSM6", context)
    operator = Operator("PSM6", context)
    executor = MultiThreadedExecutor(context=context)
    for node in (sim, listener, operator):
        executor.add_node(node)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    try:
        assert wait_until(lambda: operator.command.get_subscription_count() > 0 and operator.states, timeout_s=30.0)
        _send(operator, "home")
        assert wait_until(lambda: operator.state() == ("ENABLED", True, False), timeout_s=30.0), operator.states
        assert wait_until(lambda: listener.servo.get_subscription_count() > 0, timeout_s=30.0)
        goal = JointState(name=list(JOINT_NAMES))
        goal.position = [0.0, 0.0, 0.1, 0.0, 0.0, 0.0]
        for _ in range(2):
            listener.servo.publish(goal)
        assert wait_until(lambda: len(listener.since(0)) >= 5, timeout_s=30.0)
        assert not fault.active
        stamps = [stamp for stamp, _ in listener.since(0)]
        assert all(b > a for a, b in itertools.pairwise(stamps)), "the console's clock advances"
        listener.servo.publish(goal)  # the third: the fault starts with the next measured_js
        assert wait_until(lambda: fault.active, timeout_s=30.0)
        assert wait_until(lambda: any("injected fault" in w for w in listener.warnings), timeout_s=30.0)
        start = len(listener.since(0))
        assert wait_until(lambda: len(listener.since(start)) >= 30, timeout_s=30.0)
        faulty = listener.since(start)[-10:]  # long after the fault started, whatever arrived late
        behind = [arrived - stamp for stamp, arrived in faulty]  # how far each stamp is behind its arrival [s]
        if mode == "frozen":
            assert len({stamp for stamp, _ in faulty}) == 1, "the same stamp again and again"
        elif mode == "past":
            assert all(PAST_S <= b < PAST_S + 10.0 for b in behind), behind
            assert all(b[0] > a[0] for a, b in itertools.pairwise(faulty)), "and advancing"
        else:
            assert len({stamp for stamp, _ in faulty}) == 1, "one stamp, repeated"
            assert all(-JUMP_S <= b < -JUMP_S + 10.0 for b in behind), behind
    finally:
        executor.shutdown()
        thread.join(timeout=5.0)
        for node in (sim, listener, operator):
            node.destroy_node()
        rclpy.shutdown(context=context)
