"""The arm is where the episode thinks it is: at its start before the first command, on its commands after.

Two checks a deploy makes on the measured joints, with no ROS in them (each testable alone), and the
move back to the start (:func:`return_to_start`, through the client):

- :func:`start_offset` before an episode's first command: the measured joints and jaw against the episode's
  start (the task's start joints and open jaw, where the simulation starts every episode and the simulated
  console homes to). An arm moved since (by hand, by another program, by the last episode, which may end
  with the jaws closed on the flap) is sent back there or, in a dry run, held. The jaw is part of the start:
  a policy's first observation carries it, and jaws closed at the start may hold tissue, so the force bound
  counts the travel from there (:mod:`safety.force_bound`): a grasp soon after would be judged by travel it
  never made on the tissue.
- :class:`TrackingWatch` during the episode: each measured joint must stay within the span of the commands
  sent over the last :attr:`TrackingWatch.window_s`, widened by :data:`TRACKING_TOLERANCE`. Something
  else moving the arm (a second commander, a collision, a console that ignores the commands) shows as a
  measured pose that stops following the commanded one, long before the console's own trip (0.5 rad).

The tolerance comes from the servo's measured tracking: ``replay`` of a 3-episode scripted ``deploy
--target dvrk`` of Task I against ``sim-dvrk --task lift`` printed a largest ``|command(t-1) -
measured(t)|`` of yaw 0.0019, pitch 0.0050 rad, insertion 0.0032 m, roll 0.00002, wrist pitch 0.0041,
wrist yaw 0.0018 rad (``docs/one-commander.md`` has the command). :data:`TRACKING_TOLERANCE` is ten times
the largest rotation (0.05 rad) and three times the insertion's (0.01 m): a tenth of the console's
0.5 rad trip and a fifth of its 0.05 m one. The window, the deadman's timeout plus two control periods,
is as old as a measurement the deadman accepts can be, so a late measurement is judged against the
commands it can reflect.
"""

from __future__ import annotations

import collections
import time
from typing import Any

import numpy as np

from hardware_if.common.crtk import JOINT_NAMES

__all__ = [
    "JAW_START_TOLERANCE_RAD",
    "START_TOLERANCE",
    "TRACKING_TOLERANCE",
    "TrackingWatch",
    "return_to_start",
    "start_offset",
]

#: Largest distance of a measured joint from the commanded span (yaw, pitch [rad], insertion [m], roll,
#: wrist pitch, wrist yaw [rad]) before the deploy holds on a divergence.
TRACKING_TOLERANCE = np.array([0.05, 0.05, 0.01, 0.05, 0.05, 0.05])
#: Largest distance of a measured joint from the episode's start before the arm is sent back there
#: (same units): the console's move ends within its servo's tracking, far inside this.
START_TOLERANCE = np.array([0.01, 0.01, 0.002, 0.01, 0.01, 0.01])
#: Largest distance of the measured jaw from the episode's start jaw [rad]: far above the console's jaw
#: tracking, far below the 0.45 rad between the tasks' open jaw and a jaw that may hold tissue.
JAW_START_TOLERANCE_RAD = 0.05


def _unit(joint: int) -> str:
    return "m" if JOINT_NAMES[joint] == "insertion" else "rad"


def start_offset(
    measured_q: np.ndarray,
    start_q: np.ndarray,
    tolerance: np.ndarray = START_TOLERANCE,
    *,
    measured_jaw: float | None = None,
    start_jaw: float | None = None,
) -> str:
    """ "" when the arm (and, given both, the jaw) is at the start within tolerance; else what is how far off."""
    error = np.abs(np.asarray(measured_q, dtype=float) - np.asarray(start_q, dtype=float))
    over = np.flatnonzero(error > tolerance)
    jaw_error = 0.0 if measured_jaw is None or start_jaw is None else abs(float(measured_jaw) - float(start_jaw))
    jaw_off = not jaw_error <= JAW_START_TOLERANCE_RAD  # a non-finite jaw is off too
    if not over.size and not jaw_off:
        return ""
    if not over.size:
        return (
            f"jaw at {measured_jaw:.4g} rad, {jaw_error:.4g} rad from the episode's start {start_jaw:.4g} rad "
            f"(tolerance {JAW_START_TOLERANCE_RAD:g} rad)"
        )
    i = int(over[np.argmax(error[over] / tolerance[over])])
    return (
        f"{JOINT_NAMES[i]} is {error[i]:.4g} {_unit(i)} from the episode's start "
        f"(tolerance {tolerance[i]:g} {_unit(i)}; {over.size} joint(s) off{', and the jaw' if jaw_off else ''})"
    )


