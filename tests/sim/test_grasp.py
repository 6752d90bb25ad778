"""The grasp holds what the jaws close on: the triangle under them and the tissue within their footprint."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest

from sim.grasp import Grasp, GraspParams, closest_points_on_triangles
from sim.tissue import Tissue, TissueParams, grid_mesh


def test_closest_points_match_a_dense_sampling_of_each_triangle() -> None:
    """Never further than the nearest of 20,000 points sampled on the triangle, and never nearer (it lies on it)."""
    rng = np.random.default_rng(3)
    weights = rng.random((20000, 2))
    flip = weights.sum(axis=1) > 1
    weights[flip] = 1 - weights[flip]
    for _ in range(50):
        a, b, c = (rng.normal(size=(4, 3)) for _ in range(3))
        point = 2 * rng.normal(size=3)
        nearest = closest_points_on_triangles(point, a, b, c)
        for i in range(4):
            samples = a[i] + weights[:, :1] * (b[i] - a[i]) + weights[:, 1:] * (c[i] - a[i])
            sampled = np.linalg.norm(samples - point, axis=1).min()
            found = np.linalg.norm(nearest[i] - point)
            assert found <= sampled + 1e-12
            u, v = np.linalg.lstsq(np.column_stack([b[i] - a[i], c[i] - a[i]]), nearest[i] - a[i], rcond=None)[0]
            assert u >= -1e-9 and v >= -1e-9 and u + v <= 1 + 1e-9  # on the triangle


def _closest_points_numpy(point: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Reference: the same arithmetic on every triangle at once, in NumPy."""
    candidates = []
    for start, end in ((a, b), (b, c), (c, a)):
        span = end - start
        t = np.einsum("ij,ij->i", point - start, span) / np.maximum(np.einsum("ij,ij->i", span, span), 1e-24)
        candidates.append(start + np.clip(t, 0.0, 1.0)[:, None] * span)
    ab, ac, ap = b - a, c - a, point - a
    normal = np.cross(ab, ac)
    normal_sq = np.maximum(np.einsum("ij,ij->i", normal, normal), 1e-24)
    projected = point - (np.einsum("ij,ij->i", ap, normal) / normal_sq)[:, None] * normal
    u = np.einsum("ij,ij->i", np.cross(projected - a, ac), normal) / normal_sq
    v = np.einsum("ij,ij->i", np.cross(ab, projected - a), normal) / normal_sq
    inside = (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0)
    candidates.append(np.where(inside[:, None], projected, np.inf))
    stacked = np.stack(candidates)
    distance = np.linalg.norm(stacked - point, axis=2)
    return np.asarray(stacked[np.argmin(distance, axis=0), np.arange(len(a))])


def test_closest_points_are_the_numpy_formulas_bit_for_bit() -> None:
    """The compiled query returns exactly the points of the vectorised NumPy arithmetic, on flaps and at random."""
    rng = np.random.default_rng(8)
    vertices, triangles = grid_mesh(7, 0.08)
    for trial in range(300):
        if trial % 2:
            a, b, c = (rng.normal(size=(72, 3)) for _ in range(3))
            point = 2 * rng.normal(size=3)
        else:  # a crumpled flap and a grasp point near it
            nodes = vertices + rng.normal(scale=0.01, size=vertices.shape)
            a, b, c = (nodes[triangles[:, k]] for k in range(3))
            point = nodes[rng.integers(len(nodes))] + rng.normal(scale=0.01, size=3)
        np.testing.assert_array_equal(
            closest_points_on_triangles(point, a, b, c), _closest_points_numpy(point, a, b, c)
        )


def _flat_flap() -> tuple[int, Tissue]:
    client = p.connect(p.DIRECT)
    p.resetSimulation(p.RESET_USE_DEFORMABLE_WORLD, physicsClientId=client)
    return client, Tissue(client, TissueParams(), np.zeros(3))


@pytest.mark.parametrize(
    ("height_m", "grasps"),
    [(0.008, True), (0.012, False)],
)
def test_closing_over_a_triangle_grasps_it_when_the_flap_is_within_reach(height_m: float, grasps: bool) -> None:
    """Above a triangle's centre, 8 mm up (every node over 10 mm away) grasps it; 12 mm up grasps nothing."""
    client, tissue = _flat_flap()
    try:
        grasp = Grasp(client, tissue.body_id, tissue.triangles, GraspParams())
        nodes = tissue.positions()
        triangle = tissue.triangles[len(tissue.triangles) // 2]
        point = nodes[triangle].mean(axis=0) + np.array([0.0, 0.0, height_m])
        assert np.linalg.norm(nodes - point, axis=1).min() > GraspParams().radius_m
        events = grasp.update(0.0, point, nodes, 0.0)
        assert events.grasped is grasps and events.improper is not grasps
        if grasps:
            assert set(triangle.tolist()) <= set(grasp.nodes.tolist())
    finally:
        p.disconnect(client)


def test_a_triangle_reaching_into_the_jaws_footprint_is_held() -> None:
    """With a 3 mm footprint, closing 2 mm from a shared edge holds both triangles; 3.5 mm from it, one."""
    client, tissue = _flat_flap()
    try:
        nodes = tissue.positions()
        triangles = tissue.triangles
        pairs = [
            (i, j)
            for i in range(len(triangles))
            for j in range(i + 1, len(triangles))
            if len(set(triangles[i]) & set(triangles[j])) == 2
        ]
        first, second = pairs[len(pairs) // 2]
        shared = sorted(set(triangles[first]) & set(triangles[second]))
        midpoint = nodes[shared].mean(axis=0)
        along = nodes[shared[1]] - nodes[shared[0]]
        along /= np.linalg.norm(along)
        inward = nodes[triangles[first]].mean(axis=0) - midpoint
        inward -= (inward @ along) * along  # perpendicular to the shared edge, into the first triangle
        inward /= np.linalg.norm(inward)
        held = []
        for offset_m in (0.002, 0.0035):
            grasp = Grasp(client, tissue.body_id, triangles, GraspParams(radius_m=0.004, footprint_m=0.003))
            grasp.update(0.0, midpoint + offset_m * inward, nodes, 0.0)
            held.append(set(grasp.nodes.tolist()))
            grasp.release()
        assert set(triangles[second]) <= held[0]
        assert set(triangles[first]) <= held[1] and not set(triangles[second]) <= held[1]
    finally:
        p.disconnect(client)
