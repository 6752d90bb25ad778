"""The observation's quaternion: the same numbers as pinocchio's (Eigen's), without its per-call memory."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from psm_control.quaternion import quaternion_xyzw


@pytest.mark.parametrize("seed", range(200))
def test_matches_eigen_on_random_rotations(seed: int) -> None:
    """Every branch (positive trace, each largest diagonal) gives Eigen's quaternion, sign included."""
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    angle = rng.uniform(0.0, np.pi) if seed % 2 else rng.uniform(2.5, np.pi)  # half near pi: negative traces
    rotation = pin.exp3(axis / np.linalg.norm(axis) * angle)
    expected = np.asarray(pin.Quaternion(rotation).coeffs())
    np.testing.assert_allclose(quaternion_xyzw(rotation), expected, atol=1e-14)


def test_unit_norm_and_identity() -> None:
    """The identity is (0, 0, 0, 1); a half turn about z is (0, 0, 1, 0)."""
    np.testing.assert_array_equal(quaternion_xyzw(np.eye(3)), [0.0, 0.0, 0.0, 1.0])
    half_turn = np.diag([-1.0, -1.0, 1.0])
    np.testing.assert_allclose(quaternion_xyzw(half_turn), [0.0, 0.0, 1.0, 0.0])
