"""The simulated endoscope on ROS 2: stereo images and camera info, as the dVRK's video pipeline publishes them.

The dVRK's video pipeline (``dvrk_video``'s gscam launch files; ``dvrk_magewell`` on ROS 2) publishes a
stereo rig named ``rig_name`` (default there ``jhu_daVinci``) as ``/<rig>/left/image_raw`` and
``/<rig>/right/image_raw`` (``sensor_msgs/Image``), each with ``camera_info`` beside it
(``sensor_msgs/CameraInfo``). ``sim-dvrk --task ID --endoscope`` publishes the same topics (``rgb8``,
128 x 96, the estimator's endoscope) at ``rate_hz`` (default 10 Hz; a 640 x 480 SD endoscope delivers 30,
PyBullet's CPU renderer about 20 stereo pairs a second on a free core).

Rendering takes 20-50 ms a pair, longer than the console's 10 ms tick, so it runs in a process of its
own (:func:`serve`): the console's process hands it the scene's state (episode seed, flap nodes, arm
joints, time) every frame period (:class:`EndoscopeStream`, latest state only), and it redraws that state
in a copy of the episode's scene built from the same seed: the flap's nodes are set (one physics substep
without gravity shows them, within 0.3 mm) and the arm is posed, then both eyes are drawn under the
episode's lighting (seeded by the episode seed, the endoscope at its nominal pose) with fresh sensor
noise. Each image is stamped with the time of the state it shows. Killing that process stops the stream
and nothing else: it ends quietly on SIGINT or SIGTERM (exit status 130 or 143), and the console's process
says once that the images stopped (:meth:`EndoscopeStream.ended`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import multiprocessing
import os
import signal
import time
from multiprocessing.connection import Connection
from typing import Any, NamedTuple

import numpy as np

from hardware_if.common.task_topics import DEFAULT_RIG, camera_topics

__all__ = ["EndoscopeStream", "SceneState", "serve"]

_APPEARANCE_STREAM = 36


class SceneState(NamedTuple):
    """What the render process needs to redraw the scene.

    Attributes:
        seed: The episode seed the scene was built from.
        nodes: (N, 3) flap node positions in the world [m].
        q: (6,) arm joints.
        jaw: Jaw angle [rad].
        stamp_s: Time of this state (the ROS clock, seconds since the epoch).
    """

    seed: int
    nodes: np.ndarray
    q: np.ndarray
    jaw: float
    stamp_s: float


class EndoscopeStream:
    """The console process's side: starts the render process and offers it the scene's state.

    Args:
        task: Task id of the scene.
        texture: The flap's texture file (None: procedural).
        rig: Stereo rig name (topic prefix).
        rate_hz: Frames per second.
    """

    def __init__(self, task: str, *, texture: str | None = None, rig: str = DEFAULT_RIG, rate_hz: float = 10.0) -> None:
        self.period_s = 1.0 / rate_hz
        self._next_s = 0.0
        context = multiprocessing.get_context("spawn")
        child, self._connection = context.Pipe(duplex=False)  # (receiving end, sending end)
        self.process = context.Process(target=serve, args=(task, texture, rig, child), name="endoscope", daemon=True)
        self.process.start()
        child.close()
        self._reported = False

    @property
    def pid(self) -> int | None:
        """The render process's id."""
        return self.process.pid

    def due(self) -> bool:
        """Whether a frame is due (one per period, while the render process runs)."""
        return time.monotonic() >= self._next_s and self.process.is_alive()

    def offer(self, state: SceneState) -> None:
        """Hand over the scene's state for the next frame; the period starts again."""
        self._next_s = time.monotonic() + self.period_s
        with contextlib.suppress(BrokenPipeError, OSError):  # the render process was stopped: the stream ends
            self._connection.send(state)

    def ended(self) -> str:
        """Once, after the render process ended on its own (killed, crashed): what to tell the user; else ''."""
        if self._reported or self.process.is_alive() or self.process.exitcode is None:
            return ""
        self._reported = True
        code = self.process.exitcode
        how = f"exit status {code}"
        with contextlib.suppress(ValueError):
            if code < 0 or code > 128:
                how = signal.Signals(-code if code < 0 else code - 128).name
        return f"endoscope: the render process {self.process.pid} ended ({how}): no more images; the console goes on"

    def close(self) -> None:
        """Stop the render process."""
        self._reported = True  # ended by us: nothing to report
        self._connection.close()
        self.process.join(timeout=5.0)
        if self.process.is_alive():
            self.process.terminate()


