"""A console clock gone wrong on ``measured_js``, injected on purpose (``sim-dvrk --stamp-fault``).

The dVRK stamps each ``measured_js`` with the time its sample was read, so a client can tell a new
measurement from an old one (:mod:`hardware_if.client.deadman`). :class:`StampFault` makes the simulated
console break that, from a moment the user chooses (the N-th ``servo_jp`` it accepted, or
:meth:`StampFault.start`, which ``sim-dvrk`` calls on SIGUSR1), so that a deploy can be rehearsed against it:

- ``frozen``: the last ``measured_js`` sent before the fault is sent again and again, stamp and sample
  unchanged, at the console's rate (a console whose arm loop stopped while its publisher goes on).
- ``past``: every ``measured_js`` stamped :data:`PAST_S` in the past (the stamps go back once, then advance).
- ``jump``: one ``measured_js`` stamped :data:`JUMP_S` ahead, then that one repeated (a clock that leapt,
  then froze).

Every other topic keeps the console's clock.
"""

from __future__ import annotations

from collections.abc import Callable

from sensor_msgs.msg import JointState  # type: ignore[import-untyped]
from std_msgs.msg import Header  # type: ignore[import-untyped]

from hardware_if.common import convert
from psm_control.errors import ConfigurationError

__all__ = ["JUMP_S", "PAST_S", "STAMP_FAULTS", "StampFault"]

#: How far in the past ``past`` stamps each measurement [s].
PAST_S = 5.0
#: How far ahead ``jump`` stamps its measurement [s].
JUMP_S = 3600.0
#: The faults, with what each does (the ``--stamp-fault`` choices).
STAMP_FAULTS = {
    "frozen": "the last measured_js repeated, same stamp and sample",
    "past": f"measured_js stamped {PAST_S:g} s in the past",
    "jump": f"one measured_js stamped {JUMP_S:g} s ahead, then repeated",
}


class StampFault:
    """What the console does to its ``measured_js`` once the fault starts.

    Args:
        mode: One of :data:`STAMP_FAULTS`.
        after_commands: Start after this many accepted ``servo_jp`` commands; None: only on :meth:`start`.

    Raises:
        ConfigurationError: An unknown mode or a count below 1.
    """

    def __init__(self, mode: str, after_commands: int | None = None) -> None:
        if mode not in STAMP_FAULTS:
            raise ConfigurationError("stamp fault", mode, "one of " + ", ".join(STAMP_FAULTS))
        if after_commands is not None and after_commands < 1:
            raise ConfigurationError("stamp fault after", after_commands, "a number of servo_jp commands >= 1")
        self.mode = mode
        self.after_commands = after_commands
        self.on_start: Callable[[str], None] | None = None
        self._commands = 0
        self._asked = ""  # why the fault was asked to start ("" until then)
        self._active = False
        self._last: JointState | None = None  # the last measurement sent before the fault, or the one it repeats

    def describe(self) -> str:
        """The fault and when it starts, in words."""
        when = "on SIGUSR1"
        if self.after_commands is not None:
            when = f"after {self.after_commands} servo_jp command(s) or on SIGUSR1"
        return f"{STAMP_FAULTS[self.mode]}, {when}"

    def start(self, why: str = "asked") -> None:
        """Start with the next ``measured_js`` (safe to call from a signal handler: it only sets a flag)."""
        self._asked = self._asked or why

    def servo_command(self) -> None:
        """Count one accepted ``servo_jp``; the :attr:`after_commands`-th starts the fault."""
        self._commands += 1
        if self.after_commands is not None and self._commands == self.after_commands:
            self.start(f"after {self._commands} servo_jp command(s)")

    @property
    def active(self) -> bool:
        """Whether the fault has started (with a ``measured_js`` already sent under it)."""
        return self._active

    def measured(self, message: JointState) -> JointState:
        """The ``measured_js`` to send in place of ``message`` (``message`` itself until the fault starts)."""
        if not self._active and self._asked:
            self._active = True
            if self.mode == "jump":
                self._last = _shifted(message, JUMP_S)
            elif self._last is None:  # frozen before anything was sent: the first one is repeated
                self._last = message
            if self.on_start is not None:
                self.on_start(f"injected fault ({self._asked}): {STAMP_FAULTS[self.mode]} from now on")
        if not self._active:
            self._last = message
            return message
        if self.mode == "past":
            return _shifted(message, -PAST_S)
        return self._last if self._last is not None else message


def _shifted(message: JointState, offset_s: float) -> JointState:
    """A copy of ``message`` stamped ``offset_s`` later (earlier when negative)."""
    stamp = convert.seconds_to_time(convert.time_to_seconds(message.header.stamp) + offset_s)
    return JointState(
        header=Header(stamp=stamp, frame_id=message.header.frame_id),
        name=list(message.name),
        position=list(message.position),
        velocity=list(message.velocity),
        effort=list(message.effort),
    )
