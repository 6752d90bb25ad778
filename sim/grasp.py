"""The grasp: soft-body anchors between the tissue inside the jaws and the jaw.

Closing the jaw with the flap's surface within ``radius_m`` of the grasp point (midway along the jaws)
pinches the surface point nearest it. Held from then on, by anchors to a kinematic jaw proxy that follows
the URDF's ``grasp_link`` every substep: every triangle of the mesh reaching within ``footprint_m`` of the
pinched point (the tissue between the jaws), and every node within ``radius_m`` of the grasp point.
Opening releases them. A held triangle moves rigidly with the jaws, and so does every material point in
it: a point the jaws close on, or next to, follows them instead of hanging between held and free nodes
(measured with the shipped Lift policy over 40 episodes: a site outside the held nodes lagged the jaws
by up to 10 mm, which a robot estimating the site from the jaws' motion cannot see).

The proxy exists because anchors attached directly to a link of a kinematically driven multibody drift
and blow up in PyBullet 3.2.7 (measured), whereas anchors to a base-only body whose pose is reset each
substep are stable. Closing with no surface in reach grasps nothing (an improper grasp); a pull beyond
``friction * pinch_force_n`` makes the tissue slip out (grip loss).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np

from psm_control.errors import ConfigurationError
from sim.quiet_pybullet import pybullet as p

__all__ = ["Grasp", "GraspEvents", "GraspParams", "closest_points_on_triangles"]


def closest_points_on_triangles(point: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The point of each triangle (a[i], b[i], c[i]) nearest ``point`` (T, 3) [m].

    Written here rather than taken from a mesh library: it is the one query the grasp needs, on a few
    hundred triangles. The nearest point is the projection on the triangle's plane when that falls inside
    the triangle, else the nearest point of its three edges.
    """
    nearest = np.empty((len(a), 3))
    _closest_points(
        np.ascontiguousarray(point, dtype=np.float64),
        np.ascontiguousarray(a, dtype=np.float64),
        np.ascontiguousarray(b, dtype=np.float64),
        np.ascontiguousarray(c, dtype=np.float64),
        nearest,
    )
    return nearest


# Compiled: a closing jaw asks twice (72 triangles each), and the vectorised NumPy form of the same arithmetic
# cost a twentieth of a step of random actions (measured). tests/sim/test_grasp.py holds that form and checks
# that both give the same points bit for bit.
@numba.njit(cache=True)
def _closest_points(point: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray, nearest: np.ndarray) -> None:
    # Dot products add x, then z, then y: the order of numpy's vectorised einsum on three elements here (measured),
    # so that the points are the ones the NumPy form gave.
    px, py, pz = point[0], point[1], point[2]
    candidates = np.empty((4, 3))
    for i in range(a.shape[0]):
        ax, ay, az, bx, by, bz, cx, cy, cz = (
            a[i, 0],
            a[i, 1],
            a[i, 2],
            b[i, 0],
            b[i, 1],
            b[i, 2],
            c[i, 0],
            c[i, 1],
            c[i, 2],
        )
        for k, (sx, sy, sz, ex, ey, ez) in enumerate(
            ((ax, ay, az, bx, by, bz), (bx, by, bz, cx, cy, cz), (cx, cy, cz, ax, ay, az))
        ):
            dx, dy, dz = ex - sx, ey - sy, ez - sz
            t = ((px - sx) * dx + (pz - sz) * dz + (py - sy) * dy) / max(dx * dx + dz * dz + dy * dy, 1e-24)
            t = min(max(t, 0.0), 1.0)
            candidates[k, 0], candidates[k, 1], candidates[k, 2] = sx + t * dx, sy + t * dy, sz + t * dz
        e1x, e1y, e1z = bx - ax, by - ay, bz - az
        e2x, e2y, e2z = cx - ax, cy - ay, cz - az
        nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
        normal_sq = max(nx * nx + nz * nz + ny * ny, 1e-24)
        s = ((px - ax) * nx + (pz - az) * nz + (py - ay) * ny) / normal_sq
        qx, qy, qz = px - s * nx, py - s * ny, pz - s * nz
        rx, ry, rz = qx - ax, qy - ay, qz - az
        u = ((ry * e2z - rz * e2y) * nx + (rx * e2y - ry * e2x) * nz + (rz * e2x - rx * e2z) * ny) / normal_sq
        v = ((e1y * rz - e1z * ry) * nx + (e1x * ry - e1y * rx) * nz + (e1z * rx - e1x * rz) * ny) / normal_sq
        if u >= 0.0 and v >= 0.0 and u + v <= 1.0:
            candidates[3, 0], candidates[3, 1], candidates[3, 2] = qx, qy, qz
        else:
            candidates[3, 0], candidates[3, 1], candidates[3, 2] = np.inf, np.inf, np.inf
        best, best_distance = 0, np.inf
        for k in range(4):  # the first nearest, a NaN first of all (as numpy's argmin)
            fx, fy, fz = candidates[k, 0] - px, candidates[k, 1] - py, candidates[k, 2] - pz
            distance = math.sqrt(fx * fx + fy * fy + fz * fz)
            if k == 0 or distance < best_distance or (math.isnan(distance) and not math.isnan(best_distance)):
                best, best_distance = k, distance
        nearest[i, 0], nearest[i, 1], nearest[i, 2] = candidates[best, 0], candidates[best, 1], candidates[best, 2]


# Compile (or load from Numba's cache) now, at import, so that no env step waits for the compiler.
closest_points_on_triangles(np.zeros(3), np.zeros((1, 3)), np.eye(3)[:1], np.eye(3)[1:2])


