"""The shipped identified arm: read from the package, its inertia linear in the acceleration, names checked."""

from __future__ import annotations

import numpy as np
import pytest

from psm_control.errors import UnknownVariantError
from sim.identified_arm import ARM_FILES, identified_arm


def test_the_shipped_arm_is_read_with_its_provenance() -> None:
    """Every shipped arm loads from the package: as many values as columns, six residuals, a source named."""
    for name in ARM_FILES:
        arm = identified_arm(name)
        assert len(arm.columns) == len(arm.parameters) > 0
        assert len(arm.residual) == 6 and all(r > 0 for r in arm.residual)
        assert arm.residual_time_s > 0
        assert "bench sensing" in arm.provenance


def test_the_inertia_is_the_acceleration_part_of_the_efforts() -> None:
    """efforts(q, 0, a) - efforts(q, 0, 0) = inertial_efforts(q, a), and it doubles with a."""
    arm = identified_arm("wpi-psm")
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(-0.5, 0.5, 6)
        q[2] = rng.uniform(0.06, 0.2)
        a = rng.uniform(-5, 5, 6)
        zero = np.zeros(6)
        np.testing.assert_allclose(arm.efforts(q, zero, a) - arm.efforts(q, zero, zero), arm.inertial_efforts(q, a))
        np.testing.assert_allclose(arm.inertial_efforts(q, 2 * a), 2 * arm.inertial_efforts(q, a), atol=1e-12)


def test_an_unknown_arm_is_named_with_the_known_ones() -> None:
    """An unknown arm's name gets an error that lists the shipped ones."""
    with pytest.raises(UnknownVariantError, match="wpi-psm"):
        identified_arm("no-such-arm")
