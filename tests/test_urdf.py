"""The checked-in URDF is the generator's output and describes the DH chain."""

from __future__ import annotations

import pytest

from psm_control.spec import ARMS, psm_spec
from psm_control.urdf import generate_urdf, urdf_path


@pytest.mark.parametrize("arm", ARMS)
def test_checked_in_urdf_equals_generator_output(arm: str) -> None:
    """The packaged URDF is byte-for-byte what the generator makes from the DH table (run `make urdf`)."""
    spec = psm_spec(arm)
    assert urdf_path(spec).read_text() == generate_urdf(spec)


@pytest.mark.parametrize("arm", ARMS)
def test_urdf_carries_the_spec_limits(arm: str) -> None:
    """Each joint's URDF limits are the spec's, so PyBullet and Pinocchio see the dVRK's limits."""
    from psm_control.robot import PsmModel

    model = PsmModel.from_variant(arm)
    for index, joint in enumerate(model.spec.joints, start=1):
        assert model.model.lowerPositionLimit[index - 1] == pytest.approx(joint.lower)
        assert model.model.upperPositionLimit[index - 1] == pytest.approx(joint.upper)
        assert model.model.velocityLimit[index - 1] == pytest.approx(joint.velocity_limit)
