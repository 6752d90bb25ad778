"""The robot state object and the PSM variants reject bad input with the project's errors."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from psm_control.errors import (
    ConfigurationError,
    JointLimitError,
    JointVectorError,
    TissueRetractError,
    UnknownVariantError,
)
from psm_control.robot import PsmModel
from psm_control.spec import psm_spec


def test_variants_have_the_documented_numbers() -> None:
    """The Si variant differs from the Classic exactly where the dVRK configuration says."""
    classic, si = psm_spec("classic"), psm_spec("si")
    assert classic.joints[3].d == 0.4162 and si.joints[3].d == 0.4670
    assert classic.jaw_lower == pytest.approx(-0.698132) and si.jaw_lower == pytest.approx(-0.349066)
    assert si.joints[2].upper == 0.29 and si.joints[2].offset == -0.4826
    assert (si.joints[1].lower, si.joints[1].upper) == (-1.265, 1.301)
    assert classic.velocity_limit[0] == pytest.approx(math.radians(90))
    assert classic.acceleration_limit[2] == pytest.approx(0.2)


@pytest.mark.parametrize(
    ("arm", "tool", "field"), [("ecm", None, "arm"), ("classic", "999999", "tool"), ("classic", "420006", "arm/tool")]
)
def test_unknown_variant_names_valid_ones(arm: str, tool: str | None, field: str) -> None:
    """An unknown arm, tool or pairing raises UnknownVariantError listing what is valid."""
    with pytest.raises(UnknownVariantError) as info:
        psm_spec(arm, tool)
    assert info.value.field == field
    assert info.value.valid
    assert all(v in str(info.value) for v in info.value.valid)


def test_inconsistent_spec_is_refused_when_built() -> None:
    """Swapped limits or a non-positive velocity limit raise ConfigurationError naming the field."""
    spec = psm_spec()
    joints = list(spec.joints)
    joints[1] = dataclasses.replace(joints[1], lower=1.0, upper=-1.0)
    with pytest.raises(ConfigurationError, match=r"outer_pitch\.lower"):
        dataclasses.replace(spec, joints=tuple(joints))
    joints = list(spec.joints)
    joints[4] = dataclasses.replace(joints[4], velocity_limit=0.0)
    with pytest.raises(ConfigurationError, match=r"outer_wrist_pitch\.velocity_limit"):
        dataclasses.replace(spec, joints=tuple(joints))


@pytest.mark.parametrize("q", [np.zeros(5), np.zeros(7), np.zeros((2, 6)), "abc"])
def test_wrong_length_joint_vector_is_refused(classic: PsmModel, q: object) -> None:
    """A joint vector that is not 6 numbers raises JointVectorError and leaves the state unchanged."""
    configuration = classic.configuration()
    before = configuration.q.copy()
    with pytest.raises(JointVectorError):
        configuration.update(q)
    np.testing.assert_array_equal(configuration.q, before)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_joint_is_named(classic: PsmModel, bad: float) -> None:
    """A NaN or infinite joint value raises an error that names the joint."""
    q = classic.home()
    q[3] = bad
    with pytest.raises(JointVectorError, match="outer_roll") as info:
        classic.configuration().update(q)
    assert info.value.joint == "outer_roll"


def test_strict_check_names_joint_value_and_bound(classic: PsmModel) -> None:
    """Strict checking of an out-of-limit joint names the joint, the value and the bound."""
    q = classic.home()
    q[2] = 0.30
    with pytest.raises(JointLimitError) as info:
        classic.check_joints(q, strict=True)
    error = info.value
    assert (error.joint, error.value, error.bound) == ("outer_insertion", 0.30, 0.24)
    assert "outer_insertion" in str(error) and "0.3" in str(error) and "0.24" in str(error)
    assert isinstance(error, TissueRetractError)
    classic.check_joints(q)  # without strict checking, out-of-limit values are representable


def test_jaw_checks(classic: PsmModel) -> None:
    """A NaN jaw angle is refused; a jaw beyond its range is refused under strict checking."""
    with pytest.raises(JointVectorError, match="jaw"):
        classic.check_jaw(math.nan)
    with pytest.raises(JointLimitError, match="jaw"):
        classic.check_jaw(2.0, strict=True)


def test_state_q_is_read_only(classic: PsmModel) -> None:
    """No stage can write into the shared joint vector."""
    configuration = classic.configuration()
    with pytest.raises(ValueError, match="read-only"):
        configuration.q[0] = 1.0


def test_bad_base_frame_is_refused(classic: PsmModel) -> None:
    """A base frame that is not a rigid transform is refused."""
    configuration = classic.configuration()
    with pytest.raises(JointVectorError):
        configuration.set_base_frame(np.ones((4, 4)))
    with pytest.raises(JointVectorError):
        configuration.set_base_frame(np.eye(3))


def test_unknown_frame_lists_valid_frames(classic: PsmModel) -> None:
    """Asking for a frame the URDF lacks names the valid ones."""
    with pytest.raises(JointVectorError, match="tool_tip_link"):
        classic.configuration().frame_pose_local("no_such_frame")


def test_kinematics_kept_for_unchanged_joints_equal_fresh_ones(classic: PsmModel) -> None:
    """Through any sequence of updates, repeated joints included, every pose and Jacobian equals a fresh state's."""
    rng = np.random.default_rng(12)
    state = classic.configuration()
    frames = ("tool_tip_link", "grasp_link", "jaw_left_link")
    home = classic.home()
    for _ in range(60):
        q = home + rng.normal(scale=0.2, size=6) * (rng.random() < 0.6)  # often unchanged: exactly home
        jaw = float(rng.choice([0.0, 0.3, 0.6]))
        state.update(q, jaw if rng.random() < 0.7 else None)
        fresh = classic.configuration(state.q, state.jaw)
        np.testing.assert_array_equal(state.local_pose(), fresh.local_pose())
        np.testing.assert_array_equal(state.local_jacobian(), fresh.local_jacobian())
        for frame in frames:
            np.testing.assert_array_equal(state.frame_pose_local(frame), fresh.frame_pose_local(frame))
            np.testing.assert_array_equal(state.local_jacobian(frame), fresh.local_jacobian(frame))
