"""A task's PyBullet tissue scene behind the simulated dVRK (``tissue-retract sim-dvrk --task ID``).

:class:`TaskArm` is an :class:`~hardware_if.arm_model.ArmModel` that owns one task environment
(:func:`sim.envs.make`): the arm follows the joint set-points the console receives, the flap, the grasp
and the tissue force are the simulation's own, and the force goes out on ``body/measured_cf``. The
environment is driven through its public ``step``: its controller is replaced by :class:`SetpointFollower`,
which hands the physics the console's latest set-point on every tick (the environment's action is then
ignored), so the simulation's physics, grasp and tissue-force code run unchanged.

A policy also needs the grasp site, the goal and whether the jaw holds the tissue. On a real dVRK a
perception node supplies them, or an operator's registration and the jaw
(:mod:`hardware_if.task_estimate`). Here :class:`TaskTopics` publishes the simulation's ground truth on
extra, simulation-only topics under ``/<arm>/task/`` (see :data:`TASK_TOPICS`); a ``blind`` arm serves no
such topic and reports its jaw as a real one on tissue: stalled open on the held flap
(:meth:`sim.grasp.GraspParams.measured_jaw`), with a squeezing effort. :class:`TruthLog` writes the ground
truth to a file instead, to score a blind run.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import IO, Any

import numpy as np

import sim.envs
from hardware_if.arm_model import ArmSample
from hardware_if.crtk import periodic_qos
from psm_control.commands import CartesianDelta, ControlOutput, JointCommand, MeasuredState
from safety.config import SafetyConfig
from sim.scene import PhysicsParams

__all__ = [
    "JAW_LEVER_M",
    "TASK_PHYSICS_PERIOD_S",
    "TASK_TOPICS",
    "SetpointFollower",
    "TaskArm",
    "TaskTopics",
    "TruthLog",
    "task_arm_model",
]

#: Physics step of the served scene [s]: two 1/240 s substeps, the simulation's stable cloth step.
TASK_PHYSICS_PERIOD_S = 1.0 / 120.0
#: Distance of the grasp point from the jaw's pivot [m]: half the Large Needle Driver's jaw.
JAW_LEVER_M = 0.005
#: Simulation-only topics under ``/<arm>/task/`` (a perception node's job on a real robot).
TASK_TOPICS = {
    "site": "geometry_msgs/PointStamped: the grasp site on the flap, in <arm>_base [m]",
    "goal": "geometry_msgs/PointStamped: the desired goal (where the site must go), in <arm>_base [m]",
    "achieved_goal": "geometry_msgs/PointStamped: the task's achieved goal, in <arm>_base [m]",
    "grasped": "std_msgs/Bool: the jaw holds the flap",
    "reset": "std_msgs/Int64 (subscribed): rebuild the scene with this seed (a new episode)",
    "resets": "std_msgs/Int64: how many resets the scene has done (a client knows its reset took effect)",
}


def task_topic(arm: str, name: str) -> str:
    """The fully qualified name of a simulation-only task topic, e.g. ``/PSM1/task/site``."""
    if name not in TASK_TOPICS:
        raise KeyError(f"unknown task topic {name!r}; one of {', '.join(TASK_TOPICS)}")
    return f"/{arm}/task/{name}"


class SetpointFollower:
    """A :class:`~psm_control.commands.Controller` that outputs the latest external joint set-point.

    The simulated console owns the set-point (from ``servo_jp`` or its own trajectories); the
    environment's step asks this object for the command of each physics tick. ``config`` (the default
    :class:`~safety.config.SafetyConfig`, for the environment's workspace report) and an empty ``log``
    stand in for the control chain's attributes the environment reads.
    """

    def __init__(self, control_period_s: float, q: np.ndarray, jaw: float) -> None:
        self.control_period_s = control_period_s
        self.config = SafetyConfig()
        self.log: list[object] = []
        self.q = np.asarray(q, dtype=float).copy()
        self.jaw = float(jaw)
        self._zeros = np.zeros(6)

    def reset(self, measured: MeasuredState) -> None:
        """Nothing to forget: the set-point comes from outside."""

    def set_target(self, delta: CartesianDelta, measured: MeasuredState) -> None:
        """Ignored: the console's set-point, not an action, moves the arm."""

    def tick(self, measured: MeasuredState) -> ControlOutput:
        """The current set-point."""
        return ControlOutput(JointCommand(self.q.copy(), self._zeros, self._zeros, self.jaw, float(measured.stamp_s)))


