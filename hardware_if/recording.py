"""Recording a deploy or dry run to an MCAP file, and reading it back.

Every channel is JSON-encoded (MCAP ``message_encoding="json"``, schema encoding ``jsonschema``), so
a recording opens in Foxglove and any MCAP reader without ROS installed, and the simulation target
records the same channels as the dVRK one. Log times are the host's wall clock [ns].

Channels (:data:`CHANNELS`):

- ``/deploy/meta``: once, the run's settings (target, policy, arm, rate, dry run, task, safety config).
- ``/deploy/measured``: every control tick, the measurement the chain used (``q``, ``qd``, ``jaw``,
  ``force_n`` in base axes, ``stamp_s``).
- ``/deploy/command``: every control tick, the chain's joint command (``q``, ``qd``, ``jaw``), whether it
  was ``sent`` (false in a dry run and while the deadman holds), ``safety_stop``, ``reason``,
  ``interventions`` and the ``predicted_force_n`` of a dry run.
- ``/deploy/action``: every policy step, ``episode``, ``step``, the 5-D ``action`` and the observation.
- ``/deploy/event``: episode start/end, safety stops, deadman holds, faults, Ctrl-C (``kind``, ``text``).
- ``/deploy/report``: once at the end, the run's summary.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
from mcap.reader import make_reader
from mcap.writer import Writer

__all__ = ["CHANNELS", "Recorder", "read_recording"]

#: Channel topics and what each carries.
CHANNELS = {
    "/deploy/meta": "the run's settings, once",
    "/deploy/measured": "the measurement of every control tick",
    "/deploy/command": "the chain's command of every control tick (sent or not)",
    "/deploy/action": "the policy's action and observation of every step",
    "/deploy/event": "episode start/end, safety stops, holds, faults",
    "/deploy/report": "the run's summary, once",
}


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
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self.path.open("wb")
        self._writer = Writer(self._file)
        self._writer.start(profile="", library="tissue-retract")
        self._channels: dict[str, int] = {}
        self._sequence = 0
        self.counts: dict[str, int] = dict.fromkeys(CHANNELS, 0)
        schema = json.dumps({"type": "object"}).encode()
        for topic in CHANNELS:
            schema_id = self._writer.register_schema(name=topic.rsplit("/", 1)[-1], encoding="jsonschema", data=schema)
            self._channels[topic] = self._writer.register_channel(
                topic=topic, message_encoding="json", schema_id=schema_id
            )
        self._closed = False

    def write(self, topic: str, payload: dict[str, Any]) -> None:
        """Append one message to a channel of :data:`CHANNELS`, stamped now."""
        if self._closed:
            return
        now = time.time_ns()
        data = json.dumps(_jsonable(payload), separators=(",", ":")).encode()
        self._writer.add_message(
            self._channels[topic], log_time=now, data=data, publish_time=now, sequence=self._sequence
        )
        self._sequence += 1
        self.counts[topic] += 1

    def close(self) -> None:
        """Finish the MCAP (summary and index) and close the file (safe to call twice)."""
        if not self._closed:
            self._closed = True
            self._writer.finish()
            self._file.close()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, value: BaseException | None, traceback: TracebackType | None
    ) -> None:
        self.close()


def read_recording(path: str | Path) -> Iterator[tuple[str, float, dict[str, Any]]]:
    """Yield ``(topic, log_time_s, payload)`` of every message of a recording, in log-time order."""
    with Path(path).open("rb") as f:
        reader = make_reader(f)
        for _, channel, message in reader.iter_messages(log_time_order=True):
            yield channel.topic, message.log_time * 1e-9, json.loads(message.data)
