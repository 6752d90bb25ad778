"""A task seen over ROS 2: the policy's observation assembled from CRTK topics and a task source.

:class:`RemoteTask` has the parts of a task environment a policy reads (``observation_space``,
``action_space``, ``config``, ``goal``, ``grasp_position()``, ``site_position()``, ``scene.grasp.holding``),
so the simulation's scripted expert and trained checkpoints run unchanged against a dVRK. The arm's
part comes from the arm's own topics (``measured_cp``, ``jaw/measured_js``, ``body/measured_cf`` via
:class:`~hardware_if.client.psm_client.PsmClient`). The grasp site, the goal, the achieved goal and the grasped
flag come from one of two task sources:

- :class:`RegisteredSite`: a site the operator registered, a goal, and the jaw's own topics
  (:mod:`hardware_if.client.task_estimate`); no perception stack needed;
- :class:`TaskListener`: ``/<arm>/task/*`` (:data:`~hardware_if.common.task_topics.TASK_TOPICS`), which the
  simulated dVRK publishes and a perception node would on a robot.
"""

from __future__ import annotations

import collections
import threading
import time
from types import SimpleNamespace
from typing import Any

import numpy as np
from geometry_msgs.msg import PointStamped  # type: ignore[import-untyped]
from rclpy.node import Node
from std_msgs.msg import Bool, Int64  # type: ignore[import-untyped]

import sim.envs
from hardware_if.client.psm_client import PsmClient
from hardware_if.client.registration import console_base_frame, grasp_point
from hardware_if.client.task_estimate import TaskEstimate
from hardware_if.common.crtk import periodic_qos
from hardware_if.common.errors import DvrkTimeoutError
from hardware_if.common.session import SpinThread
from hardware_if.common.task_topics import task_topic
from psm_control.quaternion import quaternion_xyzw

__all__ = ["RegisteredSite", "RemoteTask", "TaskListener"]


