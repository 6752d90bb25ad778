"""What a recording's JSON channels may hold, checked message by message as the file is read.

:class:`RecordingMessages` reads a deploy's recording (:mod:`hardware_if.recording.recorder` wrote it) with
:class:`~hardware_if.recording.reader.McapMessages` and checks each message of the ``/deploy/*`` channels
against :data:`FIELDS`: a JSON object of at most :data:`MAX_JSON_MESSAGE_BYTES`, with the fields its readers
use of the types they need. A message that is not is refused with a
:class:`~hardware_if.recording.reader.RecordingFileError` that names the file, the channel, the message's
index on it and the field, and says what is allowed (``/deploy/measured message 3: q must be 6 numbers
(null for a non-finite one); it is ['a', 1]``). Fields a reader does not use are not checked, and a field
marked optional may be missing (older recordings lack some).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Collection, Iterator
from pathlib import Path
from typing import Any, NamedTuple

from hardware_if.recording.reader import McapMessages, RecordingFileError

__all__ = [
    "CALIBRATION_FIELDS",
    "EVENT_FIELDS",
    "FIELDS",
    "MAX_JSON_MESSAGE_BYTES",
    "SENSING_FIELDS",
    "CheckedMessage",
    "RecordingMessages",
    "as_float",
]

#: Largest JSON message [bytes]. The largest a deploy writes is its report, about 650 bytes per episode:
#: about 1 MB for an hour of 2.5-s episodes. Parsed JSON takes up to about 50 times its text in memory.
MAX_JSON_MESSAGE_BYTES = 8 * 1024 * 1024
_MAX_SHOWN = 60  # characters of an offending value shown in an error


def _number(value: Any) -> bool:
    """An int or float; a JSON integer too large for a float is not one (it would overflow every reader)."""
    if not isinstance(value, int | float) or isinstance(value, bool):
        return False
    try:
        float(value)
    except OverflowError:
        return False
    return True


class _Kind(NamedTuple):
    """A field's allowed values: a test and the words that say what it allows."""

    test: Callable[[Any], bool]
    allowed: str


def _vector(n: int) -> _Kind:
    return _Kind(
        lambda v: isinstance(v, list) and len(v) == n and all(x is None or _number(x) for x in v),
        f"{n} numbers (null for a non-finite one)",
    )


NUMBER = _Kind(_number, "a number")
NUMBER_OR_NULL = _Kind(lambda v: v is None or _number(v), "a number or null (non-finite)")
INTEGER = _Kind(lambda v: v is None or (isinstance(v, int) and not isinstance(v, bool)), "an integer or null")
BOOLEAN = _Kind(lambda v: isinstance(v, bool), "true or false")
TEXT = _Kind(lambda v: v is None or isinstance(v, str), "a string or null")
NAMES = _Kind(lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v), "a list of strings")
OBJECT = _Kind(lambda v: v is None or isinstance(v, dict), "an object or null")
ABSENT = _Kind(lambda v: False, "absent (replay gives each event the time it was logged)")

#: Per channel: field -> (allowed values, required). The channels' contents: recorder.CHANNELS.
FIELDS: dict[str, dict[str, tuple[_Kind, bool]]] = {
    "/deploy/meta": {
        "target": (TEXT, False),
        "policy": (TEXT, False),
        "task": (TEXT, False),
        "dry_run": (BOOLEAN, False),
        "sensing": (OBJECT, False),
    },
    "/deploy/measured": {
        "q": (_vector(6), True),
        "force_n": (_vector(3), True),
        "qd": (_vector(6), False),
        "effort": (_vector(6), False),
        "jaw": (NUMBER_OR_NULL, False),
        "stamp_s": (NUMBER_OR_NULL, False),
    },
    "/deploy/command": {
        "q": (_vector(6), True),
        "sent": (BOOLEAN, True),
        "safety_stop": (BOOLEAN, True),
        "qd": (_vector(6), False),
        "jaw": (NUMBER_OR_NULL, False),
        "stamp_s": (NUMBER_OR_NULL, False),
        "reason": (TEXT, False),
        "interventions": (NAMES, False),
        "predicted_force_n": (NUMBER_OR_NULL, False),
        "travel_bound_n": (NUMBER_OR_NULL, False),
    },
    "/deploy/action": {},
    "/deploy/event": {
        "kind": (_Kind(lambda v: isinstance(v, str), "a string"), True),
        "text": (TEXT, False),
        "episode": (INTEGER, False),
        "t": (ABSENT, False),
    },
    "/deploy/report": {"force_limit_n": (NUMBER_OR_NULL, False)},
}

#: The fields of ``/deploy/meta``'s ``sensing`` object (absent in recordings from before it), and of its
#: ``wrench_calibration`` object, checked as ``sensing.<field>`` and ``sensing.wrench_calibration.<field>``.
SENSING_FIELDS: dict[str, tuple[_Kind, bool]] = {
    "force_sensing": (TEXT, False),
    "force_sensing_error_n": (NUMBER_OR_NULL, False),
    "source": (TEXT, False),
    "wrench_calibration": (OBJECT, False),
}
CALIBRATION_FIELDS: dict[str, tuple[_Kind, bool]] = {
    "path": (TEXT, False),
    "sha256": (TEXT, False),
    "error_bound_n": (NUMBER_OR_NULL, False),
    "error_bound_with_acceleration_n": (NUMBER_OR_NULL, False),
}