class TaskArm:
    """The PSM in a task's tissue scene, following set-points in (simulated) real time.

    Args:
        task: Task id (``lift``, ``target``, ``multisite``, ``expose`` or a Gymnasium id).
        seed: Seed of the first episode (randomization of the flap, the RCM, ...).
        max_steps_per_call: Most physics steps one :meth:`step` runs; when the host cannot keep up,
            the simulation runs slower than the wall clock instead of falling ever further behind.
        blind: Report the jaw as a real one on tissue (stalled open on the held flap) for a client
            that senses the grasp with it.
    """

    instantaneous = False

    def __init__(self, task: str, *, seed: int = 0, max_steps_per_call: int = 6, blind: bool = False) -> None:
        self.blind = blind
        self._jaw = 0.0
        physics = PhysicsParams(substeps=2, control_period_s=TASK_PHYSICS_PERIOD_S)
        self.env: Any = sim.envs.make(task, physics=physics).unwrapped
        self.task = task
        self.step_s = physics.step_s
        self.max_steps_per_call = max_steps_per_call
        self.follower = SetpointFollower(physics.control_period_s, np.zeros(6), self.env.config.jaw_open_rad)
        self.env.controller, self.env.controller_name = self.follower, "sim-dvrk set-point follower"
        self._debt_s = 0.0
        self._qd = np.zeros(6)
        self.episode_seed = seed
        self._info: dict[str, Any] = {}
        self._achieved = np.zeros(3)
        self.reset_scene(seed)

    # -- the scene ---------------------------------------------------------------------------------
    def reset_scene(self, seed: int) -> None:
        """Rebuild the flap for a new episode; the arm stays at its set-point."""
        observation, self._info = self.env.reset(seed=seed)
        self._achieved = np.asarray(observation["achieved_goal"], dtype=float)
        self.episode_seed = seed
        self.env.backend.servo_jp(self.follower.tick(self.env.backend.measure()).command)
        self._info = {**self._info, "grasped": False}

    @property
    def base_frame(self) -> np.ndarray:
        """Pose of the RCM in the world (= ``<arm>_base``) for the current episode (4x4)."""
        return np.asarray(self.env.scene.configuration.base_frame).copy()

    @property
    def home_q(self) -> np.ndarray:
        """The task's start joints (the tool tip above the flap)."""
        return np.asarray(self.env.model.home(), dtype=float)

    def task_state(self) -> dict[str, Any]:
        """Ground truth a perception node would supply: site, goal, achieved goal [m], grasped; the grasp point."""
        return {
            "site": np.asarray(self.env.site_position(), dtype=float),
            "goal": np.asarray(self.env.goal, dtype=float),
            "achieved_goal": self._achieved.copy(),
            "grasped": bool(self.env.scene.grasp.holding),
            "grasp_point": np.asarray(self.env.grasp_position(), dtype=float),
        }

    def scene_markers(self) -> dict[str, Any]:
        """The flap, site, goal, grasp point and the force on it, in the world (= ``<arm>_base``)."""
        goal = np.asarray(self.env.goal, dtype=float)
        return {
            "nodes": self.env.scene.tissue.positions(),
            "triangles": self.env.scene.tissue.triangles,
            "site": np.asarray(self.env.site_position(), dtype=float),
            "goal": goal if goal.shape == (3,) else None,
            "grasp": np.asarray(self.env.grasp_position(), dtype=float),
            "force_n": np.asarray(self._info.get("force_n", np.zeros(3)), dtype=float),
        }

    # -- ArmModel ----------------------------------------------------------------------------------
    def reset(self, q: np.ndarray, jaw: float) -> ArmSample:
        """Place the arm at ``q`` in the current scene."""
        self.command(q, jaw)
        self.env.backend.servo_jp(self.follower.tick(self.env.backend.measure()).command)
        self._qd = np.zeros(6)
        return self._sample()

    def command(self, q: np.ndarray, jaw: float) -> None:
        """Set the set-point the arm holds during the next physics steps."""
        self.follower.q = np.asarray(q, dtype=float).copy()
        self.follower.jaw = float(jaw)

    def step(self, dt_s: float) -> ArmSample:
        """Run the physics steps that cover ``dt_s`` [s] (at most ``max_steps_per_call``)."""
        self._debt_s += max(dt_s, 0.0)
        before = np.asarray(self.env.backend.q, dtype=float).copy()
        steps = 0
        while self._debt_s >= self.step_s and steps < self.max_steps_per_call:
            observation, _, _, _, self._info = self.env.step(np.zeros(5))
            self._achieved = np.asarray(observation["achieved_goal"], dtype=float)
            self._debt_s -= self.step_s
            steps += 1
        if steps == self.max_steps_per_call:
            self._debt_s = min(self._debt_s, self.step_s)  # behind the wall clock: slow down, do not pile up
        if steps:
            self._qd = (np.asarray(self.env.backend.q, dtype=float) - before) / (steps * self.step_s)
        return self._sample(steps * self.step_s)

    def _sample(self, dt_s: float = 0.0) -> ArmSample:
        backend = self.env.backend
        force = np.asarray(self._info.get("force_n", np.zeros(3)), dtype=float)
        jaw, velocity, effort = float(backend.jaw), 0.0, 0.0
        if self.blind:
            grasp = self.env.config.grasp
            holding = bool(self.env.scene.grasp.holding)
            jaw = grasp.measured_jaw(backend.jaw, holding)
            velocity = (jaw - self._jaw) / dt_s if dt_s > 0 else 0.0
            # The servo squeezing the flap: the pinch force at the grasp point, half a jaw (5 mm) from the pivot.
            effort = -grasp.pinch_force_n * JAW_LEVER_M if holding else 0.0
        self._jaw = jaw
        q = np.asarray(backend.q, dtype=float).copy()
        return ArmSample(q, self._qd.copy(), jaw, force, velocity, effort)

    def close(self) -> None:
        """Release the physics client."""
        self.env.close()


