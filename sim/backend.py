"""The simulated PSM as a control-chain :class:`~psm_control.commands.Backend`.

The real dVRK is position-controlled, so the simulation is too: a verified joint set-point is applied
kinematically (joint state reset), and the measurement is the state it set. The tissue force estimate
is fed in by the environment, as a force sensor would be on hardware.

Two dynamics disturbances act here (both off by default, and then nothing changes):

* an encoder offset (calibration error): :meth:`SimBackend.measure` reports ``q + offset`` and a
  set-point is reached when the *measured* joints equal it, so the true joints go to ``q_cmd - offset``;
* a tracking lag: the true joints follow the set-point with a first-order lag per physics substep,
  ``q += (1 - lag) * (q_target - q)``, advanced by :meth:`SimBackend.advance` (the jaw is not lagged).
"""

from __future__ import annotations

import numpy as np

from psm_control.commands import JointCommand, MeasuredState
from psm_control.errors import ConfigurationError
from sim.psm_body import PsmBody

__all__ = ["SimBackend"]


class SimBackend:
    """Applies joint commands to a :class:`PsmBody` and reports its state.

    Args:
        body: The simulated arm.
        q: Initial arm joints (6,), true.
        jaw: Initial jaw angle [rad].
        joint_offset: Encoder offset added to the measured joints (6,); None: none.
        tracking_lag: First-order lag per physics substep in [0, 1); 0: set-points are reached at once.
        substep_s: Physics substep [s] (the lagged joints' velocity is measured over it).
    """

    def __init__(
        self,
        body: PsmBody,
        q: np.ndarray,
        jaw: float,
        *,
        joint_offset: np.ndarray | None = None,
        tracking_lag: float = 0.0,
        substep_s: float = 1.0 / 240.0,
    ) -> None:
        if not 0.0 <= tracking_lag < 1.0:
            raise ConfigurationError("tracking_lag", tracking_lag, "a lag in [0, 1)")
        self.body = body
        self.q = np.asarray(q, dtype=float).copy()
        self.qd = np.zeros_like(self.q)
        self.jaw = float(jaw)
        self.force_n = np.zeros(3)
        self.stamp_s = 0.0
        self.joint_offset = None if joint_offset is None else np.asarray(joint_offset, dtype=float).copy()
        self.tracking_lag = float(tracking_lag)
        self.substep_s = float(substep_s)
        self.q_target = self.q.copy()
        body.reset_joints(self.q, self.jaw)

    @property
    def lagging(self) -> bool:
        """Whether the joints follow their set-point with a lag (then call :meth:`advance` per substep)."""
        return self.tracking_lag > 0.0

    def measure(self) -> MeasuredState:
        """The arm's current state, as its encoders report it."""
        q = self.q.copy() if self.joint_offset is None else self.q + self.joint_offset
        return MeasuredState(q, self.qd.copy(), self.jaw, self.force_n.copy(), self.stamp_s)

    def servo_jp(self, command: JointCommand) -> None:
        """Move the arm to a joint set-point (no dynamics: the dVRK's servo loop tracks it)."""
        target = np.asarray(command.q, dtype=float).copy()
        if self.joint_offset is not None:
            target = target - self.joint_offset
        self.jaw = float(command.jaw)
        self.stamp_s = float(command.stamp_s)
        if self.lagging:
            self.q_target = target
            self.body.reset_joints(self.q, self.jaw)
            return
        self.q = target
        self.q_target = self.q.copy()
        self.qd = np.asarray(command.qd, dtype=float).copy()
        self.body.reset_joints(self.q, self.jaw)

    def advance(self) -> None:
        """One physics substep of the lagged tracking (nothing without a lag)."""
        if not self.lagging:
            return
        move = (1.0 - self.tracking_lag) * (self.q_target - self.q)
        self.q = self.q + move
        self.qd = move / self.substep_s
        self.body.reset_joints(self.q, self.jaw)