class TrackingWatch:
    """Holds when the measured joints leave the span of the recent commands widened by a tolerance.

    Args:
        window_s: How far back a measurement may reflect a command [s].
        tolerance: Per-joint widening of the commanded span (default :data:`TRACKING_TOLERANCE`).
    """

    def __init__(self, window_s: float, tolerance: np.ndarray = TRACKING_TOLERANCE) -> None:
        self.window_s = float(window_s)
        self.tolerance = np.asarray(tolerance, dtype=float)
        self._commands: collections.deque[tuple[float, np.ndarray]] = collections.deque()
        self.largest = np.zeros(len(JOINT_NAMES))

    def reset(self, measured_q: np.ndarray, t_s: float) -> None:
        """A new episode: the arm is where it was measured (the first command starts from there)."""
        self._commands.clear()
        self._commands.append((t_s, np.asarray(measured_q, dtype=float).copy()))

    def commanded(self, q: np.ndarray, t_s: float) -> None:
        """A command was sent at ``t_s`` [s, monotonic]."""
        self._commands.append((t_s, np.asarray(q, dtype=float).copy()))
        while len(self._commands) > 1 and self._commands[1][0] <= t_s - self.window_s:
            self._commands.popleft()  # the newest command older than the window stays: the arm may be there

    def check(self, measured_q: np.ndarray) -> str:
        """ "" while the arm follows the commands; else the hold reason (``tracking divergence: ...``)."""
        if not self._commands:
            return ""
        span = np.array([q for _, q in self._commands])
        q = np.asarray(measured_q, dtype=float)
        outside = np.maximum(span.min(axis=0) - q, q - span.max(axis=0)).clip(min=0.0)
        self.largest = np.maximum(self.largest, outside)
        over = np.flatnonzero(outside > self.tolerance)
        if not over.size:
            return ""
        i = int(over[np.argmax(outside[over] / self.tolerance[over])])
        return (
            f"tracking divergence: {JOINT_NAMES[i]} measured {outside[i]:.4g} {_unit(i)} away from the commanded "
            f"path (tolerance {self.tolerance[i]:g} {_unit(i)}): something other than this deploy moves the arm"
        )


def return_to_start(
    client: Any, start_q: np.ndarray, timeout_s: float, poll_s: float = 0.02, *, start_jaw: float | None = None
) -> str:
    """Send the arm to ``start_q`` (and the jaw to ``start_jaw``) along the console's own trajectories
    (``move_jp``, ``jaw/move_jp``) and wait until it is there.

    Args:
        client: The arm (:class:`~hardware_if.client.psm_client.PsmClient`).
        start_q: The episode's start joints.
        timeout_s: How long the move may take [s].
        poll_s: How often the measured joints are compared with the start [s].
        start_jaw: The episode's start jaw [rad]; None leaves the jaw as it is.

    Returns:
        "" once the arm is idle at the start within :data:`START_TOLERANCE` (the jaw within
        :data:`JAW_START_TOLERANCE_RAD`); otherwise why not.
    """
    client.move_jp(np.asarray(start_q, dtype=float))
    if start_jaw is not None:
        client.jaw_move_jp(float(start_jaw))
    deadline = time.monotonic() + timeout_s
    while True:
        measured = client.measure()
        offset = start_offset(measured.q, start_q, measured_jaw=measured.jaw, start_jaw=start_jaw)
        busy = client.operating_state()[2]
        if not offset and not busy:
            return ""
        if time.monotonic() >= deadline:
            return f"{offset or 'the move is still running'} after move_jp for {timeout_s:g} s"
        time.sleep(poll_s)  # waiting on the arm's own trajectory, bounded by the deadline
