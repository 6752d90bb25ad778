"""The grasp site seen by the endoscope over ROS 2 (``deploy --target dvrk --perception camera``).

:class:`CameraSite` is a task source for :class:`~hardware_if.client.remote_task.RemoteTask`, like
:class:`~hardware_if.client.remote_task.RegisteredSite`, with the camera in the operator's place. It subscribes
to a stereo rig's ``/<rig>/{left,right}/image_raw`` and ``camera_info`` (the dVRK video pipeline's
names, :mod:`hardware_if.common.task_topics`). At each episode's start it waits for a stereo pair taken
after that moment (left and right with the same stamp), checks the camera info against the endoscope
the estimator was trained for, estimates the sites, and registers the task's site; the goal is the
task's nominal goal about it, the grasp the jaw's (:mod:`hardware_if.client.task_estimate`). No
``/<arm>/task/*`` topic and no registration are read.

The images are a topic like any other: while an episode runs, an observation taken when the last pair
arrived more than ``stale_after_s`` ago (default 0.5 s, five frames at 10 Hz) is refused, and the deploy
holds the arm (``stale``), as it does for a stale ``measured_js``.

The camera's pose in ``<arm>_base`` is the simulated endoscope's nominal pose (``sim-dvrk``'s world is
its ``<arm>_base``); a real endoscope's would come from a hand-eye calibration, which this does not take.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image  # type: ignore[import-untyped]

import sim.envs
from hardware_if.client.psm_client import PsmClient
from hardware_if.client.task_estimate import TaskEstimate
from hardware_if.common.crtk import periodic_qos
from hardware_if.common.errors import HoldError
from hardware_if.common.session import SpinThread
from hardware_if.common.task_topics import DEFAULT_RIG, camera_topics
from sim.endoscope import StereoFrame, look_at
from sim.tissue import SITE_NAMES

__all__ = ["CameraSite"]


def image_array(message: Any) -> np.ndarray:
    """An ``rgb8`` or ``bgr8`` image message as (H, W, 3) uint8 RGB.

    Raises:
        HoldError: Another encoding, or data that does not fill the image.
    """
    encoding = str(message.encoding)
    height, width, step = int(message.height), int(message.width), int(message.step)
    data = np.frombuffer(bytes(message.data), dtype=np.uint8)
    if encoding not in ("rgb8", "bgr8") or step < 3 * width or data.size < step * height:
        raise HoldError(
            "invalid data", f"endoscope image {width}x{height} {encoding!r}: rgb8 or bgr8, filled, expected"
        )
    pixels = data[: step * height].reshape(height, step)[:, : 3 * width].reshape(height, width, 3)
    return pixels[:, :, ::-1].copy() if encoding == "bgr8" else pixels.copy()


class CameraSite(Node):
    """The task state from the endoscope's images, a nominal goal and the jaw (spins on its own thread).

    Args:
        task: Task id (its nominal goal about the seen site).
        estimator: A :class:`policies.perception.SiteEstimator`.
        client: The arm, whose jaw topics show a grasp.
        rig: Stereo rig name (topic prefix).
        site: Which of the flap's sites is the task's (``centre``, ``left``, ``right``).
        wait_s: How long an episode's start waits for a fresh stereo pair [s].
        stale_after_s: Age of the last pair that holds the arm during an episode [s].
        goal: Where the site must go [m] in ``<arm>_base`` (``deploy --goal``); None: the task's nominal goal
            about the seen site, which then carries the estimate's error.
    """

    #: What a deploy's success is judged by.
    success_source = "estimate (the site the endoscope saw, moved with the jaws)"
    #: The site is seen once an episode and then moved with the jaws: a step waits for no new image (the
    #: endoscope's 10 Hz would stretch every 50 ms policy step to the next frame).
    state_each_period = False

    def __init__(
        self,
        task: str,
        estimator: Any,
        client: PsmClient,
        *,
        rig: str = DEFAULT_RIG,
        site: str = "centre",
        wait_s: float = 30.0,
        stale_after_s: float = 0.5,
        goal: np.ndarray | None = None,
    ) -> None:
        super().__init__(f"endoscope_site_{time.monotonic_ns() % 100000}")
        self.task, self.estimator, self.client = task, estimator, client
        self.rig, self.site_index = rig, SITE_NAMES.index(site)
        self.wait_s, self.stale_after_s = wait_s, stale_after_s
        self.goal = None if goal is None else np.asarray(goal, dtype=float)
        endoscope = estimator.endoscope
        self.world_from_camera = look_at(np.asarray(endoscope.eye_m), np.asarray(endoscope.target_m))
        self.estimate: TaskEstimate | None = None
        self.seen_site: np.ndarray | None = None
        self._lock = threading.Condition()
        self._images: dict[str, tuple[float, Any]] = {}
        self._infos: dict[str, Any] = {}
        self._pair_rx_s = float("-inf")
        topics = camera_topics(rig)
        qos = periodic_qos()
        for side in ("left", "right"):
            self.create_subscription(Image, topics[f"{side}_image"], self._on_image(side), qos)
            self.create_subscription(CameraInfo, topics[f"{side}_info"], self._on_info(side), qos)
        self._spinner = SpinThread(self, f"{rig}-images")

    def _on_image(self, side: str) -> Any:
        def callback(message: Image) -> None:
            stamp = message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec
            with self._lock:
                self._images[side] = (stamp, message)
                other = self._images.get("right" if side == "left" else "left")
                if other is not None and other[0] == stamp:
                    self._pair_rx_s = time.monotonic()
                    self._lock.notify_all()

        return callback

    def _on_info(self, side: str) -> Any:
        def callback(message: CameraInfo) -> None:
            with self._lock:
                self._infos[side] = message

        return callback

    # -- the task source interface --------------------------------------------------------------------
    def wait(self, timeout_s: float, *, after_s: float = float("-inf")) -> bool:
        """Whether stereo pairs arrive (one after ``after_s`` within ``timeout_s``)."""
        deadline = time.monotonic() + timeout_s
        with self._lock:
            return self._lock.wait_for(lambda: self._pair_rx_s > after_s, timeout=max(0.0, deadline - time.monotonic()))

    def serves_resets(self) -> bool:
        """A scene seen by a camera is not reset by the client."""
        return False

    def new_episode(self) -> None:
        """Wait for a pair taken from now on, estimate the site, and register it with the goal (given, or the
        task's nominal goal about the seen site).

        Raises:
            HoldError: No fresh pair within ``wait_s`` (``not ready``), or images or camera info that do
                not match the estimator's endoscope (``invalid data``).
        """
        started = time.monotonic()
        if not self.wait(self.wait_s, after_s=started):
            topics = camera_topics(self.rig)
            raise HoldError("not ready", f"no stereo pair on {topics['left_image']} and {topics['right_image']} "
                                         f"in {self.wait_s:g} s")  # fmt: skip
        with self._lock:
            (_, left), (_, right) = self._images["left"], self._images["right"]
            info = self._infos.get("left")
        frame = self._frame(image_array(left), image_array(right), info)
        site = np.asarray(self.estimator.world_sites(frame, SITE_NAMES[self.site_index])[self.site_index])
        self.seen_site = site
        goal = self.goal if self.goal is not None else sim.envs.nominal_goal(self.task, site)
        self.estimate = TaskEstimate(site, goal)

    def _frame(self, left: np.ndarray, right: np.ndarray, info: Any) -> StereoFrame:
        endoscope = self.estimator.endoscope
        expected = (endoscope.height, endoscope.width, 3)
        if left.shape != expected or right.shape != expected:
            raise HoldError("invalid data", f"endoscope images {left.shape[:2]}: the estimator takes {expected[:2]}")
        intrinsics = endoscope.intrinsics()
        if info is not None and not np.allclose(np.reshape(info.k, (3, 3)), intrinsics, rtol=1e-3):
            raise HoldError("invalid data", f"camera_info K {list(info.k)}: the estimator's is {intrinsics.ravel()}")
        empty = np.zeros(0)
        return StereoFrame(left, right, self.world_from_camera, intrinsics, endoscope.baseline_m, empty, empty)

    def refresh(self, grasp_position: np.ndarray) -> None:
        """Check the stream is fresh, then take the jaw's reading and the grasp point [m] in ``<arm>_base``.

        Raises:
            HoldError: The last stereo pair is older than ``stale_after_s`` (``stale``).
        """
        with self._lock:
            age = time.monotonic() - self._pair_rx_s
        if age > self.stale_after_s:
            raise HoldError(
                "stale",
                f"endoscope images {age:.2f} s old on {camera_topics(self.rig)['left_image']} "
                f"(at most {self.stale_after_s:g} s)",
            )
        self._registered().update(self.client.jaw_reading(), grasp_position)

    def _registered(self) -> TaskEstimate:
        if self.estimate is None:
            raise HoldError("not ready", "no site seen yet: an episode starts with new_episode()")
        return self.estimate

    def point(self, name: str) -> np.ndarray:
        """The estimated ``site``, ``goal`` or ``achieved_goal`` [m] in ``<arm>_base``."""
        estimate = self._registered()
        points = {"site": estimate.site, "goal": estimate.goal, "achieved_goal": estimate.achieved_goal}
        return np.asarray(points[name]).copy()

    @property
    def grasped(self) -> bool:
        """The jaw has stalled on tissue."""
        return self.estimate is not None and self.estimate.grasped

    def close(self) -> None:
        """Stop spinning and destroy the node."""
        self._spinner.close()
