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
                    with u.scene.arm_in_view() as instrument_id:
                        _, _, _, _, seg = p.getCameraImage(
                            256, 256, view, projection, renderer=p.ER_TINY_RENDERER, physicsClientId=u.client
                        )
                    seg = np.reshape(np.asarray(seg), (256, 256))
                    pixels = _project(u._exposure_points, u.client, view, projection, 256, 256)
                    rendered = seg[pixels[:, 0], pixels[:, 1]] == u.scene.hidden_id
                    rays = exposed_mask(u._exposure_points, u._eye, u._nodes, u.scene.tissue.triangles)
                    instrument = seg[pixels[:, 0], pixels[:, 1]] == instrument_id
                    keep = ~instrument
                    agreements.append(np.mean(rendered[keep] == rays[keep]))
                    fractions.append(rays.mean())
                    assert set(np.unique(frame.labels)) <= set(range(len(CLASSES)))
        assert np.mean(agreements) > 0.9
        assert min(fractions) < 0.3 < max(fractions)  # both covered and exposed states were checked
    finally:
        env.close()


def _every_pair(points: np.ndarray, eye: np.ndarray, nodes: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Reference: the same segment-triangle test on every (point, triangle) pair at once, in NumPy."""
    a = nodes[triangles[:, 0]]
    e1, e2 = nodes[triangles[:, 1]] - a, nodes[triangles[:, 2]] - a
    d = (eye - points)[:, None, :]  # (P, 1, 3)
    s = points[:, None, :] - a[None]  # (P, T, 3)
    pv, qv = np.cross(d, e2[None]), np.cross(s, e1[None])
    det = np.sum(e1[None] * pv, axis=2)
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = np.where(np.abs(det) < 1e-12, np.nan, 1.0 / det)
        u = np.sum(s * pv, axis=2) * inverse
        v = np.sum(d * qv, axis=2) * inverse
        t = np.sum(e2[None] * qv, axis=2) * inverse
        hit = (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-6) & (t < 1)
    return ~hit.any(axis=1)


def test_the_compiled_test_agrees_with_every_pair_tested_at_once() -> None:
    """Flaps crumpled at random over the samples, with NaN nodes too: the same points are exposed."""
    rng = np.random.default_rng(5)
    env = make_env("expose")
    try:
        env.reset(seed=0)
        u = env.unwrapped
        points, eye, triangles = u._exposure_points, u._eye, np.asarray(u.scene.tissue.triangles)
        spread = np.ptp(points, axis=0) + 0.01
        checked = 0
        for trial in range(200):
            nodes = u._nodes + rng.normal(0.0, 1.0, u._nodes.shape) * spread * (trial % 4) / 4
            if trial % 10 == 9:
                nodes[rng.integers(len(nodes))] = np.nan
            expected = _every_pair(points, eye, nodes, triangles)
            np.testing.assert_array_equal(exposed_mask(points, eye, nodes, triangles), expected)
            checked += int(expected.sum()) * int((~expected).sum()) > 0  # both kinds of point present
        assert checked > 50
    finally:
        env.close()
