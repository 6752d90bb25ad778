"""Recording a deploy or dry run to an MCAP file, and reading it back.

Every channel is JSON-encoded (MCAP ``message_encoding="json"``, schema encoding ``jsonschema``), so
a recording opens in Foxglove and any MCAP reader without ROS installed, and the simulation target
records the same channels as the dVRK one. Log times are the host's wall clock [ns].

Channels (:data:`CHANNELS`):

- ``/deploy/meta``: once, the run's settings (target, policy, arm, rate, dry run, task, safety config) and
  the force sensing it used (``sensing``: what the force came from, the error bound the filter was given,
  the calibration file).
- ``/deploy/measured``: every control tick, the measurement the chain used (``q``, ``qd``, ``jaw``,
  ``force_n`` in base axes, ``stamp_s``).
- ``/deploy/command``: every control tick, the chain's joint command (``q``, ``qd``, ``jaw``), whether it
  was ``sent`` (false in a dry run and while the deadman holds), ``safety_stop``, ``reason``,
  ``interventions``, the ``predicted_force_n`` of a dry run and, while the chain bounds the force from the
  grasp point's travel, that ``travel_bound_n``.
- ``/deploy/action``: every policy step, ``episode``, ``step``, the 5-D ``action`` and the observation.
- ``/deploy/event``: episode start/end, safety stops, deadman holds, faults, Ctrl-C (``kind``, ``text``).
- ``/deploy/report``: once at the end, the run's summary.

The 3-D scene (:mod:`sim.scene_stream`: ``/scene/transforms``, ``/scene/arm``, ``/scene/task``,
``/scene/log``) is written beside them in Foxglove's own protobuf schemas (``foxglove.FrameTransforms``,
``foxglove.SceneUpdate``, ``foxglove.Log``), so Foxglove shows the arm, the commanded arm, the tissue and
the force in 3-D; readers of the JSON channels skip these.

A recording survives a crash: the writer ends its chunk and flushes the file at least every
:data:`FLUSH_PERIOD_S` of wall time (and at every episode end and hold), so a SIGKILL loses at most about
the last second. :func:`read_recording` reads such a file, which lacks its summary and footer, record by
record (:mod:`hardware_if.recording.reader`, within stated limits), and says so (:class:`RecordingRead`).

A file that cannot be written (a full disk, a folder that vanishes or turns read-only, any write error)
raises :class:`~hardware_if.recording.checked_file.RecordingError`, a hold naming the file and the error, at once
and once. The torn end is cut off, and what is written afterwards (the hold, the report) is appended as
plain records into room kept for them from the start (:data:`~hardware_if.recording.checked_file.RESERVE_BYTES`);
the file then reads as far as it got.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
from mcap.data_stream import RecordBuilder
from mcap.records import Channel, Message
from mcap.writer import Writer

from hardware_if.recording.checked_file import CheckedFile, RecordingError, describe_os_error
from hardware_if.recording.schema import RecordingMessages
from psm_control.outputs import special_file_kind
from sim.scene_stream import LOG_TOPIC, SceneSink, log_message

__all__ = ["CHANNELS", "CHUNK_SIZE_BYTES", "FLUSH_PERIOD_S", "Recorder", "RecordingRead", "read_recording"]

#: A chunk is ended and the file flushed at least this often [s]: a crash loses at most this much.
FLUSH_PERIOD_S = 1.0
#: A chunk is also ended when it holds this many bytes (about 1 s of a 100 Hz deploy).
CHUNK_SIZE_BYTES = 256 * 1024
#: Events after which the file is flushed at once (what a post-mortem needs most).
_FLUSH_EVENTS = ("episode_end", "hold", "interrupted", "fault")

#: Channel topics and what each carries.
CHANNELS = {
    "/deploy/meta": "the run's settings, once",
    "/deploy/measured": "the measurement of every control tick",
    "/deploy/command": "the chain's command of every control tick (sent or not)",
    "/deploy/action": "the policy's action and observation of every step",
    "/deploy/event": "episode start/end, safety stops, holds, faults",
    "/deploy/report": "the run's summary, once",
}


#: Events that also go to the scene's log, and whether each is a warning.
_LOGGED_EVENTS = {
    "hold": True,
    "fault": True,
    "error": True,
    "interrupted": True,
    "safety_stop": True,
    "force_limit_stall": True,
    "episode_start": False,
    "episode_end": False,
}


def _episode_text(payload: dict[str, Any]) -> str:
    episode = f"episode {payload.get('episode')}"
    return f"{episode}, success={payload['success']}" if "success" in payload else episode


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return [_jsonable(v) for v in value.tolist()]
    if isinstance(value, np.generic):
        return _jsonable(value.item())
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


class Recorder:
    """Writes the run's channels to an MCAP file (use as a context manager).

    Args:
        path: Output file (``.mcap``); its folder is created.
        mirror: Also sends the 3-D scene there (a live Foxglove view), message for message.
    """

    def __init__(self, path: str | Path, mirror: SceneSink | None = None) -> None:
        self.path = Path(path)
        self.mirror = mirror
        self._interventions: tuple[str, ...] = ()
        self._failed: RecordingError | None = None
        kind = special_file_kind(self.path)
        if kind is not None:  # opening a FIFO would block, a device would take the run
            raise RecordingError(self.path, f"not a regular file (this is a {kind})")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = CheckedFile(self.path)
        except OSError as e:
            raise RecordingError(self.path, describe_os_error(e)) from None
        self._writer = Writer(self._file, chunk_size=CHUNK_SIZE_BYTES)  # type: ignore[arg-type]
        try:
            self._guarded(lambda: self._writer.start(profile="", library="tissue-retract"))
        except RecordingError:
            self._file.close()
            raise
        self._flushed_s = time.monotonic()
        self._channels: dict[str, int] = {}
        self._sequence = 0
        self.counts: dict[str, int] = dict.fromkeys(CHANNELS, 0)
        schema = json.dumps({"type": "object"}).encode()
        for topic in CHANNELS:
            schema_id = self._writer.register_schema(name=topic.rsplit("/", 1)[-1], encoding="jsonschema", data=schema)
            self._channels[topic] = self._writer.register_channel(
                topic=topic, message_encoding="json", schema_id=schema_id
            )
        self._scene_channels: dict[str, int] = {}
        self._scene_schemas: dict[str, int] = {}
        self._closed = False

    @property
    def failed(self) -> RecordingError | None:
        """The write error that stopped the recording, or None."""
        return self._failed

    def _guarded(self, write: Any) -> None:
        """Run one write to the file; an OS error becomes the recording's failure (raised once)."""
        try:
            write()
        except OSError as e:
            self._file.rewind()
            self._file.release_reserve()  # the room kept for what follows: the hold, the report
            self._failed = RecordingError(self.path, describe_os_error(e))
            raise self._failed from None

    def _append_after_failure(self, topic: str, data: bytes) -> None:
        """After a failure: the channel and the message as plain records at the file's good end, if it takes them."""
        builder = RecordBuilder()
        channel = self._channels[topic]
        Channel(id=channel, topic=topic, message_encoding="json", metadata={}, schema_id=0).write(builder)
        now = time.time_ns()
        Message(channel_id=channel, log_time=now, data=data, publish_time=now, sequence=self._sequence).write(builder)
        self._sequence += 1
        self._file.append(builder.end())

    def write_message(self, topic: str, message: Any, t_s: float) -> None:
        """Append a Foxglove SDK message (the 3-D scene) under its protobuf schema, stamped now.

        ``t_s`` is the message's own time; the log time is the wall clock, as for every other channel.
        """
        if self._closed or self._failed is not None:
            return
        channel = self._scene_channels.get(topic)
        if channel is None:
            schema = message.get_schema()
            if schema.name not in self._scene_schemas:
                self._scene_schemas[schema.name] = self._writer.register_schema(
                    name=schema.name, encoding=schema.encoding, data=bytes(schema.data)
                )
            channel = self._writer.register_channel(
                topic=topic, message_encoding=schema.encoding, schema_id=self._scene_schemas[schema.name]
            )
            self._scene_channels[topic] = channel
        self._add(channel, bytes(message.encode()))
        if self.mirror is not None:
            self.mirror.write_message(topic, message, t_s)

    def _log_to_scene(self, topic: str, payload: dict[str, Any]) -> None:
        """Holds, faults, safety stops, episodes and changes of the active interventions, as scene logs."""
        text = None
        if topic == "/deploy/event" and payload.get("kind") in _LOGGED_EVENTS:
            kind = str(payload["kind"])
            text = f"{kind.replace('_', ' ')}: {payload.get('text') or _episode_text(payload)}"
            warning = _LOGGED_EVENTS[kind]
        elif topic == "/deploy/command":
            interventions = tuple(str(i) for i in payload.get("interventions", ()))
            if interventions and interventions != self._interventions:
                text, warning = f"interventions: {', '.join(interventions)}", False
            self._interventions = interventions
        if text is not None:
            now = time.time()
            self.write_message(LOG_TOPIC, log_message(now, text, warning=warning), now)

    def _add(self, channel: int, data: bytes) -> None:
        now = time.time_ns()
        self._guarded(
            lambda: self._writer.add_message(
                channel, log_time=now, data=data, publish_time=now, sequence=self._sequence
            )
        )
        self._sequence += 1
        if time.monotonic() - self._flushed_s >= FLUSH_PERIOD_S:
            self.flush()

    def write(self, topic: str, payload: dict[str, Any]) -> None:
        """Append one message to a channel of :data:`CHANNELS`, stamped now."""
        if self._closed:
            return
        data = json.dumps(_jsonable(payload), separators=(",", ":")).encode()
        if self._failed is not None:
            self._append_after_failure(topic, data)
            return
        self._add(self._channels[topic], data)
        self.counts[topic] += 1
        self._log_to_scene(topic, payload)
        if topic == "/deploy/event" and payload.get("kind") in _FLUSH_EVENTS:
            self.flush()

    def flush(self) -> None:
        """End the chunk in progress and write it to the file (what a crash after this keeps)."""
        if not self._closed and self._failed is None:
            self._guarded(self._writer.flush)
            self._guarded(self._file.flush)
            self._flushed_s = time.monotonic()

    def close(self) -> None:
        """Finish the MCAP (summary and index) and close the file (safe to call twice).

        Raises:
            RecordingError: The end could not be written (the file then reads without its summary).
        """
        if self._closed:
            return
        self._closed = True
        try:
            if self._failed is None:
                self._guarded(self._writer.finish)
                self._guarded(self._file.flush)
        finally:
            self._file.close()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, value: BaseException | None, traceback: TracebackType | None
    ) -> None:
        self.close()