class _MirrorScene:
    """A copy of the episode's scene, posed from :class:`SceneState` and drawn by the endoscope."""

    def __init__(self, task: str, texture: str | None) -> None:
        import sim.envs
        from sim.tissue import TissueParams

        self.env: Any = sim.envs.make(task, tissue=TissueParams(texture_path=texture)).unwrapped
        self.seed: int | None = None
        self.appearance: Any = None
        self.rng = np.random.default_rng()

    def frame(self, state: SceneState) -> Any:
        import pybullet as p

        from sim.endoscope import Appearance

        env = self.env
        if state.seed != self.seed:
            env.reset(seed=int(state.seed))
            p.setGravity(0.0, 0.0, 0.0, physicsClientId=env.client)
            rng = np.random.default_rng([int(state.seed), _APPEARANCE_STREAM])
            drawn = Appearance.sample(rng, env.config.endoscope)
            # The endoscope at its nominal pose: a client knows where it is (its kinematics, a calibration).
            self.appearance = dataclasses.replace(
                drawn, eye_shift_m=(0.0,) * 3, target_shift_m=(0.0,) * 3, roll_rad=0.0
            )
            self.seed, self.rng = int(state.seed), rng
        p.resetMeshData(env.scene.tissue.body_id, vertices=np.asarray(state.nodes).tolist(), physicsClientId=env.client)
        p.stepSimulation(physicsClientId=env.client)  # draws the nodes just set (the render mesh follows a step)
        env.arm.reset_joints(np.asarray(state.q), float(state.jaw))
        return env.render_endoscope(self.appearance, self.rng)


def _messages(frame: Any, stamp_s: float, rig: str) -> dict[str, Any]:
    from sensor_msgs.msg import CameraInfo, Image  # type: ignore[import-untyped]  # the ros extra

    seconds = int(stamp_s)
    messages: dict[str, Any] = {}
    fx = float(frame.intrinsics[0, 0])
    for side, pixels in (("left", frame.left), ("right", frame.right)):
        image = Image()
        image.header.stamp.sec, image.header.stamp.nanosec = seconds, int((stamp_s - seconds) * 1e9)
        image.header.frame_id = f"{rig}_{side}"
        image.height, image.width = int(pixels.shape[0]), int(pixels.shape[1])
        image.encoding, image.is_bigendian, image.step = "rgb8", 0, int(3 * pixels.shape[1])
        image.data = np.ascontiguousarray(pixels).tobytes()
        info = CameraInfo()
        info.header = image.header
        info.height, info.width = image.height, image.width
        info.distortion_model = "plumb_bob"
        info.d = [0.0] * 5
        info.k = [float(v) for v in frame.intrinsics.ravel()]
        info.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        projection = np.zeros((3, 4))
        projection[:, :3] = frame.intrinsics
        if side == "right":  # ROS's stereo convention: P[0, 3] = -fx * baseline
            projection[0, 3] = -fx * frame.baseline_m
        info.p = [float(v) for v in projection.ravel()]
        messages[f"{side}_image"], messages[f"{side}_info"] = image, info
    return messages


class _Stopped(KeyboardInterrupt):
    """A stop signal reached the render process (the exit status is 128 + ``signum``)."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(signal.Signals(signum).name)


def _stop(signum: int, _frame: Any) -> None:
    raise _Stopped(signum)


def serve(task: str, texture: str | None, rig: str, connection: Connection) -> None:
    """The render process: redraw each state received and publish the pair, until the pipe closes or a stop signal.

    Stop signals are its own, not rclpy's: rclpy's shut the context down under the next publish, which then
    raised an ``RCLError`` and printed its traceback into the console's output.
    """
    import rclpy  # the ros extra, in this process of its own
    from rclpy.executors import ExternalShutdownException
    from rclpy.node import Node
    from rclpy.signals import SignalHandlerOptions
    from sensor_msgs.msg import CameraInfo, Image

    from hardware_if.common.crtk import periodic_qos

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _stop)
    stopped = 0
    mirror: _MirrorScene | None = None
    try:
        mirror = _MirrorScene(task, texture)
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
        node = Node(f"endoscope_{os.getpid()}")
        publishers = {
            key: node.create_publisher(Image if key.endswith("image") else CameraInfo, topic, periodic_qos())
            for key, topic in camera_topics(rig).items()
        }
        while True:
            try:
                state = connection.recv()
                while connection.poll():  # only the latest state is drawn
                    state = connection.recv()
            except (EOFError, OSError):
                break
            for key, message in _messages(mirror.frame(state), state.stamp_s, rig).items():
                publishers[key].publish(message)
    except _Stopped as e:
        stopped = e.signum
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RuntimeError:  # rclpy's RCLError: quiet only when the context ended under a publish
        if rclpy.ok():
            raise
    finally:
        with contextlib.suppress(_Stopped):  # a second signal while it closes
            if mirror is not None:
                mirror.env.close()
            if rclpy.ok():
                rclpy.shutdown()
    if stopped:
        raise SystemExit(128 + stopped)
