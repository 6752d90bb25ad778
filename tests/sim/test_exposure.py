"""Exposure by ray tests agrees with what the camera renders."""

from __future__ import annotations

import numpy as np
import pybullet as p

from sim.expert import ScriptedExpert
from sim.exposure import exposed_mask
from sim.rendering import CLASSES
from tests.sim.conftest import make_env


def _project(points: np.ndarray, client: int, view: list[float], projection: list[float], w: int, h: int) -> np.ndarray:
    V = np.reshape(view, (4, 4)).T
    P = np.reshape(projection, (4, 4)).T
    clip = (P @ V @ np.c_[points, np.ones(len(points))].T).T
    ndc = clip[:, :3] / clip[:, 3:4]
    cols = np.clip(((ndc[:, 0] + 1) / 2 * w).astype(int), 0, w - 1)
    rows = np.clip(((1 - ndc[:, 1]) / 2 * h).astype(int), 0, h - 1)
    return np.stack([rows, cols], axis=1)


def test_ray_exposure_matches_segmentation() -> None:
    """Sample points the ray test calls exposed are rendered as hidden tissue, and the rest are not."""
    env = make_env("expose")
    try:
        u = env.unwrapped
        expert = ScriptedExpert(env)
        agreements, fractions = [], []
        for seed in range(3):
            obs, _ = env.reset(seed=seed, options={"observation_noise_m": 0.0})
            expert.reset()
            for step in range(40):
                obs, *_ = env.step(expert(obs))
                if step % 10 == 9:
                    camera = u.config.camera.__class__(**{**u.config.camera.__dict__, "width": 256, "height": 256})
                    view, projection = camera.matrices(u.scene.tissue_origin, u.client)
                    frame = u.render_frame()
                    _, _, _, _, seg = p.getCameraImage(
                        256, 256, view, projection, renderer=p.ER_TINY_RENDERER, physicsClientId=u.client
                    )
                    seg = np.reshape(np.asarray(seg), (256, 256))
                    pixels = _project(u._exposure_points, u.client, view, projection, 256, 256)
                    rendered = seg[pixels[:, 0], pixels[:, 1]] == u.scene.hidden_id
                    rays = exposed_mask(u._exposure_points, u._eye, u._nodes, u.scene.tissue.triangles)
                    instrument = seg[pixels[:, 0], pixels[:, 1]] == u.scene.body.body_id
                    keep = ~instrument
                    agreements.append(np.mean(rendered[keep] == rays[keep]))
                    fractions.append(rays.mean())
                    assert set(np.unique(frame.labels)) <= set(range(len(CLASSES)))
        assert np.mean(agreements) > 0.9
        assert min(fractions) < 0.3 < max(fractions)  # both covered and exposed states were checked
    finally:
        env.close()