class RecordingRead:
    """The messages of a recording, read once: iterate for ``(topic, log_time_s, payload)`` in log-time order.

    Read and checked by :class:`~hardware_if.recording.schema.RecordingMessages`, within the limits of
    :mod:`hardware_if.recording.reader`. Every payload is kept: ``replay`` reads long recordings into
    arrays instead (:func:`hardware_if.recording.replay.load_recording`).

    Attributes:
        truncated: True when the file has no footer (the writer did not finish: a crash or a kill);
            the messages are then those of every complete record.

    Raises:
        RecordingFileError: The file is not a recording within the reader's limits, or a message is not
            what its channel holds (named).
    """

    def __init__(self, path: str | Path) -> None:
        read = RecordingMessages(path)
        rows = [(t_ns, topic, payload) for topic, _, t_ns, payload in read]
        rows.sort(key=lambda row: row[0])
        self.truncated = read.truncated
        self.messages: list[tuple[str, float, dict[str, Any]]] = [
            (topic, t * 1e-9, payload) for t, topic, payload in rows
        ]

    def __iter__(self) -> Iterator[tuple[str, float, dict[str, Any]]]:
        return iter(self.messages)


def read_recording(path: str | Path) -> RecordingRead:
    """Every message of a recording, ``(topic, log_time_s, payload)`` in log-time order; see :class:`RecordingRead`."""
    return RecordingRead(path)
