"""A task's PyBullet tissue scene behind the simulated dVRK (``tissue-retract sim-dvrk --task ID``).

:class:`TaskArm` is an :class:`~hardware_if.console.arm_model.ArmModel` that owns one task environment
(:func:`sim.envs.make`): the arm follows the joint set-points the console receives, the flap, the grasp
and the tissue force are the simulation's own, and the force goes out on ``body/measured_cf``. The
environment is driven through its public ``step``: its controller is replaced by :class:`SetpointFollower`,
which hands the physics the console's latest set-point on every tick (the environment's action is then
ignored), so the simulation's physics, grasp and tissue-force code run unchanged.

A policy also needs the grasp site, the goal and whether the jaw holds the tissue. On a real dVRK a
perception node supplies them, or an operator's registration and the jaw
(:mod:`hardware_if.client.task_estimate`). Here :class:`TaskTopics` publishes the simulation's ground truth on
extra, simulation-only topics under ``/<arm>/task/`` (see :data:`~hardware_if.common.task_topics.TASK_TOPICS`);
a ``blind`` arm serves no such topic and reports its jaw as a real one on tissue: stalled open on the held flap
(:meth:`sim.grasp.GraspParams.measured_jaw`), with a squeezing effort. :class:`TruthLog` writes the ground
truth to a file instead, to score a blind run.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

import numpy as np

from hardware_if.common.crtk import periodic_qos
from hardware_if.common.task_topics import task_topic
from hardware_if.console.arm_model import ArmSample, WindowedVelocity
from hardware_if.console.endoscope_stream import EndoscopeStream, SceneState
from hardware_if.console.motion import inverse_kinematics
from psm_control.commands import CartesianDelta, ControlOutput, JointCommand, MeasuredState
from safety.config import SafetyConfig
from safety.force_bound import ForceBound
from sim.strict_json import strict_dumps
from sim.tissue_params import SITE_NAMES, TissueParams

__all__ = [
    "JAW_LEVER_M",
    "PLACEABLE_SITES",
    "TASK_PHYSICS_PERIOD_S",
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
#: Where ``sim-dvrk --place-jaws-on`` can put the closed jaws: the episode's grasp site, or a named one.
PLACEABLE_SITES = ("site", *SITE_NAMES)
#: Physics steps with the same set-point after which the scene is checked for rest (1 s of simulated time).
REST_AFTER_STEPS = 120
#: Largest motion of any flap node over :data:`REST_AFTER_STEPS` steps for the scene to be at rest [m].
REST_MOTION_M = 1e-6
#: Grasp-point error at which the jaws count as on a site [m].
_PLACE_TOLERANCE_M = 1e-4


class SetpointFollower:
    """A :class:`~psm_control.commands.Controller` that outputs the latest external joint set-point.

    The simulated console owns the set-point (from ``servo_jp`` or its own trajectories); the
    environment's step asks this object for the command of each physics tick. ``config`` (the default
    :class:`~safety.config.SafetyConfig`, for the environment's workspace report), an empty ``log`` and a
    ``force_bound`` never updated (the travel bound is the deploying chain's, in its own process) stand in for
    the control chain's attributes the environment reads.
    """

    def __init__(self, control_period_s: float, q: np.ndarray, jaw: float) -> None:
        self.control_period_s = control_period_s
        self.config = SafetyConfig()
        self.log: list[object] = []
        self.force_bound = ForceBound.from_config(self.config)
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
        texture: The flap's texture image file (None: the procedural textures).
    """

    instantaneous = False

    def __init__(
        self, task: str, *, seed: int = 0, max_steps_per_call: int = 6, blind: bool = False, texture: str | None = None
    ) -> None:
        # The simulation (PyBullet) is loaded for the scene only: sim-dvrk checks its arguments without it.
        import sim.envs
        from sim.scene import PhysicsParams

        self.blind = blind
        self._jaw = 0.0
        physics = PhysicsParams(substeps=2, control_period_s=TASK_PHYSICS_PERIOD_S)
        self.env: Any = sim.envs.make(task, physics=physics, tissue=TissueParams(texture_path=texture)).unwrapped
        self.task = task
        self.step_s = physics.step_s
        self.max_steps_per_call = max_steps_per_call
        self.follower = SetpointFollower(physics.control_period_s, np.zeros(6), self.env.config.jaw_open_rad)
        self.env.controller, self.env.controller_name = self.follower, "sim-dvrk set-point follower"
        self._debt_s = 0.0
        self._velocity = WindowedVelocity()
        self.episode_seed = seed
        self._info: dict[str, Any] = {}
        self._achieved = np.zeros(3)
        #: Where the scene's state goes for the endoscope's images (``sim-dvrk --endoscope``); None: nowhere.
        self.endoscope: EndoscopeStream | None = None
        # Held while the scene is rebuilt (on a thread of its own, see TaskTopics): the console keeps
        # publishing the arm as it was instead of waiting for the new scene.
        self._scene_lock = threading.Lock()
        self._held = ArmSample(np.zeros(6), np.zeros(6), 0.0, np.zeros(3))
        self._state: dict[str, Any] = {}
        self._markers: dict[str, Any] = {}
        self._rest_setpoint = np.zeros(7)
        self._rest_nodes: np.ndarray | None = None
        self._still_steps = 0
        self._asleep = False
        self.reset_scene(seed)

    # -- the scene ---------------------------------------------------------------------------------
    def reset_scene(self, seed: int) -> np.ndarray:
        """Rebuild the flap for a new episode; the arm stays at its set-point.

        Safe to call from another thread than the one that steps: meanwhile :meth:`step` returns the arm
        as it was and no simulated time passes; the new scene's time starts when the reset ends.

        Returns:
            The new episode's RCM pose in the world (4x4), read while the new scene was current.
        """
        with self._scene_lock:
            observation, self._info = self.env.reset(seed=seed)
            self._achieved = np.asarray(observation["achieved_goal"], dtype=float)
            self.episode_seed = seed
            self.env.backend.servo_jp(self.follower.tick(self.env.backend.measure()).command)
            self._info = {**self._info, "grasped": False}
            self._debt_s = 0.0
            self._velocity.reset(self.env.backend.q)
            self._rest_nodes, self._still_steps, self._asleep = None, 0, False
            self._held = self._sample()
            self._state, self._markers = self._read_task_state(), self._read_scene_markers()
            return self._base_frame()

    def jaws_on(self, name: str) -> np.ndarray:
        """Joints that put the grasp point (closed jaws) on a site of the current scene, tool as at home.

        Args:
            name: ``site`` (the episode's grasp site) or one of the flap's named sites (``centre``, ...).

        Raises:
            KeyError: ``name`` is not in :data:`PLACEABLE_SITES`.
        """
        if name not in PLACEABLE_SITES:
            raise KeyError(f"unknown site {name!r}; one of {', '.join(PLACEABLE_SITES)}")
        with self._scene_lock:
            if name == "site":
                target = np.asarray(self.env.site_position(), dtype=float)
            else:
                tissue = self.env.scene.tissue
                nodes, weights = tissue.site_binding(tissue.site_local[name])
                target = np.asarray(weights @ tissue.positions()[nodes], dtype=float)
            base_frame = self._base_frame()
        configuration = self.env.model.configuration(self.home_q, base_frame=base_frame)
        configuration.update(self.home_q, 0.0)
        q = self.home_q
        for _ in range(10):  # the tip's goal moves by the grasp point's error: the orientation stays the home's
            error = target - np.asarray(configuration.grasp_position(), dtype=float)
            if np.linalg.norm(error) < _PLACE_TOLERANCE_M:
                break
            goal = np.asarray(configuration.local_pose(), dtype=float).copy()
            goal[:3, 3] += base_frame[:3, :3].T @ error
            q, _ = inverse_kinematics(configuration, goal)
            configuration.update(q, 0.0)
        return np.asarray(q, dtype=float)

    @property
    def at_rest(self) -> bool:
        """True while the scene sleeps: the same set-point for a while and the flap still."""
        return self._asleep

    @property
    def resetting(self) -> bool:
        """True while a scene reset runs."""
        return self._scene_lock.locked()

    @property
    def base_frame(self) -> np.ndarray:
        """Pose of the RCM in the world (= ``<arm>_base``) for the current episode (4x4)."""
        with self._scene_lock:
            return self._base_frame()

    def _base_frame(self) -> np.ndarray:
        return np.asarray(self.env.scene.configuration.base_frame).copy()

    @property
    def home_q(self) -> np.ndarray:
        """The task's start joints (the tool tip above the flap)."""
        return np.asarray(self.env.model.home(), dtype=float)

    def task_state(self) -> dict[str, Any]:
        """Ground truth a perception node would supply: site, goal, achieved goal [m], grasped; the grasp point.

        During a scene reset: the last state before it.
        """
        self._state = self._unless_resetting(self._read_task_state, self._state)
        return dict(self._state)

    def _unless_resetting(self, read: Callable[[], dict[str, Any]], last: dict[str, Any]) -> dict[str, Any]:
        """``read()`` of the current scene, or ``last`` while a reset rebuilds it."""
        if not self._scene_lock.acquire(blocking=False):
            return last
        try:
            return read()
        finally:
            self._scene_lock.release()

    def _read_task_state(self) -> dict[str, Any]:
        return {
            "seed": self.episode_seed,
            "site": np.asarray(self.env.site_position(), dtype=float),
            "goal": np.asarray(self.env.goal, dtype=float),
            "achieved_goal": self._achieved.copy(),
            "grasped": bool(self.env.scene.grasp.holding),
            "grasp_point": np.asarray(self.env.grasp_position(), dtype=float),
        }

    def scene_markers(self) -> dict[str, Any]:
        """The flap, site, goal, grasp point and the force on it, in the world (= ``<arm>_base``).

        During a scene reset: the last markers before it.
        """
        self._markers = self._unless_resetting(self._read_scene_markers, self._markers)
        return dict(self._markers)

    def _read_scene_markers(self) -> dict[str, Any]:
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
        with self._scene_lock:
            self.env.backend.servo_jp(self.follower.tick(self.env.backend.measure()).command)
            self._velocity.reset(self.env.backend.q)
            self._held = self._sample()
            return self._held

    def command(self, q: np.ndarray, jaw: float) -> None:
        """Set the set-point the arm holds during the next physics steps."""
        self.follower.q = np.asarray(q, dtype=float).copy()
        self.follower.jaw = float(jaw)

    def step(self, dt_s: float) -> ArmSample:
        """Run the physics steps that cover ``dt_s`` [s] (at most ``max_steps_per_call``).

        During a scene reset the arm is returned as it was and no simulated time passes.
        """
        if not self._scene_lock.acquire(blocking=False):
            return self._held._replace(elapsed_s=0.0)
        try:
            self._held = self._step(dt_s)
            return self._held
        finally:
            self._scene_lock.release()

    def _step(self, dt_s: float) -> ArmSample:
        if self._at_rest():  # a still scene is not stepped, but the endoscope keeps filming it
            self._debt_s = 0.0
            self._velocity.reset(self.env.backend.q)
            self._offer_frame()
            return self._held._replace(qd=self._velocity.qd.copy(), elapsed_s=0.0)
        self._debt_s += max(dt_s, 0.0)
        steps = 0
        while self._debt_s >= self.step_s and steps < self.max_steps_per_call:
            observation, _, _, _, self._info = self.env.step(np.zeros(5))
            self._achieved = np.asarray(observation["achieved_goal"], dtype=float)
            self._debt_s -= self.step_s
            steps += 1
        self._still_steps += steps
        if steps == self.max_steps_per_call:
            self._debt_s = min(self._debt_s, self.step_s)  # behind the wall clock: slow down, do not pile up
        self._velocity.advance(self.env.backend.q, steps * self.step_s)  # no step: the velocity stands
        self._offer_frame()
        return self._sample(steps * self.step_s)

    def _offer_frame(self) -> None:
        """Give the endoscope the scene when a frame is due (``sim-dvrk --endoscope``)."""
        if self.endoscope is not None and self.endoscope.due():
            backend = self.env.backend
            nodes = self.env.scene.tissue.positions()
            self.endoscope.offer(
                SceneState(self.episode_seed, nodes, backend.q.copy(), float(backend.jaw), time.time())
            )

    def _at_rest(self) -> bool:
        """True when stepping would change nothing: the same set-point for a while and the flap still.

        An idle console then costs no physics (an idle sim-dvrk stepped the cloth 120 times a second for
        nothing, held or not). A held flap at rest stays held: the grasp lets go only of a pull above its
        capacity, which a still flap does not change. A new set-point or a reset wakes it.
        """
        setpoint = np.append(self.follower.q, self.follower.jaw)
        if not np.array_equal(setpoint, self._rest_setpoint):
            self._rest_setpoint, self._still_steps, self._rest_nodes, self._asleep = setpoint, 0, None, False
            return False
        if self._asleep or self._still_steps < REST_AFTER_STEPS:
            return self._asleep
        nodes = np.asarray(self.env.scene.tissue.positions(), dtype=float)
        last, self._rest_nodes, self._still_steps = self._rest_nodes, nodes, 0
        self._asleep = last is not None and float(np.max(np.abs(nodes - last))) < REST_MOTION_M
        return self._asleep

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
        return ArmSample(q, self._velocity.qd.copy(), jaw, force, velocity, effort, elapsed_s=dt_s)

    def close(self) -> None:
        """Release the physics client (after a reset that is running)."""
        with self._scene_lock:
            self.env.close()


class TaskTopics:
    """Publishes a :class:`TaskArm`'s ground truth on ``/<arm>/task/*`` and serves ``task/reset``.

    Args:
        node: The :class:`~hardware_if.console.sim_dvrk.SimulatedPsm` serving the arm (its base frame is
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
        # A reset rebuilds the scene on a thread of its own: the console's timer keeps publishing the arm
        # (measured_js at its rate) meanwhile, so a client's deadman never sees the simulator's reset as a
        # dead robot. Finished resets are taken up on the executor's thread, in _publish.
        self._requests: queue.SimpleQueue[int | None] = queue.SimpleQueue()
        self._finished: queue.SimpleQueue[tuple[int, np.ndarray]] = queue.SimpleQueue()
        self._worker = threading.Thread(target=self._reset_scenes, name=f"{arm}-scene-reset", daemon=True)
        self._worker.start()
        node.create_subscription(Int64, task_topic(arm, "reset"), self._on_reset, qos)
        node.create_timer(node.period_s, self._publish)

    def _on_reset(self, message: Any) -> None:
        self._requests.put(int(message.data))

    def _reset_scenes(self) -> None:
        while (seed := self._requests.get()) is not None:
            self._finished.put((seed, self.arm_model.reset_scene(seed)))

    def close(self) -> None:
        """Stop the reset thread after the reset it runs, if any."""
        self._requests.put(None)
        self._worker.join(timeout=10.0)

    def _publish(self) -> None:
        from hardware_if.common import convert  # the ros extra (message types), as above

        while not self._finished.empty():
            seed, base_frame = self._finished.get()
            self.node.set_base_frame(base_frame)
            self._resets += 1
            self.node.get_logger().info(f"task scene reset (seed {seed})")
        if self.arm_model.resetting:
            return  # the old scene's state is not news, and the new scene's is not ready yet
        publishers = [*self._pub.values(), self._grasped, self._resets_pub]
        if not any(publisher.get_subscription_count() for publisher in publishers):
            return  # nobody listens: an idle console builds nothing (a subscriber gets the next period's)
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

    One line per policy period (the task's environment step): ``t`` [s since the log opened], the episode's
    ``seed``, ``grasped``,
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
        from sim.scene import PhysicsParams  # loaded with the task's scene already

        node.create_timer(PhysicsParams().step_s, self.write)

    def write(self) -> None:
        """Write the current truth as one line."""
        state = self.arm_model.task_state()
        line = {
            "t": time.monotonic() - self._start_s,
            "seed": state["seed"],
            "grasped": state["grasped"],
            **{name: [float(v) for v in state[name]] for name in ("site", "achieved_goal", "goal", "grasp_point")},
            "distance_m": float(np.linalg.norm(state["achieved_goal"] - state["goal"])),
            # The true tissue force, whatever the console makes of it.
            "force_n": float(np.linalg.norm(self.arm_model.scene_markers()["force_n"])),
        }
        self._file.write(strict_dumps(line) + "\n")

    def close(self) -> None:
        """Close the file."""
        self._file.close()


def task_arm_model(task: str, seed: int = 0) -> TaskArm:
    """The arm model of a task's tissue scene (see :class:`TaskArm`)."""
    return TaskArm(task, seed=seed)
