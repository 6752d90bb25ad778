"""The stereo endoscope: geometry that agrees with the render, seeded randomization, textures and inked sites."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from sim.endoscope import Appearance, Endoscope, look_at
from sim.rendering import CLASSES
from sim.tissue import TissueParams
from tests.sim.conftest import make_env

TEXTURES = Path(__file__).resolve().parents[1] / "data" / "textures"
_OPTIONS = {"site": "left", "site_offset_x_m": 0.003, "site_offset_y_m": -0.002}


def _left_image(mark: bool, texture: str | None = None, seed: int = 5) -> tuple[np.ndarray, Any, np.ndarray]:
    env = make_env("multisite", tissue=TissueParams(mark_sites=mark, texture_path=texture))
    try:
        env.reset(seed=seed, options=_OPTIONS)
        frame = env.unwrapped.render_endoscope(Appearance(), np.random.default_rng(0))
        return frame.left.astype(float), frame, env.unwrapped.site_position()
    finally:
        env.close()


def _project(frame: Any, point: np.ndarray) -> np.ndarray:
    camera = np.linalg.inv(frame.world_from_camera) @ np.r_[point, 1.0]
    pixel = frame.intrinsics @ camera[:3]
    return np.asarray(pixel[:2] / pixel[2])


def test_inked_site_is_where_the_true_site_projects() -> None:
    """The dot inked at the offset site lies within a pixel of the site projected by the frame's pose and K."""
    marked, frame, site = _left_image(True)
    plain, _, _ = _left_image(False)
    rows, cols = np.nonzero(np.abs(marked - plain).sum(axis=2) > 60)
    u, v = _project(frame, site)
    near = (np.abs(cols + 0.5 - u) < 8) & (np.abs(rows + 0.5 - v) < 8)
    assert near.sum() >= 4
    # A mirrored texture would put this dot 6 mm (about 5 px) away: within a pixel, it is not mirrored.
    assert np.hypot(cols[near].mean() + 0.5 - u, rows[near].mean() + 0.5 - v) < 1.0


def test_depth_and_labels_agree_with_the_pose() -> None:
    """The left eye's depth at the site's pixel is the site's depth in the camera frame (within 3 mm)."""
    _, frame, site = _left_image(False)
    u, v = _project(frame, site)
    camera = np.linalg.inv(frame.world_from_camera) @ np.r_[site, 1.0]
    assert frame.labels[int(v), int(u)] == CLASSES.index("tissue")
    assert abs(frame.depth_m[int(v), int(u)] - camera[2]) < 0.003


def test_appearances_are_seeded_and_within_their_ranges() -> None:
    """Same generator, same appearance; light within 35 degrees of the scope's axis, jitter within 4 mm."""
    endoscope = Endoscope()
    a = Appearance.sample(np.random.default_rng(3), endoscope)
    assert a == Appearance.sample(np.random.default_rng(3), endoscope)
    axis = np.subtract(endoscope.eye_m, endoscope.target_m)
    axis /= np.linalg.norm(axis)
    for seed in range(50):
        b = Appearance.sample(np.random.default_rng(seed), endoscope)
        assert np.degrees(np.arccos(np.dot(b.light_direction, axis))) <= 35.0 + 1e-9
        assert np.max(np.abs(b.eye_shift_m)) <= 0.004 and 0.0 <= b.specular <= 0.6


def test_randomized_frames_differ_and_the_right_eye_is_offset() -> None:
    """Two appearances of one scene give different images; the right eye sits one baseline along x."""
    env = make_env("multisite")
    try:
        env.reset(seed=2)
        rng = np.random.default_rng(1)
        endoscope = env.unwrapped.config.endoscope
        one = env.unwrapped.render_endoscope(Appearance.sample(rng, endoscope), rng)
        two = env.unwrapped.render_endoscope(Appearance.sample(rng, endoscope), rng)
    finally:
        env.close()
    assert one.left.shape == (endoscope.height, endoscope.width, 3)
    assert np.abs(one.left.astype(float) - two.left.astype(float)).mean() > 3.0
    assert np.abs(one.left.astype(float) - one.right.astype(float)).mean() > 1.0


def test_look_at_is_a_rotation_along_the_view() -> None:
    """The pose's z axis points at the target, y points down in the world, and R is a rotation."""
    pose = look_at(np.array([0.0, 0.1, 0.1]), np.array([0.0, 0.0, 0.0]), 0.05)
    rotation = pose[:3, :3]
    np.testing.assert_allclose(rotation.T @ rotation, np.eye(3), atol=1e-12)
    assert np.linalg.det(rotation) > 0
    np.testing.assert_allclose(rotation[:, 2], np.array([0.0, -1.0, -1.0]) / np.sqrt(2.0), atol=1e-12)
    assert rotation[2, 1] < 0


def test_a_texture_file_shows_on_the_flap_in_its_own_colours() -> None:
    """The blue checker image makes the flap's pixels blue-dominant, which no procedural texture is."""
    image, frame, _ = _left_image(False, str(TEXTURES / "checker-blue.png"))
    tissue = image[frame.labels == CLASSES.index("tissue")]
    assert len(tissue) > 500
    assert tissue[:, 2].mean() > tissue[:, 0].mean() + 20
    procedural, frame, _ = _left_image(False)
    flap = procedural[frame.labels == CLASSES.index("tissue")]
    assert flap[:, 0].mean() > flap[:, 2].mean()