class TaskListener(Node):
    """Subscribes to ``/<arm>/task/*`` and spins on its own thread (use as a context manager).

    Args:
        arm: Arm name.
        listen_only: Create no ``task/reset`` publisher (a dry run changes nothing).
    """

    #: What a deploy's success is judged by.
    success_source = "task topics"
    #: The state comes anew every period (the deploy waits for the one its last commands produced).
    state_each_period = True

    def __init__(self, arm: str, *, listen_only: bool = False) -> None:
        super().__init__(f"{arm.lower()}_task_listener_{time.monotonic_ns() % 100000}")
        self.arm = arm
        self._lock = threading.Condition()
        self._points: dict[str, np.ndarray] = {}
        self._stamps: dict[str, float] = {}
        self._grasped = False
        qos = periodic_qos()
        for name in ("site", "goal", "achieved_goal"):
            self.create_subscription(PointStamped, task_topic(arm, name), self._point_callback(name), qos)
        self.create_subscription(Bool, task_topic(arm, "grasped"), self._on_grasped, qos)
        self._resets: int | None = None
        self._resets_rx_s = float("-inf")
        self.create_subscription(Int64, task_topic(arm, "resets"), self._on_resets, qos)
        self._reset = None if listen_only else self.create_publisher(Int64, task_topic(arm, "reset"), qos)
        self._spinner = SpinThread(self, f"{arm}-task")

    def _point_callback(self, name: str) -> Any:
        def callback(message: PointStamped) -> None:
            with self._lock:
                self._points[name] = np.array([message.point.x, message.point.y, message.point.z])
                self._stamps[name] = time.monotonic()
                self._lock.notify_all()

        return callback

    def _on_resets(self, message: Int64) -> None:
        with self._lock:
            if self._resets != int(message.data):
                self._resets_rx_s = time.monotonic()
            self._resets = int(message.data)
            self._lock.notify_all()

    def _on_grasped(self, message: Bool) -> None:
        with self._lock:
            self._grasped = bool(message.data)

    def refresh(self, grasp_position: np.ndarray) -> None:
        """Nothing to do: the topics bring the task state."""

    def new_episode(self) -> None:
        """Nothing to forget: the topics bring the new episode's state."""

    def point(self, name: str) -> np.ndarray:
        """The latest ``site``, ``goal`` or ``achieved_goal`` [m] in ``<arm>_base``."""
        with self._lock:
            if name not in self._points:
                raise DvrkTimeoutError(f"{task_topic(self.arm, name)}", 0.0)
            return self._points[name].copy()

    @property
    def grasped(self) -> bool:
        """The latest ``task/grasped``."""
        with self._lock:
            return self._grasped

    def wait(self, timeout_s: float, *, after_s: float = float("-inf")) -> bool:
        """Block until site and goal arrived (both after ``after_s`` on ``time.monotonic``); False on timeout."""
        deadline = time.monotonic() + timeout_s
        with self._lock:
            while not all(self._stamps.get(n, float("-inf")) > after_s for n in ("site", "goal")):
                remaining = deadline - time.monotonic()
                if remaining <= 0.0:
                    return False
                self._lock.wait(min(remaining, 0.1))
            return True

    def serves_resets(self) -> bool:
        """True when the task's publisher counts its resets (the simulated dVRK), checked in the ROS graph."""
        return self.count_publishers(task_topic(self.arm, "resets")) > 0

    def reset_and_wait(self, seed: int, timeout_s: float) -> float:
        """Ask for a new episode and wait until the scene reports it done; return when that was seen.

        Returns:
            The ``time.monotonic`` [s] at which the new reset count arrived: task and arm states that
            arrive after it are of the new scene.

        Raises:
            DvrkTimeoutError: No reset subscriber, no count, or the count did not change in ``timeout_s``.
        """
        deadline = time.monotonic() + timeout_s
        with self._lock:
            while self._resets is None or self._reset is None or self._reset.get_subscription_count() == 0:
                remaining = deadline - time.monotonic()
                if remaining <= 0.0 or self._reset is None:
                    raise DvrkTimeoutError(f"{task_topic(self.arm, 'reset')} and its count", timeout_s)
                self._lock.wait(min(remaining, 0.02))
            before = self._resets
            self._reset.publish(Int64(data=int(seed)))
            while self._resets == before:
                remaining = deadline - time.monotonic()
                if remaining <= 0.0:
                    raise DvrkTimeoutError(f"a reset of the task scene (seed {seed})", timeout_s)
                self._lock.wait(min(remaining, 0.1))
            return self._resets_rx_s

    def request_reset(self, seed: int) -> bool:
        """Ask the simulated dVRK for a new episode; False for a listen-only listener."""
        if self._reset is None:
            return False
        self._reset.publish(Int64(data=int(seed)))
        return True

    def close(self) -> None:
        """Stop spinning and destroy the node."""
        self._spinner.close()

    def __enter__(self) -> TaskListener:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class RegisteredSite:
    """The task state from a registered site, a goal and the jaw (no ``/<arm>/task/*`` topic).

    Has the task source interface :class:`RemoteTask` and the deploy read (as :class:`TaskListener`).

    Args:
        estimate: The registration and goal, and the grasp sensing.
        client: The arm, whose ``jaw/measured_js`` and ``jaw/setpoint_js`` show a grasp.
    """

    #: What a deploy's success is judged by: an estimate, not a measurement of the tissue.
    success_source = "estimate (the registered site moved with the jaws)"
    #: The state is the registration moved with the jaws: nothing to wait for between steps.
    state_each_period = False

    def __init__(self, estimate: TaskEstimate, client: PsmClient) -> None:
        self.estimate, self.client = estimate, client

    def refresh(self, grasp_position: np.ndarray) -> None:
        """Take the jaw's latest reading and the grasp point [m] in ``<arm>_base``."""
        self.estimate.update(self.client.jaw_reading(), grasp_position)

    def point(self, name: str) -> np.ndarray:
        """The estimated ``site``, ``goal`` or ``achieved_goal`` [m] in ``<arm>_base``."""
        points = {"site": self.estimate.site, "goal": self.estimate.goal, "achieved_goal": self.estimate.achieved_goal}
        return np.asarray(points[name]).copy()

    @property
    def grasped(self) -> bool:
        """The jaw has stalled on tissue."""
        return self.estimate.grasped

    def wait(self, timeout_s: float, *, after_s: float = float("-inf")) -> bool:
        """Always ready: the registration does not arrive, it is given."""
        return True

    def serves_resets(self) -> bool:
        """A registered scene is the real one: nothing to reset."""
        return False

    def new_episode(self) -> None:
        """Nothing held at the start of an episode."""
        self.estimate.reset()

    def close(self) -> None:
        """Nothing to release."""