#: Per event kind, the fields its readers use beyond :data:`FIELDS`'s ``/deploy/event`` ones.
EVENT_FIELDS: dict[str, dict[str, tuple[_Kind, bool]]] = {
    "episode_start": {"seed": (INTEGER, False)},
    "episode_end": {
        "success": (_Kind(lambda v: v is None or isinstance(v, bool), "true, false or null"), False),
        "steps": (INTEGER, False),
        "peak_force_n": (NUMBER_OR_NULL, False),
    },
    "force_limit_exceeded": {
        "limit_n": (NUMBER, True),
        "duration_s": (NUMBER, True),
        "peak_n": (NUMBER_OR_NULL, False),
        "start_s": (NUMBER, False),
    },
    "force_limit_stall": {
        "limit_n": (NUMBER, True),
        "speed_m_s": (NUMBER, True),
        "static_load_n": (NUMBER, True),
    },
    "hold": {"data": (OBJECT, False)},
}


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= _MAX_SHOWN else text[: _MAX_SHOWN - 3] + "..."


class CheckedMessage(NamedTuple):
    """A JSON message that passed its channel's checks: topic, index on its channel, log time [ns], payload."""

    topic: str
    channel_index: int
    log_time_ns: int
    payload: dict[str, Any]


class RecordingMessages:
    """The checked messages of a recording's JSON channels, in file order (see the module docstring).

    Iterate once; :attr:`truncated` holds after the end.

    Args:
        path: The recording.
        topics: The channels wanted (default: all of :data:`FIELDS`).
        field: How the command names the file in errors (``recording``, ``--from``).
    """

    def __init__(self, path: str | Path, topics: Collection[str] | None = None, *, field: str = "recording") -> None:
        self.path = Path(path)
        self.field = field
        self._messages = McapMessages(path, FIELDS if topics is None else topics, field=field)

    @property
    def truncated(self) -> bool:
        """True when the file ends without its footer (a killed run): the messages are its complete records'."""
        return self._messages.truncated

    def error(self, topic: str, index: int, key: str | None, allowed: str) -> RecordingFileError:
        """The error for one message's field: ``/deploy/measured message 3: q must be ...``."""
        where = f"{topic} message {index}" + (f": {key}" if key else "")
        return RecordingFileError(
            self.path, f"{where} must be {allowed}", field=self.field, topic=topic, index=index, key=key
        )

    def __iter__(self) -> Iterator[CheckedMessage]:
        for message in self._messages:
            yield CheckedMessage(message.topic, message.index, message.log_time_ns, self._payload(message))

    def _payload(self, message: Any) -> dict[str, Any]:
        topic, index = message.topic, message.index
        if len(message.data) > MAX_JSON_MESSAGE_BYTES:
            raise self.error(
                topic, index, None, f"at most {MAX_JSON_MESSAGE_BYTES} bytes of JSON; it has {len(message.data)}"
            )
        try:
            payload = json.loads(message.data)
        except (ValueError, RecursionError) as e:  # UnicodeDecodeError and JSONDecodeError are ValueErrors
            raise self.error(topic, index, None, f"a JSON object ({type(e).__name__}: {_shown(str(e))})") from e
        if not isinstance(payload, dict):
            raise self.error(topic, index, None, f"a JSON object; it is {type(payload).__name__} {_shown(payload)}")
        fields = dict(FIELDS.get(topic, {}))
        if topic == "/deploy/event" and isinstance(payload.get("kind"), str):
            fields.update(EVENT_FIELDS.get(payload["kind"], {}))
        self._check(topic, index, payload, fields)
        sensing = payload.get("sensing") if topic == "/deploy/meta" else None
        if isinstance(sensing, dict):
            self._check(topic, index, sensing, SENSING_FIELDS, "sensing.")
            if isinstance(sensing.get("wrench_calibration"), dict):
                self._check(
                    topic, index, sensing["wrench_calibration"], CALIBRATION_FIELDS, "sensing.wrench_calibration."
                )
        return payload

    def _check(
        self, topic: str, index: int, payload: dict[str, Any], fields: dict[str, tuple[_Kind, bool]], prefix: str = ""
    ) -> None:
        for key, (kind, required) in fields.items():
            if key not in payload:
                if required:
                    raise self.error(topic, index, prefix + key, f"{kind.allowed}; it is missing")
            elif not kind.test(payload[key]):
                raise self.error(topic, index, prefix + key, f"{kind.allowed}; it is {_shown(payload[key])}")


def as_float(value: Any) -> float:
    """A checked number or null (or a missing field: None) as a float; null is nan."""
    return math.nan if value is None else float(value)
