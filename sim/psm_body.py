"""The PSM as a PyBullet multibody, loaded from the same URDF as the Pinocchio model."""

from __future__ import annotations

import numpy as np
import pybullet as p

from psm_control.robot import PsmModel
from psm_control.urdf import JAW_JOINTS

__all__ = ["PsmBody"]


class PsmBody:
    """A PSM in one PyBullet physics client.

    Every call passes the client id, so several bodies in several clients never share a world.

    Args:
        client: PyBullet physics client id.
        model: The PSM model whose URDF is loaded.
        rcm_position: Position of the RCM (the URDF root) in the world [m].
        rcm_orientation: Orientation of the RCM frame as an xyzw quaternion.
    """

    def __init__(
        self,
        client: int,
        model: PsmModel,
        rcm_position: np.ndarray | None = None,
        rcm_orientation: np.ndarray | None = None,
    ) -> None:
        self.client = client
        self.model = model
        position = np.zeros(3) if rcm_position is None else np.asarray(rcm_position, dtype=float)
        orientation = np.array([0.0, 0.0, 0.0, 1.0]) if rcm_orientation is None else np.asarray(rcm_orientation)
        self.body_id = p.loadURDF(
            str(model.urdf_path),
            position.tolist(),
            orientation.tolist(),
            useFixedBase=True,
            flags=p.URDF_USE_INERTIA_FROM_FILE,
            physicsClientId=client,
        )
        self.joint_index: dict[str, int] = {}
        self.link_index: dict[str, int] = {}
        for index in range(p.getNumJoints(self.body_id, physicsClientId=client)):
            info = p.getJointInfo(self.body_id, index, physicsClientId=client)
            self.joint_index[info[1].decode()] = index
            self.link_index[info[12].decode()] = index
        self.arm_joints = [self.joint_index[name] for name in model.spec.joint_names]
        self.jaw_joints = [self.joint_index[name] for name in JAW_JOINTS]
        self._joints = self.arm_joints + self.jaw_joints

    def reset_joints(self, q: np.ndarray, jaw: float = 0.0) -> None:
        """Teleport the arm and jaw to a configuration at rest (no dynamics), in one call to the engine."""
        if len(q) != len(self.arm_joints):
            raise ValueError(f"reset_joints: {len(self.arm_joints)} joint values expected, got {len(q)}")
        values = [[float(v)] for v in q] + [[float(jaw) / 2.0]] * len(self.jaw_joints)
        p.resetJointStatesMultiDof(self.body_id, self._joints, targetValues=values, physicsClientId=self.client)

    def link_pose(self, link: str) -> np.ndarray:
        """4x4 world pose of a URDF link's frame."""
        state = p.getLinkState(
            self.body_id, self.link_index[link], computeForwardKinematics=True, physicsClientId=self.client
        )
        transform = np.eye(4)
        transform[:3, :3] = np.reshape(p.getMatrixFromQuaternion(state[5], physicsClientId=self.client), (3, 3))
        transform[:3, 3] = state[4]
        return transform
