"""The client-side deadman: when to stop commanding a dVRK and hold.

The dVRK has no timeout on servo commands: a servo_jp goal is held until replaced, so a client that
stops thinking must not leave the arm chasing an old goal, and a client whose measurements stop must
not keep sending new ones. :class:`Deadman` decides, from facts the client gathers (message ages,
publisher counts, the operating state, measured vs setpoint joints), whether commanding is safe. It
has no ROS in it, so each rule can be tested alone.

A measurement is fresh when its stamp advanced, not merely when a message arrived: the dVRK stamps each
``measured_js`` with the time its sample was read and publishes at its own rate (100 Hz by default, up to
1 kHz), so each one is stamped later than the one before. A console that repeats its last message (same
stamp) is as stale as one that went silent; a stamp that goes back, or runs ahead of the arrivals by more
than :data:`STAMP_JUMP_S`, is no clock the deadman can judge age by (:func:`stamp_step_fault`). Stamps are
judged against each other and the intervals between arrivals, never against this machine's clock: the
console's may differ from ours.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from hardware_if.common.crtk import JOINT_NAMES, TRACKING_TOLERANCE
from psm_control.errors import ConfigurationError
from safety.config import SafetyConfig

__all__ = ["STAMP_JUMP_S", "ArmFacts", "Deadman", "DeadmanStatus", "stamp_step_fault"]

#: How far a ``measured_js`` stamp may run further ahead of its arrival than the measurements before it did [s].
#: A message under way longer, or a callback this process ran late, only makes a stamp look older than the
#: arrivals, never newer; the next message's stamp is then judged against the least delayed of the ones before
#: it (:func:`stamp_step_fault`). 1 s, a hundred of the dVRK's 100 Hz periods, is a clock that jumped.
STAMP_JUMP_S = 1.0


def stamp_step_fault(previous_stamp_s: float, stamp_s: float, ahead_s: float, jump_s: float = STAMP_JUMP_S) -> str:
    """What is wrong with a ``measured_js`` stamp after the previous one, or "" when it may follow it.

    Args:
        previous_stamp_s: The previous measurement's stamp (the console's clock) [s].
        stamp_s: This measurement's stamp [s].
        ahead_s: How much further this stamp runs ahead of its arrival (stamp less arrival time, this machine's
            clock) than the least delayed of the measurements before it did [s].
        jump_s: Largest allowed ``ahead_s`` [s].

    Returns:
        "" for a stamp that advanced no further than the arrivals allow, or one equal to the previous (a
        repeat: not a fault here, but no new measurement either); otherwise ``stamp went back ...`` or
        ``stamp jumped ...`` (the listener says it as ``invalid data: measured_js: ...``).
    """
    step = stamp_s - previous_stamp_s
    if step < 0.0:
        return f"stamp went back {-step:.3g} s (each measurement is stamped later than the one before)"
    if ahead_s > jump_s:
        return (
            f"stamp jumped {ahead_s:.4g} s further ahead of its arrival than the measurements before it "
            f"(at most {jump_s:g} s)"
        )
    return ""


class ArmFacts(NamedTuple):
    """What the client knows about the arm at one instant.

    Attributes:
        now_s: Client's monotonic clock [s].
        measured_rx_s: When the latest ``measured_js`` with a new stamp arrived [s], None if never.
        publishers: Number of publishers of ``measured_js`` seen in the ROS graph (-1 if unknown).
        state: Latest ``operating_state.state`` ("" if never received).
        is_homed: Latest ``operating_state.is_homed``.
        measured_q: Latest measured joints (6,), or None.
        setpoint_q: Latest ``setpoint_js`` joints (6,), or None.
        data_fault: The first malformed or non-finite message on a subscribed topic ("" if none).
        conflict: Another commander or console of the arm in the ROS graph ("" if none), as
            :meth:`hardware_if.common.commander_watch.CommanderWatch.conflict` words it.
        repeated_rx_s: When a ``measured_js`` stamped as the latest one last arrived again [s] (the console
            repeats its measurement), None if none has since.
    """

    now_s: float
    measured_rx_s: float | None
    publishers: int
    state: str
    is_homed: bool
    measured_q: np.ndarray | None
    setpoint_q: np.ndarray | None
    data_fault: str = ""
    conflict: str = ""
    repeated_rx_s: float | None = None


class DeadmanStatus(NamedTuple):
    """The deadman's verdict, readable by the caller at any time.

    Attributes:
        ok: True when commands may be sent.
        holding: True once a fault stopped commanding; stays True until :meth:`Deadman.release`.
        reason: The first failed rule ("" when ok), e.g. ``"stale: measured_js 0.412 s old"``.
        since_s: Client clock time [s] at which the current hold started (nan when not holding).
    """

    ok: bool
    holding: bool
    reason: str
    since_s: float = float("nan")


@dataclass
class Deadman:
    """Latching deadman over the dVRK's state, with the dVRK's own tracking tolerances.

    Args:
        timeout_s: Largest allowed age of the latest ``measured_js`` with a new stamp (by its arrival) [s];
            default the chain's ``SafetyConfig.deadman_timeout_s`` (0.15 s, 15 periods of the dVRK's 100 Hz
            publication).
        tracking_tolerance: Largest |measured - setpoint| per joint before tripping; default the dVRK's
            (0.5 rad yaw/pitch, 0.05 m insertion, 0.6 rad roll and wrist).

    Raises:
        ConfigurationError: A non-positive timeout or a tolerance not of shape (6,) and positive.
    """

    timeout_s: float = SafetyConfig.deadman_timeout_s
    tracking_tolerance: np.ndarray = field(default_factory=lambda: TRACKING_TOLERANCE.copy())
    _hold_reason: str = field(default="", init=False)
    _hold_since_s: float = field(default=float("nan"), init=False)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.timeout_s) and self.timeout_s > 0.0):
            raise ConfigurationError("timeout_s", self.timeout_s, "a finite number of seconds > 0")
        tolerance = np.asarray(self.tracking_tolerance, dtype=float)
        if tolerance.shape != (len(JOINT_NAMES),) or not np.all(tolerance > 0.0):
            raise ConfigurationError("tracking_tolerance", self.tracking_tolerance, "6 positive numbers")
        self.tracking_tolerance = tolerance

    def check(self, facts: ArmFacts) -> str:
        """The first rule the facts break, or "" when commanding is safe (no latching)."""
        if facts.data_fault:
            return facts.data_fault
        if facts.conflict:
            return facts.conflict
        if facts.publishers == 0:
            return "publisher gone: nobody publishes measured_js"
        if facts.publishers > 1:
            return f"publisher conflict: {facts.publishers} publishers of measured_js (one arm allowed)"
        if facts.measured_rx_s is None or facts.measured_q is None:
            return "no measurement: measured_js never received"
        age = facts.now_s - facts.measured_rx_s
        if age > self.timeout_s:
            if facts.repeated_rx_s is not None and facts.repeated_rx_s > facts.measured_rx_s:
                return (
                    f"stale: measured_js stamp has not advanced for {age:.3f} s (timeout {self.timeout_s:.3f} s; "
                    "the console repeats its last measurement)"
                )
            return f"stale: measured_js {age:.3f} s old (timeout {self.timeout_s:.3f} s)"
        if facts.state != "ENABLED" or not facts.is_homed:
            state = facts.state or "unknown"
            return f"not ready: operating state {state}, {'homed' if facts.is_homed else 'not homed'}"
        if facts.setpoint_q is not None:
            error = np.abs(facts.measured_q - facts.setpoint_q)
            over = np.flatnonzero(error > self.tracking_tolerance)
            if over.size:
                i = int(over[0])
                return (
                    f"tracking error: {JOINT_NAMES[i]} |measured - setpoint| = {error[i]:.4g} "
                    f"> {self.tracking_tolerance[i]:.4g}"
                )
        return ""

    def update(self, facts: ArmFacts) -> DeadmanStatus:
        """Apply the rules; a failure latches a hold until :meth:`release`."""
        reason = self.check(facts)
        if reason and not self._hold_reason:
            self._hold_reason = reason
            self._hold_since_s = facts.now_s
        if self._hold_reason:
            return DeadmanStatus(False, True, self._hold_reason, self._hold_since_s)
        return DeadmanStatus(True, False, "")

    @property
    def status(self) -> DeadmanStatus:
        """The latched verdict without new facts."""
        if self._hold_reason:
            return DeadmanStatus(False, True, self._hold_reason, self._hold_since_s)
        return DeadmanStatus(True, False, "")

    def release(self, facts: ArmFacts) -> DeadmanStatus:
        """Clear a hold if the facts now pass every rule; otherwise keep holding with the new reason."""
        reason = self.check(facts)
        if reason:
            self._hold_reason = reason
            if not np.isfinite(self._hold_since_s):
                self._hold_since_s = facts.now_s
            return self.status
        self._hold_reason = ""
        self._hold_since_s = float("nan")
        return self.status
