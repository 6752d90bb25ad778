"""The flap's mesh bookkeeping: springs from its triangles, and material points bound to a triangle."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pybullet as p
import pytest

from sim.tissue import Tissue, TissueParams, grid_mesh


@pytest.fixture
def client() -> Iterator[int]:
    """A deformable-world physics client, disconnected after the test."""
    client = p.connect(p.DIRECT)
    p.resetSimulation(p.RESET_USE_DEFORMABLE_WORLD, physicsClientId=client)
    yield client
    p.disconnect(client)


def _first_triangle_loop(rest: np.ndarray, triangles: np.ndarray, point: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reference: one 2 x 2 solve per triangle, in order, until one holds the point."""
    for triangle in triangles:
        a, b, c = rest[triangle, :2]
        u, v = np.linalg.solve(np.column_stack([b - a, c - a]), point[:2] - a)
        if u >= -1e-9 and v >= -1e-9 and u + v <= 1 + 1e-9:
            return triangle, np.array([1.0 - u - v, u, v])
    raise AssertionError("no triangle holds the point")


@pytest.mark.parametrize("resolution", [4, 7, 10])
def test_springs_are_the_triangles_edges(client: int, resolution: int) -> None:
    """The flap's springs are each edge of its triangles once, as sorted node pairs; two flaps share none."""
    tissue = Tissue(client, TissueParams(resolution=resolution, size_m=0.07), np.zeros(3))
    _, triangles = grid_mesh(resolution, 0.07)
    pairs = {tuple(sorted((int(t[i]), int(t[(i + 1) % 3])))) for t in triangles for i in range(3)}
    assert sorted(pairs) == [tuple(edge) for edge in tissue.edges.tolist()]
    np.testing.assert_array_equal(tissue.triangles, triangles)
    tissue.edges[0, 0] = -1  # a flap's arrays are its own
    assert Tissue(client, TissueParams(resolution=resolution), np.zeros(3)).edges[0, 0] != -1


def test_a_site_is_bound_to_the_first_triangle_holding_it(client: int) -> None:
    """The binding is the per-triangle search's triangle and weights, bit for bit, and its weights give the point."""
    rng = np.random.default_rng(2)
    for _ in range(20):
        size = rng.uniform(0.07, 0.09)
        origin = rng.uniform(-0.01, 0.01, 3)
        tissue = Tissue(client, TissueParams(size_m=size), origin)
        rest = tissue.rest_positions - origin
        for point in rng.uniform(-size / 2, size / 2, (10, 3)) * [1.0, 1.0, 0.0]:
            triangle, weights = tissue.site_binding(point)
            expected_triangle, expected_weights = _first_triangle_loop(rest, tissue.triangles, point)
            np.testing.assert_array_equal(triangle, expected_triangle)
            np.testing.assert_array_equal(weights, expected_weights)
            np.testing.assert_allclose(weights @ rest[triangle], point, atol=1e-12)


def test_temporary_mesh_folders_of_ended_processes_do_not_accumulate(tmp_path: Path) -> None:
    """A process killed before its exit handlers leaves its folder; the next process to make one removes it."""
    script = "import os, sim.tissue as t; print(os.path.dirname(t.texture_file(1)), flush=True); os._exit(0)"
    env = dict(os.environ, TMPDIR=str(tmp_path))

    def folder_of_a_killed_process() -> Path:
        done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
        return Path(done.stdout.strip().splitlines()[-1])

    first = folder_of_a_killed_process()
    assert first.is_dir() and first.parent == tmp_path
    second = folder_of_a_killed_process()
    assert not first.exists() and second.is_dir()
    assert [path.name for path in tmp_path.iterdir()] == [second.name]
