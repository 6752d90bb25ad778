"""Jerk-limited smoothing of the filtered joint goals with Ruckig, one control period at a time.

Each tick the goal (where the filtered step says the joints should come to rest) is handed to Ruckig,
which returns the next state of a time-optimal trajectory to it within the per-joint velocity,
acceleration and jerk limits, starting from the previous output. Because every trajectory ends at rest at
its goal and the state is always on a feasible plan, the output never passes the furthest goal it was
given. Ruckig's community edition does not enforce position limits; the verifier checks that.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from ruckig import ControlInterface, InputParameter, OutputParameter, Result, Ruckig, RuckigError

from psm_control.errors import SafetyStopError

__all__ = ["JointSmoother", "SmootherState"]

_WORKING = Result.Working
_DUST = 1e-9  # velocity [rad/s, m/s] and acceleration below which a retry treats the joint as at rest


class SmootherState(NamedTuple):
    """The smoother's output at one tick.

    Attributes:
        q: Joint positions (6,).
        qd: Joint velocities (6,).
        qdd: Joint accelerations (6,).
    """

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray


class JointSmoother:
    """Ruckig at the control period, tracking a new goal each tick.

    Args:
        velocity_limit: Per-joint velocity limits (6,).
        acceleration_limit: Per-joint acceleration limits (6,).
        jerk_limit: Per-joint jerk limits (6,).
        dt: Control period [s].
    """

    def __init__(
        self, velocity_limit: np.ndarray, acceleration_limit: np.ndarray, jerk_limit: np.ndarray, dt: float
    ) -> None:
        self.dof = int(np.asarray(velocity_limit).size)
        self.dt = dt
        self._ruckig = Ruckig(self.dof, dt)
        self._input = InputParameter(self.dof)
        self._output = OutputParameter(self.dof)
        self._input.max_velocity = [float(v) for v in velocity_limit]
        self._input.max_acceleration = [float(a) for a in acceleration_limit]
        self._input.max_jerk = [float(j) for j in jerk_limit]
        self._zeros = [0.0] * self.dof
        self._input.control_interface = ControlInterface.Position
        self._input.target_velocity = self._zeros
        self._input.target_acceleration = self._zeros
        self._braking = False
        self.reset(np.zeros(self.dof))

    def reset(self, q: np.ndarray) -> SmootherState:
        """Start at rest at ``q``."""
        self._input.current_position = np.asarray(q, dtype=float).tolist()
        self._input.current_velocity = self._zeros
        self._input.current_acceleration = self._zeros
        self._state = self._read_state()
        return self._state

    @property
    def state(self) -> SmootherState:
        """The current (last output) state (treat its arrays as read-only)."""
        return self._state

    def _read_state(self) -> SmootherState:
        # Read-only: the same arrays are the next tick's starting state, so nobody may change them.
        # One (3, dof) array; its rows are read-only views.
        data = self._input
        rows = np.array((data.current_position, data.current_velocity, data.current_acceleration))
        rows.flags.writeable = False
        return SmootherState(rows[0], rows[1], rows[2])

    def step_to(self, goal: np.ndarray) -> SmootherState:
        """Advance one period towards ``goal``, where the joints should come to rest.

        Raises:
            SafetyStopError: Ruckig rejected the input or failed to compute a trajectory.
        """
        if self._braking:  # the target velocity and acceleration stay zero in both interfaces
            self._input.control_interface = ControlInterface.Position
            self._braking = False
        self._input.target_position = np.asarray(goal, dtype=float).tolist()
        return self._update()

    def brake(self) -> SmootherState:
        """Advance one period of the quickest jerk-limited stop from the current state."""
        self._input.control_interface = ControlInterface.Velocity
        self._braking = True
        return self._update()

    def _update(self) -> SmootherState:
        try:
            result = self._ruckig.update(self._input, self._output)
        except (RuntimeError, RuckigError):
            # Ruckig 0.19 can fail to synchronise a joint that is at its target with a residual velocity
            # or acceleration of ~1e-15 (floating-point dust after a stop, measured). Zeroing components
            # below 1e-9 changes the motion by far less than any limit's tolerance; then try once more.
            self._input.current_velocity = [v if abs(v) > _DUST else 0.0 for v in self._input.current_velocity]
            self._input.current_acceleration = [a if abs(a) > _DUST else 0.0 for a in self._input.current_acceleration]
            try:
                result = self._ruckig.update(self._input, self._output)
            except (RuntimeError, RuckigError) as e:
                raise SafetyStopError(f"smoother: Ruckig rejected the input ({str(e).splitlines()[0]})") from e
        if result is not _WORKING and result not in (Result.Working, Result.Finished):
            raise SafetyStopError(f"smoother: Ruckig returned {result}")
        self._output.pass_to_input(self._input)
        self._state = self._read_state()
        return self._state