@dataclass(frozen=True)
class GraspParams:
    """Grasp settings.

    Attributes:
        radius_m: The jaw's reach [m]: closing grasps the flap when its surface is this close to the grasp
            point, and holds the nodes this close as well.
        friction: Jaw-tissue friction coefficient.
        pinch_force_n: Jaw pinch force [N]; bowel needs about 3 N of pinch to hold a 5 N pull
            (Heijnsdijk et al. 2004).
        close_below_rad: The jaw counts as closed below this opening angle [rad].
        stall_rad: The angle at which a real jaw closing on the held flap stops [rad]: the jaws grip
            at ``close_below_rad`` and squeeze the thin flap a little further. The kinematic jaw of
            the simulation closes through it; :meth:`measured_jaw` reports what a real jaw would.
        footprint_m: The jaws hold the tissue within this distance of the point they pinch [m]: half
            the jaws' length (10 mm, ``psm_control.spec``), the tissue between the jaws either side of it.
    """

    radius_m: float = 0.010
    friction: float = 0.5
    pinch_force_n: float = 4.0
    close_below_rad: float = 0.15
    stall_rad: float = 0.12
    footprint_m: float = 0.005

    @property
    def capacity_n(self) -> float:
        """Largest pull the grip holds [N]."""
        return self.friction * self.pinch_force_n

    def measured_jaw(self, jaw_rad: float, holding: bool) -> float:
        """The jaw angle a real jaw's encoder reads for a commanded ``jaw_rad`` [rad]: stalled on held tissue."""
        return max(float(jaw_rad), self.stall_rad) if holding else float(jaw_rad)

    def __post_init__(self) -> None:
        for name in ("radius_m", "friction", "pinch_force_n", "close_below_rad", "footprint_m"):
            if not getattr(self, name) > 0:
                raise ConfigurationError(name, getattr(self, name), "a positive number")
        if not 0 <= self.stall_rad < self.close_below_rad:
            raise ConfigurationError("stall_rad", self.stall_rad, f"an angle in [0, {self.close_below_rad:g}) rad")


class GraspEvents(NamedTuple):
    """What changed in one update: a new grasp, an improper grasp, a release or a grip loss."""

    grasped: bool = False
    improper: bool = False
    released: bool = False
    lost: bool = False


class Grasp:
    """The jaw's hold on the tissue in one physics client.

    Args:
        client: PyBullet physics client id.
        tissue_body: The soft body's id.
        triangles: The soft body's surface triangles (T, 3), node indices.
        params: Grasp settings.
    """

    def __init__(self, client: int, tissue_body: int, triangles: np.ndarray, params: GraspParams) -> None:
        self.client = client
        self.tissue_body = tissue_body
        self.triangles = np.asarray(triangles, dtype=int)
        self.params = params
        shape = p.createCollisionShape(p.GEOM_SPHERE, radius=0.001, physicsClientId=client)
        self.proxy = p.createMultiBody(0.0, shape, physicsClientId=client)
        p.setCollisionFilterGroupMask(self.proxy, -1, 0, 0, physicsClientId=client)
        self.nodes = np.zeros(0, dtype=int)
        self._anchors: list[int] = []
        self._armed = True  # a closed jaw must reopen before it can grasp again

    @property
    def holding(self) -> bool:
        """Whether the jaw holds tissue."""
        return len(self.nodes) > 0

    def follow(self, grasp_position: np.ndarray) -> None:
        """Move the jaw proxy to the grasp point (call every substep)."""
        p.resetBasePositionAndOrientation(
            self.proxy, grasp_position.tolist(), [0.0, 0.0, 0.0, 1.0], physicsClientId=self.client
        )

    def update(self, jaw_rad: float, grasp_position: np.ndarray, nodes: np.ndarray, pull_n: float) -> GraspEvents:
        """Grasp, release or slip after a step.

        Args:
            jaw_rad: Measured jaw opening [rad].
            grasp_position: World position of the grasp point [m].
            nodes: Tissue node positions (N, 3) [m].
            pull_n: Magnitude of the force the tissue exerts on the grasp [N].
        """
        closed = jaw_rad < self.params.close_below_rad
        if not closed:
            released = self.holding
            self.release()
            self._armed = True
            return GraspEvents(released=released)
        if self.holding:
            if pull_n > self.params.capacity_n:
                self.release()
                return GraspEvents(lost=True)
            return GraspEvents()
        if not self._armed:
            return GraspEvents()
        self._armed = False
        a, b, c = (nodes[self.triangles[:, k]] for k in range(3))
        surface = closest_points_on_triangles(grasp_position, a, b, c)
        distance = np.linalg.norm(surface - grasp_position, axis=1)
        closed_on = int(np.argmin(distance))
        if not distance[closed_on] < self.params.radius_m:
            return GraspEvents(improper=True)
        pinched = surface[closed_on]
        in_jaws = (
            np.linalg.norm(closest_points_on_triangles(pinched, a, b, c) - pinched, axis=1) <= self.params.footprint_m
        )
        near = np.flatnonzero(np.linalg.norm(nodes - grasp_position, axis=1) < self.params.radius_m)
        reach = np.union1d(self.triangles[in_jaws].ravel(), near)
        self.follow(grasp_position)
        self._anchors = [
            p.createSoftBodyAnchor(self.tissue_body, int(node), self.proxy, -1, physicsClientId=self.client)
            for node in reach
        ]
        self.nodes = reach
        return GraspEvents(grasped=True)

    def release(self) -> None:
        """Let go of every held node."""
        for anchor in self._anchors:
            p.removeConstraint(anchor, physicsClientId=self.client)
        self._anchors = []
        self.nodes = np.zeros(0, dtype=int)
