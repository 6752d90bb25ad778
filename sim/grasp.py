"""The grasp: soft-body anchors between the tissue nodes inside the jaws and the jaw.

Closing the jaw near the tissue anchors every node within ``radius_m`` of the grasp point (midway
along the jaws), and the patch of the ``patch_nodes`` nodes nearest to it (within ``patch_radius_m``),
to a kinematic jaw proxy that follows the URDF's ``grasp_link`` every substep; opening
releases them. The proxy exists because anchors attached directly to a link of a kinematically driven
multibody drift and blow up in PyBullet 3.2.7 (measured), whereas anchors to a base-only body whose
pose is reset each substep are stable. Closing with no node in reach grasps nothing (an improper grasp);
a pull beyond ``friction * pinch_force_n`` makes the tissue slip out (grip loss).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pybullet as p

from psm_control.errors import ConfigurationError

__all__ = ["Grasp", "GraspEvents", "GraspParams"]


@dataclass(frozen=True)
class GraspParams:
    """Grasp settings.

    Attributes:
        radius_m: Nodes within this distance of the grasp point are held when the jaw closes [m].
        friction: Jaw-tissue friction coefficient.
        pinch_force_n: Jaw pinch force [N]; bowel needs about 3 N of pinch to hold a 5 N pull
            (Heijnsdijk et al. 2004).
        close_below_rad: The jaw counts as closed below this opening angle [rad].
        patch_nodes: The jaws hold a patch of tissue, not a node: the this many nodes nearest the grasp
            point (a triangle of the flap's mesh) are held with those within ``radius_m``, so the
            tissue between them moves with the jaws. With one held node the rest of the triangle
            sagged, and a point of it lagged the jaws by 5-17 mm in a lift (measured).
        patch_radius_m: Patch nodes further than this from the grasp point are not held [m].
        stall_rad: The angle at which a real jaw closing on the held flap stops [rad]: the jaws grip
            at ``close_below_rad`` and squeeze the thin flap a little further. The kinematic jaw of
            the simulation closes through it; :meth:`measured_jaw` reports what a real jaw would.
    """

    radius_m: float = 0.010
    friction: float = 0.5
    pinch_force_n: float = 4.0
    close_below_rad: float = 0.15
    patch_nodes: int = 3
    patch_radius_m: float = 0.015
    stall_rad: float = 0.12

    @property
    def capacity_n(self) -> float:
        """Largest pull the grip holds [N]."""
        return self.friction * self.pinch_force_n

    def measured_jaw(self, jaw_rad: float, holding: bool) -> float:
        """The jaw angle a real jaw's encoder reads for a commanded ``jaw_rad`` [rad]: stalled on held tissue."""
        return max(float(jaw_rad), self.stall_rad) if holding else float(jaw_rad)

    def __post_init__(self) -> None:
        for name in ("radius_m", "friction", "pinch_force_n", "close_below_rad"):
            if not getattr(self, name) > 0:
                raise ConfigurationError(name, getattr(self, name), "a positive number")
        if self.patch_nodes < 0 or not self.patch_radius_m >= 0:
            raise ConfigurationError("patch_nodes", self.patch_nodes, "a node count >= 0 and a radius >= 0")
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
        params: Grasp settings.
    """

    def __init__(self, client: int, tissue_body: int, params: GraspParams) -> None:
        self.client = client
        self.tissue_body = tissue_body
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
        distance = np.linalg.norm(nodes - grasp_position, axis=1)
        reach = np.flatnonzero(distance < self.params.radius_m)
        if len(reach) == 0:
            return GraspEvents(improper=True)
        nearest = np.argsort(distance)[: self.params.patch_nodes]
        reach = np.union1d(reach, nearest[distance[nearest] < self.params.patch_radius_m])
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
