"""The simulated PSM as a control-chain :class:`~psm_control.commands.Backend`.

The real dVRK is position-controlled, so the simulation is too: a verified joint set-point is applied
kinematically (joint state reset), and the measurement is the state it set. The tissue force estimate
is fed in by the environment, as a force sensor would be on hardware.
"""

from __future__ import annotations

import numpy as np

from psm_control.commands import JointCommand, MeasuredState
from sim.psm_body import PsmBody

__all__ = ["SimBackend"]


class SimBackend:
    """Applies joint commands to a :class:`PsmBody` and reports its state.

    Args:
        body: The simulated arm.
        q: Initial arm joints (6,).
        jaw: Initial jaw angle [rad].
    """

    def __init__(self, body: PsmBody, q: np.ndarray, jaw: float) -> None:
        self.body = body
        self.q = np.asarray(q, dtype=float).copy()
        self.qd = np.zeros_like(self.q)
        self.jaw = float(jaw)
        self.force_n = np.zeros(3)
        self.stamp_s = 0.0
        body.reset_joints(self.q, self.jaw)

    def measure(self) -> MeasuredState:
        """The arm's current state."""
        return MeasuredState(self.q.copy(), self.qd.copy(), self.jaw, self.force_n.copy(), self.stamp_s)

    def servo_jp(self, command: JointCommand) -> None:
        """Move the arm to a joint set-point (no dynamics: the dVRK's servo loop tracks it)."""
        self.q = np.asarray(command.q, dtype=float).copy()
        self.qd = np.asarray(command.qd, dtype=float).copy()
        self.jaw = float(command.jaw)
        self.stamp_s = float(command.stamp_s)
        self.body.reset_joints(self.q, self.jaw)
