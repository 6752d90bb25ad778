"""The RCM-to-base transform used each tick by the chain and the verifier."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from psm_control.frames import BaseTransform


def test_points_and_rows_match_the_homogeneous_transform() -> None:
    rng = np.random.default_rng(3)
    transform = pin.SE3.Random().homogeneous
    base = BaseTransform(transform)
    point, rows = rng.normal(size=3), rng.normal(size=(3, 6))
    np.testing.assert_allclose(base.point(point), (transform @ np.r_[point, 1.0])[:3], atol=1e-12)
    np.testing.assert_allclose(base.vectors(rows), transform[:3, :3] @ rows, atol=1e-12)


def test_an_identity_rotation_gives_exactly_the_translated_point_and_does_not_alias() -> None:
    transform = np.eye(4)
    transform[:3, 3] = [0.1, -0.2, 0.3]
    base = BaseTransform(transform)
    point = np.array([1e-3, 2e-3, -5e-2])
    moved = base.point(point)
    assert np.array_equal(moved, point + transform[:3, 3]) and moved is not point
    rows = np.arange(18.0).reshape(3, 6)
    assert np.array_equal(base.vectors(rows), rows)


def test_the_kept_inverse_takes_base_points_back_to_the_rcm() -> None:
    """The inverse kept at construction undoes the transform, and is the one a fresh inversion gives."""
    transform = pin.SE3.Random().homogeneous
    base = BaseTransform(transform)
    np.testing.assert_allclose(base.transform_base_to_rcm @ transform, np.eye(4), atol=1e-12)
    np.testing.assert_array_equal(base.transform_base_to_rcm, np.linalg.inv(transform))
