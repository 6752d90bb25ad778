"""What moves behind the simulated dVRK: a pluggable arm model.

The simulated console (:mod:`hardware_if.console.sim_dvrk`) owns the CRTK interface and the operating-state
machine; an :class:`ArmModel` owns the physics. :class:`KinematicArm` is the dVRK's own "KINEMATIC"
simulation (measured = last commanded). A physics model (the PyBullet tissue scene) plugs in through
the same protocol and also reports the tissue force for ``body/measured_cf``.
"""

from __future__ import annotations

import collections
from typing import Any, NamedTuple, Protocol

import numpy as np

__all__ = ["VELOCITY_WINDOW_S", "ArmModel", "ArmSample", "KinematicArm", "WindowedVelocity"]

#: The span the simulated arm's velocities are measured over [s]: a moving average over it passes what a real
#: arm's mass and servo pass (half power at 4.4 Hz), not the steps of set-points arriving between ticks.
VELOCITY_WINDOW_S = 0.1


class ArmSample(NamedTuple):
    """The arm's state after a step.

    Attributes:
        q: Measured joints (6,), dVRK order.
        qd: Measured joint velocities (6,).
        jaw: Measured jaw angle [rad].
        force_n: Force on the tool (3,) [N], in the base frame's axes.
        jaw_velocity: Measured jaw velocity [rad/s].
        jaw_effort: Jaw effort [N m] (negative: squeezing something between the jaws).
        elapsed_s: The arm's own time this step advanced [s] (a physics model steps in whole steps, so some
            of the console's ticks move it and some do not); None: the console's tick.
    """

    q: np.ndarray
    qd: np.ndarray
    jaw: float
    force_n: np.ndarray
    jaw_velocity: float = 0.0
    jaw_effort: float = 0.0
    elapsed_s: float | None = None


class ArmModel(Protocol):
    """The physics behind the simulated console."""

    #: True when a command is measured at once (the console then answers a servo without waiting a tick).
    instantaneous: bool

    def reset(self, q: np.ndarray, jaw: float) -> ArmSample:
        """Place the arm at rest at ``q`` and return its state."""

    def command(self, q: np.ndarray, jaw: float) -> None:
        """Set the joint set-point the arm's servo loop tracks."""

    def step(self, dt_s: float) -> ArmSample:
        """Advance by ``dt_s`` [s] (0 to only read the state) and return the measured state."""

    def scene_markers(self) -> dict[str, Any]:
        """What the 3-D scene shows besides the arm (tissue, site, goal, grasp, force), in ``<arm>_base``."""


class WindowedVelocity:
    """Joint velocities as the change of the joints over the last :data:`VELOCITY_WINDOW_S` of the arm's time.

    Set-points arrive between the console's ticks and a physics model moves in whole steps, so a difference
    over one tick alternates between no motion and twice it; a real arm's encoders see its mass move
    smoothly, and the efforts its inertia needs (the force sensing's) follow that smooth velocity.
    """

    def __init__(self) -> None:
        self.reset(np.zeros(6))

    def reset(self, q: np.ndarray) -> None:
        """At rest at ``q``."""
        self._elapsed_s = 0.0
        self._history: collections.deque[tuple[float, np.ndarray]] = collections.deque(
            [(0.0, np.asarray(q, dtype=float).copy())]
        )
        self.qd = np.zeros(6)

    def advance(self, q: np.ndarray, dt_s: float) -> np.ndarray:
        """The arm is at ``q`` after ``dt_s`` [s] more of its time (none: the velocity is unchanged)."""
        if dt_s > 0.0:
            self._elapsed_s += dt_s
            self._history.append((self._elapsed_s, np.asarray(q, dtype=float).copy()))
            while len(self._history) > 2 and self._elapsed_s - self._history[1][0] >= VELOCITY_WINDOW_S:
                self._history.popleft()
            start_s, start_q = self._history[0]
            self.qd = (self._history[-1][1] - start_q) / (self._elapsed_s - start_s)
        return self.qd.copy()


class KinematicArm:
    """The dVRK's "KINEMATIC" simulation: the measured joints are the last commanded ones, their velocities
    a :class:`WindowedVelocity`.
    """

    instantaneous = True

    def __init__(self) -> None:
        self._q = np.zeros(6)
        self._jaw = 0.0
        self._velocity = WindowedVelocity()

    def reset(self, q: np.ndarray, jaw: float) -> ArmSample:
        """Place the arm at ``q``, at rest."""
        self._q = np.asarray(q, dtype=float).copy()
        self._jaw = float(jaw)
        self._velocity.reset(self._q)
        return self._sample()

    def command(self, q: np.ndarray, jaw: float) -> None:
        """Move to ``q`` at once."""
        self._q = np.asarray(q, dtype=float).copy()
        self._jaw = float(jaw)

    def step(self, dt_s: float) -> ArmSample:
        """Report the last command; velocities over the window when ``dt_s`` is positive."""
        self._velocity.advance(self._q, dt_s)
        return self._sample()

    def _sample(self) -> ArmSample:
        return ArmSample(self._q.copy(), self._velocity.qd.copy(), self._jaw, np.zeros(3))

    def scene_markers(self) -> dict[str, Any]:
        """Nothing but the arm: there is no task scene."""
        return {}
