"""The flap's procedural texture: seeded, visible in the render, and without effect on the physics."""

from __future__ import annotations

from typing import Any

import numpy as np

from sim.randomization import Randomizer
from sim.rendering import CLASSES
from sim.tissue import texture_image
from tests.sim.conftest import make_env

_TISSUE = CLASSES.index("tissue")
_FLAT = {"tissue_color_r": 0.85, "tissue_color_g": 0.42, "tissue_color_b": 0.42}


def _tissue_pixels(env: Any, seed: int, texture_seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The rendered flap's pixels (and its mask) right after a reset."""
    env.reset(seed=seed, options={**_FLAT, "tissue_texture_seed": texture_seed})
    frame = env.unwrapped.render_frame()
    mask = frame.labels == _TISSUE
    return frame.rgb.astype(float), mask


def test_texture_is_rendered_seeded_and_physics_free() -> None:
    env = make_env("lift", render_mode="rgb_array")
    try:
        rgb_a, mask_a = _tissue_pixels(env, 3, 11)
        nodes_a = env.unwrapped.scene.tissue.positions()
        rgb_a2, _ = _tissue_pixels(env, 3, 11)
        rgb_b, mask_b = _tissue_pixels(env, 3, 12)
        nodes_b = env.unwrapped.scene.tissue.positions()
    finally:
        env.close()
    assert mask_a.sum() > 500
    # The flap is not a flat colour: with the colour fixed, its pixels vary by the texture.
    assert rgb_a[mask_a].std(axis=0).max() > 8.0
    # Same texture, same pixels; another texture, other pixels, on the same flap in the same place.
    np.testing.assert_array_equal(rgb_a, rgb_a2)
    np.testing.assert_array_equal(mask_a, mask_b)
    np.testing.assert_array_equal(nodes_a, nodes_b)
    assert np.abs(rgb_a[mask_a] - rgb_b[mask_b]).mean() > 4.0


def test_texture_images_are_seeded() -> None:
    a, b = texture_image(5), texture_image(6)
    np.testing.assert_array_equal(a, texture_image(5))
    assert a.shape == (64, 64, 3) and a.dtype == np.uint8
    assert np.abs(a.astype(int) - b.astype(int)).mean() > 5.0


def test_texture_seed_does_not_shift_the_other_draws() -> None:
    """The render-only parameter has a stream of its own: the physical draws stay as before."""
    with_texture = Randomizer().sample(np.random.default_rng(7))
    without = Randomizer()
    del without.ranges["tissue_texture_seed"]
    plain = without.sample(np.random.default_rng(7))
    assert {k: v for k, v in with_texture.items() if k != "tissue_texture_seed"} == plain
    seeds = {Randomizer().sample(np.random.default_rng(s))["tissue_texture_seed"] for s in range(20)}
    assert len(seeds) > 15 and all(float(s).is_integer() for s in seeds)
