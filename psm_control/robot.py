"""The PSM as a Pinocchio model, and the robot state object every stage of the chain shares.

:class:`PsmModel` loads the package's URDF once (nothing else defines the robot) and checks joint
vectors. :class:`PsmConfiguration` is the one state carrier, in the manner of pink/mink's
``Configuration``: a read-only joint vector, forward kinematics, Jacobians, and the dVRK frames
``local`` (about the RCM, as ``local/measured_cp``) and base (``measured_cp = base_frame @ local``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from psm_control.errors import JointLimitError, JointVectorError
from psm_control.spec import PsmSpec, psm_spec
from psm_control.urdf import GRASP_FRAME, JAW_JOINTS, TOOL_TIP_FRAME, urdf_path

__all__ = ["PsmConfiguration", "PsmModel"]


@dataclass(frozen=True)
class _FrameIds:
    tool_tip: int
    grasp: int


class PsmModel:
    """The kinematic model of one PSM variant, loaded from the package's URDF.

    Args:
        spec: The variant; defaults to the Classic PSM with the 400006 large needle driver.

    Attributes:
        spec: The variant's specification.
        model: The Pinocchio model (6 arm joints then the two jaw joints).
    """

    def __init__(self, spec: PsmSpec | None = None) -> None:
        self.spec = spec if spec is not None else psm_spec()
        self.urdf_path = urdf_path(self.spec)
        self.model: pin.Model = pin.buildModelFromUrdf(str(self.urdf_path))
        names = [self.model.names[i] for i in range(1, self.model.njoints)]
        expected = [*self.spec.joint_names, *JAW_JOINTS]
        if names != expected:
            raise JointVectorError(f"URDF {self.urdf_path} has joints {names}, expected {expected}")
        self.frame_ids = _FrameIds(
            tool_tip=self.model.getFrameId(TOOL_TIP_FRAME), grasp=self.model.getFrameId(GRASP_FRAME)
        )
        self.lower = self.spec.lower
        self.upper = self.spec.upper
        self.velocity_limit = self.spec.velocity_limit
        self.acceleration_limit = self.spec.acceleration_limit
        self._dof = self.spec.dof
        self._shape = (self._dof,)

    @classmethod
    def from_variant(cls, arm: str = "classic", tool: str | None = None) -> PsmModel:
        """Build the model of a named variant (see :func:`psm_control.spec.psm_spec`)."""
        return cls(psm_spec(arm, tool))

    @property
    def dof(self) -> int:
        """Number of arm joints (6)."""
        return self.spec.dof

    def check_joints(self, q: object, *, strict: bool = False, name: str = "q") -> np.ndarray:
        """Return ``q`` as a float array of shape (6,), or raise naming what is wrong.

        Args:
            q: Joint positions in dVRK order.
            strict: Also require every joint within its position limits.
            name: What the vector is, for the error message.

        Raises:
            JointVectorError: Wrong length or a non-finite value (the joint is named).
            JointLimitError: With ``strict``, a joint outside its limits (joint, value and bound named).
        """
        try:
            array = np.asarray(q, dtype=float)
        except (TypeError, ValueError) as e:
            raise JointVectorError(f"{name} is not a numeric vector: {q!r}") from e
        if array.shape != self._shape:
            raise JointVectorError(
                f"{name} must have shape ({self.dof},) for joints {self.spec.joint_names}, got {array.shape}",
                value=array.shape,
            )
        # The common case in one or two vector comparisons (NaN fails both, an overflowing sum only sends a
        # finite vector to the loop); the loop names the first offending joint.
        if strict:
            if np.count_nonzero((array >= self.lower) & (array <= self.upper)) == self._dof:
                return array
        elif math.isfinite(array.sum()):
            return array
        for joint, value in zip(self.spec.joints, array, strict=True):
            if not np.isfinite(value):
                raise JointVectorError(f"{name}: joint {joint.name!r} is {value}", joint=joint.name, value=value)
            if strict and value < joint.lower:
                raise JointLimitError(joint.name, float(value), joint.lower)
            if strict and value > joint.upper:
                raise JointLimitError(joint.name, float(value), joint.upper)
        return array

    def check_jaw(self, jaw: float, *, strict: bool = False) -> float:
        """Return the jaw angle as a float, or raise if non-finite (or out of range with ``strict``)."""
        value = float(jaw)
        if not np.isfinite(value):
            raise JointVectorError(f"jaw angle is {value}", joint="jaw", value=value)
        if strict and value < self.spec.jaw_lower:
            raise JointLimitError("jaw", value, self.spec.jaw_lower)
        if strict and value > self.spec.jaw_upper:
            raise JointLimitError("jaw", value, self.spec.jaw_upper)
        return value

    def configuration(
        self, q: object | None = None, jaw: float = 0.0, base_frame: np.ndarray | None = None
    ) -> PsmConfiguration:
        """Return a new state object at ``q`` (default: the dVRK's Cartesian start pose)."""
        return PsmConfiguration(self, q, jaw=jaw, base_frame=base_frame)

    def home(self) -> np.ndarray:
        """A safe start configuration: zero angles at the insertion the dVRK scripts use."""
        q = np.zeros(self.dof)
        q[2] = self.spec.rcm.cartesian_start_insertion_m
        return q


class PsmConfiguration:
    """Robot state: joint positions and the frames and Jacobians derived from them.

    Stages of the control chain take this object as an argument; it is updated from measurements
    with :meth:`update`. ``q`` is a read-only view, so no stage can change it behind the others' backs.

    Args:
        model: The PSM model.
        q: Joint positions (6,), dVRK order; default :meth:`PsmModel.home`.
        jaw: Jaw opening angle [rad].
        base_frame: 4x4 pose of the RCM in the base frame (dVRK ``set_base_frame``); default identity.
    """

    def __init__(
        self, model: PsmModel, q: object | None = None, jaw: float = 0.0, base_frame: np.ndarray | None = None
    ) -> None:
        self.model = model
        self.data = model.model.createData()
        self._q_full = np.zeros(model.model.nq)
        self._q = np.zeros(model.dof)
        self._jaw = 0.0
        self._base = np.eye(4)
        self._tip_pose: np.ndarray | None = None
        self._tip_jacobian: np.ndarray | None = None
        self._q_bytes = b""  # the joints the kinematics were computed at (none yet)
        if base_frame is not None:
            self.set_base_frame(base_frame)
        self.update(model.home() if q is None else q, jaw)

    @property
    def q(self) -> np.ndarray:
        """Arm joint positions (6,), read-only."""
        view = self._q.view()
        view.flags.writeable = False
        return view

    @property
    def jaw(self) -> float:
        """Jaw opening angle [rad]."""
        return self._jaw

    @property
    def base_frame(self) -> np.ndarray:
        """4x4 pose of the RCM in the base frame (copy)."""
        return self._base.copy()

    def set_base_frame(self, transform_rcm_to_base: np.ndarray) -> None:
        """Set the base frame as the dVRK's ``set_base_frame`` does (``measured_cp = base @ local``)."""
        transform = np.asarray(transform_rcm_to_base, dtype=float)
        if transform.shape != (4, 4) or not np.all(np.isfinite(transform)):
            raise JointVectorError(f"base frame must be a finite 4x4 transform, got shape {transform.shape}")
        rotation = transform[:3, :3]
        if not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-9) or np.linalg.det(rotation) < 0:
            raise JointVectorError("base frame rotation is not a proper rotation matrix")
        self._base = transform.copy()

    def update(self, q: object, jaw: float | None = None) -> None:
        """Set the joint positions (and optionally the jaw) and recompute kinematics if they changed.

        Raises:
            JointVectorError: Wrong length or non-finite values; the state is left unchanged.
        """
        array = self.model.check_joints(q)
        jaw_value = self._jaw if jaw is None else self.model.check_jaw(jaw)
        # An env step updates its state object twice with the same joints (measured: 22 % of all updates).
        if jaw_value == self._jaw and array.tobytes() == self._q_bytes:
            return
        self._q_bytes = array.tobytes()
        self._q[:] = array
        self._jaw = jaw_value
        self._q_full[: self.model.dof] = array
        self._q_full[self.model.dof :] = jaw_value / 2.0
        pin.computeJointJacobians(self.model.model, self.data, self._q_full)
        pin.updateFramePlacements(self.model.model, self.data)
        self._tip_pose = None
        self._tip_jacobian = None

    def _frame_id(self, frame: str) -> int:
        if frame == TOOL_TIP_FRAME:
            return self.model.frame_ids.tool_tip
        if frame == GRASP_FRAME:
            return self.model.frame_ids.grasp
        if not self.model.model.existFrame(frame):
            valid = [f.name for f in self.model.model.frames]
            raise JointVectorError(f"unknown frame {frame!r}; valid frames: {valid}")
        return self.model.model.getFrameId(frame)

    def frame_pose_local(self, frame: str = TOOL_TIP_FRAME) -> np.ndarray:
        """4x4 pose of a URDF frame about the RCM."""
        return self.data.oMf[self._frame_id(frame)].homogeneous.copy()

    def local_pose(self) -> np.ndarray:
        """Tool-tip pose about the RCM: the dVRK's ``local/measured_cp``."""
        if self._tip_pose is None:  # computed once per update; every caller gets its own copy
            self._tip_pose = self.data.oMf[self.model.frame_ids.tool_tip].homogeneous
        return self._tip_pose.copy()

    def measured_pose(self) -> np.ndarray:
        """Tool-tip pose in the base frame: the dVRK's ``measured_cp``."""
        return self._base @ self.local_pose()

    def grasp_position(self) -> np.ndarray:
        """Position of the point midway along the jaws in the base frame [m]."""
        return (self._base @ self.frame_pose_local(GRASP_FRAME))[:3, 3]

    def local_jacobian(self, frame: str = TOOL_TIP_FRAME) -> np.ndarray:
        """6x6 Jacobian of a frame, about the RCM, [linear; angular] at the frame's origin.

        Expressed in the RCM frame's axes (Pinocchio ``LOCAL_WORLD_ALIGNED``), arm joints only.
        """
        if frame == TOOL_TIP_FRAME:  # computed once per update; every caller gets its own copy
            if self._tip_jacobian is None:
                self._tip_jacobian = pin.getFrameJacobian(
                    self.model.model, self.data, self.model.frame_ids.tool_tip, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
                )[:, : self.model.dof].copy()
            return self._tip_jacobian.copy()
        jacobian = pin.getFrameJacobian(
            self.model.model, self.data, self._frame_id(frame), pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        )
        return jacobian[:, : self.model.dof].copy()

    def base_jacobian(self, frame: str = TOOL_TIP_FRAME) -> np.ndarray:
        """6x6 Jacobian of a frame, expressed in the base frame's axes."""
        rotation = self._base[:3, :3]
        jacobian = self.local_jacobian(frame)
        jacobian[:3] = rotation @ jacobian[:3]
        jacobian[3:] = rotation @ jacobian[3:]
        return jacobian

    @property
    def insertion_m(self) -> float:
        """Insertion joint value [m], what the dVRK compares with its 45 mm RCM safety distance."""
        return float(self._q[2])

    def copy(self) -> PsmConfiguration:
        """An independent state object at the same joints, jaw and base frame."""
        return PsmConfiguration(self.model, self._q.copy(), self._jaw, self._base)
