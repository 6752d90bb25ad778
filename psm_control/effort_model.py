"""The joint efforts of a PSM in free space, linear in a parameter vector: rigid body, gravity, friction, offsets.

A PSM's measured efforts with nothing touching the tool are its own dynamics and losses. The
identification literature writes them linear in parameters (Wang et al. 2019, arXiv 1902.10875; Yang et
al. 2024, arXiv 2405.07453), ``tau = Y(q, qd, qdd) p``, with columns:

* **rigid body, without gravity** (inertia, Coriolis and centrifugal terms): Pinocchio's joint torque
  regressor (``pin.computeJointTorqueRegressor``) of the package's PSM model, ten inertial parameters per
  body, gravity set to zero;
* **gravity**, three times over: the same regressor at rest with gravity along each axis of the RCM frame.
  The arm's mounting (its setup joints) is not known, so the gravity direction is not either; each axis
  gets its own copy of the inertial parameters, and the fit finds ``g_k`` times them;
* **per joint**: Coulomb friction ``tanh(qd / coulomb_speed)``, viscous friction ``qd`` and an offset.

The package's URDF is a serial chain rooted at the RCM, not the dVRK's parallelogram and counterweight.
It still spans their dynamics to the precision the fit needs: the parallelogram's links turn with the
pitch joint about axes parallel to it, so their gravity is ``a cos q2 + b sin q2`` terms the pitch body's
centre of mass spans, and the counterweight moves against the insertion, so its weight is linear in the
insertion as the instrument's is (a negative mass on the insertion body is a valid fitted value). Many
columns are then not identifiable on their own: :func:`independent_columns` picks a set that is, on the
data fitted, by QR with column pivoting, and a calibration keeps those columns' indices with its values.
"""

from __future__ import annotations

import functools

import numpy as np
import pinocchio as pin

from psm_control.robot import PsmModel

__all__ = ["EffortRegressor", "independent_columns", "shared_regressor"]

_GRAVITY_M_S2 = 9.81
#: Inertial parameters per body in Pinocchio's regressor.
_PER_BODY = 10
#: Friction and offset columns per joint.
_PER_JOINT = 3
_JOINTS = 6


class EffortRegressor:
    """The regressor ``Y(q, qd, qdd)`` of one PSM's six arm-joint efforts (see the module notes).

    Args:
        model: The PSM's model; default the Classic PSM with the large needle driver.
        coulomb_speed: Speed over which Coulomb friction changes sign [rad/s or m/s].
    """

    def __init__(self, model: PsmModel | None = None, coulomb_speed: float = 0.02) -> None:
        self._model = (model if model is not None else PsmModel()).model.copy()
        self._data = self._model.createData()
        self.coulomb_speed = float(coulomb_speed)
        self._bodies = self._model.njoints - 1
        self._rigid = _PER_BODY * self._bodies
        #: Number of columns: rigid body, three gravity axes, friction and offsets.
        self.columns = 4 * self._rigid + _PER_JOINT * _JOINTS
        self._zero = np.zeros(self._model.nv)

    @property
    def friction_start(self) -> int:
        """Index of the first friction column (joint ``j``'s Coulomb, viscous, offset at ``start + 3 j``)."""
        return 4 * self._rigid

    def rows(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """The (6, :attr:`columns`) regressor of one sample (arm joints; the jaw held at 0)."""
        model, data = self._model, self._data
        q_full = np.zeros(model.nq)
        q_full[:_JOINTS] = q
        v = np.zeros(model.nv)
        v[:_JOINTS] = qd
        a = np.zeros(model.nv)
        a[:_JOINTS] = qdd
        out = np.zeros((_JOINTS, self.columns))
        model.gravity.linear = np.zeros(3)
        out[:, : self._rigid] = pin.computeJointTorqueRegressor(model, data, q_full, v, a)[:_JOINTS]
        for axis in range(3):
            gravity = np.zeros(3)
            gravity[axis] = -_GRAVITY_M_S2
            model.gravity.linear = gravity
            start = self._rigid * (1 + axis)
            out[:, start : start + self._rigid] = pin.computeJointTorqueRegressor(
                model, data, q_full, self._zero, self._zero
            )[:_JOINTS]
        model.gravity.linear = np.zeros(3)
        base = self.friction_start
        for joint in range(_JOINTS):
            out[joint, base + _PER_JOINT * joint] = np.tanh(qd[joint] / self.coulomb_speed)
            out[joint, base + _PER_JOINT * joint + 1] = qd[joint]
            out[joint, base + _PER_JOINT * joint + 2] = 1.0
        return out

    def matrix(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """The (N, 6, :attr:`columns`) regressors of N samples ``q, qd, qdd`` (N, 6)."""
        return np.stack([self.rows(q[k], qd[k], qdd[k]) for k in range(len(q))])


@functools.cache
def shared_regressor() -> EffortRegressor:
    """The default PSM's regressor, one for the whole process (one Pinocchio model and data for every user:
    the calibrations fitted and applied, the identified arms of the sensing model)."""
    return EffortRegressor()


def independent_columns(stacked: np.ndarray, rcond: float = 1e-7) -> np.ndarray:
    """Indices of a set of identifiable columns of a stacked regressor (rows x columns), in order.

    QR with column pivoting: the columns whose diagonal in ``R`` is above
    ``rcond`` times the largest, after each column is scaled to unit norm (so units do not decide).
    """
    from scipy.linalg import qr  # only a fit needs it; imported at the top it cost every arm model's process

    norms = np.linalg.norm(stacked, axis=0)
    used = np.flatnonzero(norms > 1e-12)
    _, r, pivots = qr(stacked[:, used] / norms[used], mode="economic", pivoting=True)
    diagonal = np.abs(np.diag(r))
    rank = int(np.sum(diagonal > rcond * diagonal[0]))
    return np.sort(used[pivots[:rank]])