class RemoteTask:
    """The policy's view of a task over ROS 2 (see the module docstring).

    Args:
        task: Task id; its spaces and action scaling come from the task's simulation config.
        client: The arm.
        listener: The task source (:class:`TaskListener` or :class:`RegisteredSite`).
    """

    def __init__(self, task: str, client: PsmClient, listener: TaskListener | RegisteredSite) -> None:
        env = sim.envs.make(task)
        try:
            self.spec = env.spec  # the task's Gymnasium id names its shipped policy ("pretrained")
            self.observation_space = env.observation_space
            self.action_space = env.action_space
            self.config = env.unwrapped.config
            self.model = env.unwrapped.model
        finally:
            env.close()
        self.task = task
        self.client, self.listener = client, listener
        self.unwrapped = self
        # The simulated expert reads the environment's queue of delayed actions: over ROS the grasped flag
        # shows one step after the jaw closed (the console's state travels back), so the view reports one
        # step of latency carrying no motion; the expert then waits that step before re-opening.
        self._pending: collections.deque[np.ndarray] = collections.deque([np.zeros(5)])
        self._configuration = self.model.configuration()
        self.scene = SimpleNamespace(grasp=self)

    @property
    def force_sensing(self) -> str:
        """The console's force (``dvrk``), or the calibrated one (``dvrk-calibrated``): picks the shipped policy."""
        return self.client.force_sensing

    @property
    def holding(self) -> bool:
        """The jaw holds the tissue (``scene.grasp.holding``, from ``task/grasped``)."""
        return self.listener.grasped

    @property
    def goal(self) -> np.ndarray:
        """The desired goal [m] in ``<arm>_base``."""
        return self.listener.point("goal")

    def base_frame(self) -> np.ndarray:
        """Pose of the RCM in ``<arm>_base`` from ``measured_cp`` and ``local/measured_cp`` (4x4)."""
        return console_base_frame(self.client)

    def grasp_position(self) -> np.ndarray:
        """The point midway along the jaws [m] in ``<arm>_base``, by kinematics from the measured joints."""
        return grasp_point(self.client, self._configuration)

    def site_position(self) -> np.ndarray:
        """The grasp site [m] in ``<arm>_base``."""
        return self.listener.point("site")

    def success(self) -> tuple[bool, float]:
        """Whether the achieved goal is within the task's success threshold, and its distance [m]."""
        distance = float(np.linalg.norm(self.listener.point("achieved_goal") - self.goal))
        return distance <= self.config.success_threshold_m, distance

    def observation(self) -> dict[str, np.ndarray]:
        """The task's observation dict, laid out as the simulation's (tip pose, jaw, site, force, grasped)."""
        measured = self.client.measure()
        pose, _ = self.client.pose("measured_cp")
        tip = pose[:3, 3]
        self.listener.refresh(self.grasp_position())
        site = self.site_position()
        quaternion = quaternion_xyzw(pose[:3, :3])  # x, y, z, w
        vector = np.concatenate(
            [tip, quaternion, [measured.jaw], site, site - tip, measured.force_n, [float(self.holding)]]
        )
        return {
            "observation": vector.astype(np.float32),
            "achieved_goal": self.listener.point("achieved_goal").astype(np.float32),
            "desired_goal": self.goal.astype(np.float32),
        }
