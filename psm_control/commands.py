"""Typed values that flow between the stages of the control chain, and the stage protocols.

policy action -> :class:`CartesianDelta` -> controller (IK -> safety filter -> smoother -> verifier)
-> :class:`JointCommand` -> :class:`Backend` (PyBullet or a dVRK over ROS 2) -> :class:`MeasuredState`.
The same objects are used in simulation and on hardware.
"""

from __future__ import annotations

from typing import Any, Literal, NamedTuple, Protocol

import numpy as np

__all__ = ["Backend", "CartesianDelta", "ControlOutput", "Controller", "JointCommand", "MeasuredState"]


class CartesianDelta(NamedTuple):
    """A policy's requested tool motion, applied to the measured tool pose.

    Attributes:
        translation_m: Tool-tip displacement (3,) [m], in the axes named by ``frame``.
        yaw_rad: Rotation of the tool about the frame's z axis [rad].
        jaw_rad: Requested jaw opening angle [rad] (absolute, not a delta).
        frame: ``"base"`` (the dVRK base frame) or ``"local"`` (about the RCM).
    """

    translation_m: np.ndarray
    yaw_rad: float = 0.0
    jaw_rad: float = 0.0
    frame: Literal["base", "local"] = "base"


class MeasuredState(NamedTuple):
    """What a backend measures at one instant.

    Attributes:
        q: Arm joint positions (6,), dVRK order [rad, rad, m, rad, rad, rad].
        qd: Arm joint velocities (6,).
        jaw: Jaw opening angle [rad].
        force_n: Measured or estimated tissue force on the tool (3,) [N], base axes.
        stamp_s: Measurement time [s] on the backend's clock.
    """

    q: np.ndarray
    qd: np.ndarray
    jaw: float
    force_n: np.ndarray
    stamp_s: float


class JointCommand(NamedTuple):
    """A verified joint set-point for one control period.

    Attributes:
        q: Joint positions (6,).
        qd: Joint velocities (6,).
        qdd: Joint accelerations (6,).
        jaw: Jaw angle [rad].
        stamp_s: Time the command is for [s].
    """

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    jaw: float
    stamp_s: float


class ControlOutput(NamedTuple):
    """What one tick of a controller produced.

    Attributes:
        command: The command to send; when ``safety_stop`` is set it holds the last safe set-point.
        safety_stop: True when the tick refused to move and held position.
        reason: Why it stopped ("" when it did not).
        interventions: Names of the safety constraints that changed the command this tick.
        events: What this tick found that the user must hear of and the recording keep: JSON-ready dicts
            with a ``kind`` and a ``text`` for the user.
    """

    command: JointCommand
    safety_stop: bool = False
    reason: str = ""
    interventions: tuple[str, ...] = ()
    events: tuple[dict[str, Any], ...] = ()


class Controller(Protocol):
    """The control chain as the simulation and the ROS interface see it."""

    control_period_s: float

    def reset(self, measured: MeasuredState) -> None:
        """Forget any target and motion state; hold at the measured configuration."""

    def set_target(self, delta: CartesianDelta, measured: MeasuredState) -> None:
        """Set a new Cartesian goal: the delta applied to the measured tool pose (once per policy step)."""

    def tick(self, measured: MeasuredState) -> ControlOutput:
        """Advance one control period towards the goal and return the verified command."""


class Backend(Protocol):
    """Where verified commands go: the PyBullet simulation or a dVRK over ROS 2."""

    def measure(self) -> MeasuredState:
        """Return the latest measured state."""

    def servo_jp(self, command: JointCommand) -> None:
        """Send a verified joint set-point (the CRTK ``servo_jp`` semantics)."""
