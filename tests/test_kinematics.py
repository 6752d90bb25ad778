"""Forward kinematics and Jacobians of the Pinocchio model against independent references."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pybullet as p
import pytest

from psm_control.dh import dh_chain, dh_tool_pose
from psm_control.robot import PsmModel
from psm_control.urdf import GRASP_FRAME, JAW_JOINTS
from sim.psm_body import PsmBody
from tests.conftest import random_joints


def test_fk_matches_closed_form_dh(model: PsmModel) -> None:
    """Pinocchio's tool-tip pose equals the closed-form modified-DH product at 1,000 random joint vectors."""
    configuration = model.configuration()
    rng = np.random.default_rng(1)
    for q in random_joints(model, rng, 1000):
        configuration.update(q)
        expected = dh_tool_pose(model.spec, q)
        actual = configuration.local_pose()
        np.testing.assert_allclose(actual[:3, 3], expected[:3, 3], rtol=0, atol=1e-9)
        rotation_error = pin.log3(actual[:3, :3].T @ expected[:3, :3])
        assert np.linalg.norm(rotation_error) < 1e-9


def test_intermediate_joint_frames_match_dh(classic: PsmModel) -> None:
    """Every joint frame of the Pinocchio model equals the DH chain's frame, not only the tool tip."""
    configuration = classic.configuration()
    rng = np.random.default_rng(2)
    for q in random_joints(classic, rng, 100):
        configuration.update(q)
        for index, expected in enumerate(dh_chain(classic.spec, q), start=1):
            np.testing.assert_allclose(configuration.data.oMi[index].homogeneous, expected, atol=1e-9)


def test_home_tool_points_down_the_shaft(classic: PsmModel) -> None:
    """At zero angles the tool tip lies on the RCM's -z axis, 0.12 - 0.4318 + 0.4162 + 0.0091 m past the RCM."""
    pose = classic.configuration(classic.home()).local_pose()
    np.testing.assert_allclose(pose[:3, 3], [0.0, 0.0, -(0.12 - 0.4318 + 0.4162 + 0.0091)], atol=1e-10)
    np.testing.assert_allclose(pose[:3, 2], [0.0, 0.0, -1.0], atol=1e-10)


def test_pybullet_link_poses_equal_pinocchio(model: PsmModel) -> None:
    """PyBullet's pose of every link of the same URDF equals Pinocchio's to 1e-6, jaws included."""
    client = p.connect(p.DIRECT)
    try:
        body = PsmBody(client, model)
        configuration = model.configuration()
        rng = np.random.default_rng(3)
        for q in random_joints(model, rng, 200):
            jaw = rng.uniform(model.spec.jaw_lower, model.spec.jaw_upper)
            configuration.update(q, jaw)
            body.reset_joints(q, jaw)
            for link in body.link_index:
                np.testing.assert_allclose(
                    body.link_pose(link), configuration.frame_pose_local(link), atol=1e-6, err_msg=link
                )
    finally:
        p.disconnect(client)


def _finite_difference_jacobian(model: PsmModel, q: np.ndarray, frame: str, step: float = 1e-6) -> np.ndarray:
    configuration = model.configuration()
    jacobian = np.zeros((6, model.dof))
    for joint in range(model.dof):
        dq = np.zeros(model.dof)
        dq[joint] = step
        configuration.update(q + dq)
        plus = configuration.frame_pose_local(frame)
        configuration.update(q - dq)
        minus = configuration.frame_pose_local(frame)
        jacobian[:3, joint] = (plus[:3, 3] - minus[:3, 3]) / (2 * step)
        # Angular velocity in world-aligned axes: log of the relative rotation, expressed in the world.
        jacobian[3:, joint] = pin.log3(plus[:3, :3] @ minus[:3, :3].T) / (2 * step)
    return jacobian


@pytest.mark.parametrize("frame", ["tool_tip_link", GRASP_FRAME])
def test_jacobian_matches_finite_differences(model: PsmModel, frame: str) -> None:
    """The 6x6 frame Jacobian equals central finite differences of the pose to 1e-6."""
    rng = np.random.default_rng(4)
    configuration = model.configuration()
    margin = 1e-3
    for q in rng.uniform(model.lower + margin, model.upper - margin, size=(50, model.dof)):
        configuration.update(q)
        np.testing.assert_allclose(
            configuration.local_jacobian(frame), _finite_difference_jacobian(model, q, frame), atol=1e-6
        )


def test_base_frame_maps_measured_pose_and_jacobian(classic: PsmModel) -> None:
    """measured_cp = base_frame @ local_cp and the base Jacobian is the local one rotated into the base axes."""
    base = np.eye(4)
    base[:3, :3] = pin.rpy.rpyToMatrix(0.3, -0.2, 1.1)
    base[:3, 3] = [0.1, -0.05, 0.4]
    configuration = classic.configuration(base_frame=base)
    q = np.array([0.2, -0.3, 0.15, 0.5, 0.2, -0.1])
    configuration.update(q)
    np.testing.assert_allclose(configuration.measured_pose(), base @ configuration.local_pose(), atol=1e-12)
    local = configuration.local_jacobian()
    base_jacobian = configuration.base_jacobian()
    np.testing.assert_allclose(base_jacobian[:3], base[:3, :3] @ local[:3], atol=1e-12)
    np.testing.assert_allclose(base_jacobian[3:], base[:3, :3] @ local[3:], atol=1e-12)


def test_jaw_angle_opens_both_jaws_symmetrically(classic: PsmModel) -> None:
    """A jaw angle of theta turns each jaw by theta/2 away from the other."""
    configuration = classic.configuration(jaw=0.8)
    left = configuration.frame_pose_local(f"{JAW_JOINTS[0]}_link")[:3, :3]
    right = configuration.frame_pose_local(f"{JAW_JOINTS[1]}_link")[:3, :3]
    angle = np.arccos(np.clip(left[:, 2] @ right[:, 2], -1.0, 1.0))
    assert angle == pytest.approx(0.8, abs=1e-12)
