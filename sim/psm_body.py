"""The PSM as a PyBullet multibody, loaded from the same URDF as the Pinocchio model."""

from __future__ import annotations

import numpy as np

from psm_control.robot import PsmModel
from psm_control.urdf import JAW_JOINTS
from sim.quiet_pybullet import pybullet as p

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
            # Every drawn frame loads a copy of the arm (sim.scene); with the client's shapes cached a load and
            # removal takes 0.62 ms instead of 0.90 ms (measured).
            flags=p.URDF_USE_INERTIA_FROM_FILE | p.URDF_ENABLE_CACHED_GRAPHICS_SHAPES,
            physicsClientId=client,
        )
        self.rcm_position = position
        self.rcm_orientation = orientation
        self.joint_index: dict[str, int] = {}
        self.link_index: dict[str, int] = {}
        for index in range(p.getNumJoints(self.body_id, physicsClientId=client)):
            info = p.getJointInfo(self.body_id, index, physicsClientId=client)
            self.joint_index[info[1].decode()] = index
            self.link_index[info[12].decode()] = index
        self.arm_joints = [self.joint_index[name] for name in model.spec.joint_names]
        self.jaw_joints = [self.joint_index[name] for name in JAW_JOINTS]
        self._joints = self.arm_joints + self.jaw_joints

    def move_base(self, rcm_position: np.ndarray) -> None:
        """Put the RCM (the URDF root) at a new world position, orientation unchanged [m]."""
        self.rcm_position = np.asarray(rcm_position, dtype=float).copy()
        p.resetBasePositionAndOrientation(
            self.body_id, self.rcm_position.tolist(), self.rcm_orientation.tolist(), physicsClientId=self.client
        )

    def joint_states(self) -> tuple[np.ndarray, float]:
        """The arm joints (6,) and the jaw angle [rad] the body is at now."""
        states = p.getJointStates(self.body_id, self._joints, physicsClientId=self.client)
        return np.array([state[0] for state in states[: len(self.arm_joints)]]), 2.0 * states[-1][0]

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