class TaskTopics:
    """Publishes a :class:`TaskArm`'s ground truth on ``/<arm>/task/*`` and serves ``task/reset``.

    Args:
        node: The :class:`~hardware_if.sim_dvrk.SimulatedPsm` serving the arm (its base frame is
            updated when a reset moves the RCM).
        arm_model: The task scene.
    """

    def __init__(self, node: Any, arm_model: TaskArm) -> None:
        # The ros extra: message types, needed only when the scene is served over ROS 2.
        from geometry_msgs.msg import PointStamped  # type: ignore[import-untyped]
        from std_msgs.msg import Bool, Int64  # type: ignore[import-untyped]

        self.node, self.arm_model = node, arm_model
        self._point = PointStamped
        self._bool = Bool
        arm = node.topics.arm
        qos = periodic_qos()
        self._pub = {
            name: node.create_publisher(PointStamped, task_topic(arm, name), qos)
            for name in ("site", "goal", "achieved_goal")
        }
        self._grasped = node.create_publisher(Bool, task_topic(arm, "grasped"), qos)
        self._int = Int64
        self._resets = 0
        self._resets_pub = node.create_publisher(Int64, task_topic(arm, "resets"), qos)
        node.create_subscription(Int64, task_topic(arm, "reset"), self._on_reset, qos)
        node.create_timer(node.period_s, self._publish)

    def _on_reset(self, message: Any) -> None:
        self.arm_model.reset_scene(int(message.data))
        self.node.set_base_frame(self.arm_model.base_frame)
        self._resets += 1
        self.node.get_logger().info(f"task scene reset (seed {int(message.data)})")

    def _publish(self) -> None:
        from hardware_if import convert  # the ros extra (message types), as above

        state = self.arm_model.task_state()
        stamp = convert.seconds_to_time(float(self.node.get_clock().now().nanoseconds) * 1e-9)
        frame_id = self.node.topics.base_frame_id
        for name, publisher in self._pub.items():
            message = self._point()
            message.header.stamp, message.header.frame_id = stamp, frame_id
            message.point.x, message.point.y, message.point.z = (float(v) for v in state[name][:3])
            publisher.publish(message)
        self._grasped.publish(self._bool(data=state["grasped"]))
        # Last, after the state of the same period: a client that sees the count sees the new scene next.
        self._resets_pub.publish(self._int(data=self._resets))


class TruthLog:
    """Writes a :class:`TaskArm`'s ground truth as JSON lines, to score a run that could not see it.

    One line per policy period (the task's environment step): ``t`` [s since the log opened], ``grasped``,
    ``site``, ``achieved_goal``, ``goal``, ``grasp_point`` [m] in ``<arm>_base`` and ``distance_m`` (achieved
    goal to goal). Each line is flushed as written, so a killed server leaves every line but the last.

    Args:
        node: The node whose timer writes (the simulated console).
        arm_model: The task scene.
        path: The file (replaced).
    """

    def __init__(self, node: Any, arm_model: TaskArm, path: Path) -> None:
        self.arm_model = arm_model
        self._file: IO[str] = path.open("w", buffering=1)
        self._start_s = time.monotonic()
        node.create_timer(PhysicsParams().step_s, self.write)

    def write(self) -> None:
        """Write the current truth as one line."""
        state = self.arm_model.task_state()
        line = {
            "t": time.monotonic() - self._start_s,
            "grasped": state["grasped"],
            **{name: [float(v) for v in state[name]] for name in ("site", "achieved_goal", "goal", "grasp_point")},
            "distance_m": float(np.linalg.norm(state["achieved_goal"] - state["goal"])),
        }
        self._file.write(json.dumps(line) + "\n")

    def close(self) -> None:
        """Close the file."""
        self._file.close()


def task_arm_model(task: str, seed: int = 0) -> TaskArm:
    """The arm model of a task's tissue scene (see :class:`TaskArm`)."""
    return TaskArm(task, seed=seed)
