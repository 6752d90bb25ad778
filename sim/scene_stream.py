"""Streaming a run's 3-D scene to where it is watched: a recording, a live Foxglove view, or both.

:class:`SceneStream` is what a control loop calls once per tick; it builds the messages with
:class:`sim.scene3d.PsmScene` and hands each to every sink. A sink takes ``(topic, message, t_s)``:
the MCAP recorder writes the message's protobuf encoding under its Foxglove schema, and
:class:`LiveScene` logs it to a Foxglove WebSocket server on 127.0.0.1, which the Foxglove app opens
(``ws://127.0.0.1:PORT``). :class:`StreamScene` wraps a simulation environment to stream its scene.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any, Protocol

import foxglove
import gymnasium as gym
import numpy as np
from foxglove import channels
from foxglove.messages import Log, LogLevel

from psm_control.errors import ConfigurationError
from sim.scene3d import COMMANDED_PREFIX, PsmScene, timestamp

__all__ = [
    "ARM_TOPIC",
    "LOG_TOPIC",
    "TASK_TOPIC",
    "TRANSFORMS_TOPIC",
    "LiveScene",
    "SceneSink",
    "SceneStream",
    "StreamScene",
    "log_message",
]

#: The scene's topics: frames of the measured (and commanded) arm, link shapes, tissue and markers, events.
TRANSFORMS_TOPIC = "/scene/transforms"
ARM_TOPIC = "/scene/arm"
TASK_TOPIC = "/scene/task"
LOG_TOPIC = "/scene/log"

#: The channel of each scene topic, by the message it carries.
_SCENE_CHANNELS = {
    TRANSFORMS_TOPIC: channels.FrameTransformsChannel,
    ARM_TOPIC: channels.SceneUpdateChannel,
    TASK_TOPIC: channels.SceneUpdateChannel,
    LOG_TOPIC: channels.LogChannel,
}

#: The link shapes are sent again this often [s], so that a player seeking into a recording finds them.
_ARM_REPEAT_S = 1.0


def log_message(t_s: float, text: str, *, warning: bool = False) -> Log:
    """An event (a hold, an intervention) as a Foxglove log message for :data:`LOG_TOPIC`."""
    level = LogLevel.Warning if warning else LogLevel.Info
    return Log(timestamp=timestamp(t_s), level=level, message=text, name="tissue-retract")


class SceneSink(Protocol):
    """Where scene messages go."""

    def write_message(self, topic: str, message: Any, t_s: float) -> None:
        """Take one Foxglove SDK message at time ``t_s`` [s]."""


class LiveScene:
    """A Foxglove WebSocket server on 127.0.0.1 that serves the scene as it happens.

    Args:
        port: TCP port (0 picks a free one; see :attr:`port`).
        name: The server's name shown in the Foxglove app.

    Raises:
        ConfigurationError: The port is out of range or taken.
    """

    def __init__(self, port: int = 8765, name: str = "tissue-retract") -> None:
        if not 0 <= port <= 65535:
            raise ConfigurationError("live port", port, "a TCP port in 0-65535 (0 picks a free one)")
        try:
            self._server = foxglove.start_server(name=name, host="127.0.0.1", port=port)
        except RuntimeError as e:  # the SDK reports a taken port as a RuntimeError
            raise ConfigurationError("live port", port, f"a free TCP port on 127.0.0.1 ({e})") from e
        # Every scene channel exists before anyone can know the port, so a client finds them all in the
        # advertisement that greets it. A channel made while a client is connected is advertised to it
        # before the server can serve it (foxglove-sdk 0.30): a client that subscribes as soon as it
        # sees the advertisement is told "Unknown channel ID" and never receives a message.
        self._channels: dict[str, Any] = {topic: make(topic) for topic, make in _SCENE_CHANNELS.items()}

    @property
    def port(self) -> int:
        """The port the server listens on."""
        return int(self._server.port)

    def write_message(self, topic: str, message: Any, t_s: float) -> None:
        """Log a message on its topic (a topic other than the scene's gets a channel on first use)."""
        channel = self._channels.get(topic)
        if channel is None:
            channel = getattr(channels, f"{type(message).__name__}Channel")(topic)
            self._channels[topic] = channel
        channel.log(message, log_time=round(t_s * 1e9))

    def close(self) -> None:
        """Stop the server."""
        for channel in self._channels.values():
            channel.close()
        self._server.stop()

    def __enter__(self) -> LiveScene:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class SceneStream:
    """Sends the scene of one arm to its sinks, tick by tick.

    Args:
        scene: Builds the messages.
        sinks: Where they go.
        period_s: Least time between two streamed ticks [s]; ticks closer than this to the last one are
            skipped (a 1 kHz control loop need not draw every tick). 0 streams every tick.
    """

    def __init__(self, scene: PsmScene, sinks: Sequence[SceneSink], period_s: float = 0.0) -> None:
        self.scene = scene
        self.sinks = list(sinks)
        self.period_s = float(period_s)
        self._arm_sent_s = -np.inf
        self._tick_sent_s = -np.inf

    def _send(self, topic: str, message: Any, t_s: float) -> None:
        for sink in self.sinks:
            sink.write_message(topic, message, t_s)

    def tick(
        self,
        t_s: float,
        q: np.ndarray,
        jaw: float,
        *,
        commanded_q: np.ndarray | None = None,
        commanded_jaw: float | None = None,
        nodes: np.ndarray | None = None,
        triangles: np.ndarray | None = None,
        site: np.ndarray | None = None,
        goal: np.ndarray | None = None,
        grasp: np.ndarray | None = None,
        force_n: np.ndarray | None = None,
    ) -> None:
        """The arm at its measured joints (and, if given, where it was commanded), the tissue and markers.

        Positions are in the scene's root frame [m]; see :meth:`sim.scene3d.PsmScene.task`.
        """
        if not self.sinks or t_s - self._tick_sent_s < self.period_s:
            return
        self._tick_sent_s = t_s
        if t_s - self._arm_sent_s >= _ARM_REPEAT_S:
            self._send(ARM_TOPIC, self.scene.arm(t_s), t_s)
            self._send(ARM_TOPIC, self.scene.arm(t_s, prefix=COMMANDED_PREFIX), t_s)
            self._arm_sent_s = t_s
        self._send(TRANSFORMS_TOPIC, self.scene.transforms(t_s, q, jaw), t_s)
        if commanded_q is not None:
            jaw_command = jaw if commanded_jaw is None else commanded_jaw
            self._send(TRANSFORMS_TOPIC, self.scene.transforms(t_s, commanded_q, jaw_command, COMMANDED_PREFIX), t_s)
        update = self.scene.task(
            t_s, nodes=nodes, triangles=triangles, site=site, goal=goal, grasp=grasp, force_n=force_n
        )
        self._send(TASK_TOPIC, update, t_s)

    def log(self, t_s: float, message: str, *, warning: bool = False) -> None:
        """An event (a hold, an intervention) as a Foxglove log message."""
        self._send(LOG_TOPIC, log_message(t_s, message, warning=warning), t_s)


class StreamScene(gym.Wrapper[dict[str, np.ndarray], np.ndarray, dict[str, np.ndarray], np.ndarray]):
    """Streams a tissue-retraction environment's 3-D scene to sinks after every reset and step.

    The scene's root frame is the simulation's ``world``; its clock runs on across episodes by the
    environment's step time (a recording's time must not go back).

    Args:
        env: A tissue-retraction environment (or a wrapper of one).
        sinks: Where the scene goes (a recording, a :class:`LiveScene`).
        realtime: Wait between steps so that the scene plays at the speed of the physics, for a person
            watching live; the episodes' outcomes do not depend on it.
        clock: The scene's time [s] (``time.time`` to match a recording's wall-clock channels); None runs
            a clock of the simulation's own, from 0.
    """

    def __init__(
        self,
        env: gym.Env[Any, Any],
        sinks: Sequence[SceneSink],
        *,
        realtime: bool = False,
        clock: Callable[[], float] | None = None,
    ) -> None:
        super().__init__(env)
        simulation = env.unwrapped
        self.stream = SceneStream(PsmScene(simulation.model, "world"), sinks)  # type: ignore[attr-defined]
        self.clock = clock
        physics = simulation.config.physics  # type: ignore[attr-defined]
        self.step_s = physics.time_step_s * physics.substeps
        self.realtime = realtime
        self.t_s = 0.0
        self._sim_s = 0.0
        self._wall_start = time.monotonic()

    def reset(self, **kwargs: Any) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Reset, then stream the new scene (the clock moves on by one step)."""
        observation, info = self.env.reset(**kwargs)
        self._stream(info)
        return observation, info

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Step, then stream the scene."""
        observation, reward, terminated, truncated, info = self.env.step(action)
        self._stream(info)
        return observation, float(reward), terminated, truncated, info

    def _stream(self, info: dict[str, Any]) -> None:
        self.t_s = self.clock() if self.clock is not None else self.t_s + self.step_s
        simulation: Any = self.env.unwrapped
        scene, backend = simulation.scene, simulation.backend
        base = np.eye(4)
        base[:3, 3] = scene.rcm_position
        self.stream.scene.base_frame = base
        goal = np.asarray(simulation.goal, dtype=float)
        self.stream.tick(
            self.t_s,
            backend.q,
            backend.jaw,
            commanded_q=backend.q_target,
            nodes=scene.tissue.positions(),
            triangles=scene.tissue.triangles,
            site=simulation.site_position(),
            goal=goal if goal.shape == (3,) else None,
            grasp=simulation.grasp_position(),
            force_n=np.asarray(info.get("force_n", np.zeros(3)), dtype=float),
        )
        if self.realtime:
            self._sim_s += self.step_s
            ahead = self._sim_s - (time.monotonic() - self._wall_start)
            if ahead > 0:  # pacing for a person watching, not synchronisation
                time.sleep(ahead)
