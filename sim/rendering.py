"""Camera images of the scene: RGB, depth in metres and a segmentation by class.

The camera plays the endoscope: in front of the free edge, above the flap, looking at the hidden
tissue. Rendering uses PyBullet's CPU renderer, so it works headless.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from sim.quiet_pybullet import pybullet as p

__all__ = ["CLASSES", "Camera", "Frame", "render"]

#: Segmentation classes, by label value.
CLASSES = ("background", "tissue", "hidden_tissue", "instrument")


@dataclass(frozen=True)
class Camera:
    """A pinhole camera placed relative to the flap's centre.

    Attributes:
        eye_offset_m: Eye position relative to the flap centre [m].
        target_offset_m: Point looked at, relative to the flap centre [m].
        fov_deg: Vertical field of view [deg].
        width: Image width [px].
        height: Image height [px].
        near_m: Near clipping plane [m].
        far_m: Far clipping plane [m].
    """

    eye_offset_m: tuple[float, float, float] = (0.0, 0.12, 0.16)
    target_offset_m: tuple[float, float, float] = (0.0, 0.005, 0.0)
    fov_deg: float = 45.0
    width: int = 128
    height: int = 128
    near_m: float = 0.02
    far_m: float = 1.0

    def eye(self, centre: np.ndarray) -> np.ndarray:
        """World position of the eye [m]."""
        return np.asarray(centre, dtype=float) + np.array(self.eye_offset_m)

    def matrices(self, centre: np.ndarray, client: int) -> tuple[list[float], list[float]]:
        """PyBullet view and projection matrices."""
        target = np.asarray(centre, dtype=float) + np.array(self.target_offset_m)
        view = p.computeViewMatrix(self.eye(centre).tolist(), target.tolist(), [0, 0, 1], physicsClientId=client)
        projection = p.computeProjectionMatrixFOV(
            self.fov_deg, self.width / self.height, self.near_m, self.far_m, physicsClientId=client
        )
        return list(view), list(projection)


class Frame(NamedTuple):
    """One rendered frame.

    Attributes:
        rgb: (H, W, 3) uint8.
        depth_m: (H, W) distance along the optical axis [m].
        labels: (H, W) uint8 class labels, indices into :data:`CLASSES`.
    """

    rgb: np.ndarray
    depth_m: np.ndarray
    labels: np.ndarray


def render(client: int, camera: Camera, centre: np.ndarray, bodies: dict[str, int]) -> Frame:
    """Render the scene; ``bodies`` maps class names to the body ids that belong to them."""
    view, projection = camera.matrices(centre, client)
    _, _, rgba, depth, segmentation = p.getCameraImage(
        camera.width, camera.height, view, projection, renderer=p.ER_TINY_RENDERER, physicsClientId=client
    )
    rgb = np.reshape(np.asarray(rgba, dtype=np.uint8), (camera.height, camera.width, 4))[:, :, :3]
    buffer = np.reshape(np.asarray(depth, dtype=float), (camera.height, camera.width))
    near, far = camera.near_m, camera.far_m
    depth_m = far * near / (far - (far - near) * buffer)
    ids = np.reshape(np.asarray(segmentation, dtype=np.int64), (camera.height, camera.width))
    objects = np.where(ids >= 0, ids & ((1 << 24) - 1), -1)
    labels = np.zeros(ids.shape, dtype=np.uint8)
    for name, body in bodies.items():
        labels[objects == body] = CLASSES.index(name)
    return Frame(rgb, depth_m, labels)
