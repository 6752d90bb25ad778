"""A run as a 3-D scene in Foxglove's own schemas: the arm, the commanded pose, the tissue, the force.

Frames: the RCM is the frame ``rcm`` under the scene's root frame (the arm's ``<arm>_base``, or the
simulation's ``world``), and every URDF link with a shape is a frame ``<prefix><link>`` under ``rcm``,
placed by the Pinocchio kinematics at the given joints, so Foxglove draws the arm as it was; a second
prefix (``commanded/``) draws where the chain sent it, in another colour. The link
shapes are the URDF's own primitives (cylinders and boxes), parsed from the file the models load. The
tissue flap is a triangle list of its nodes; the grasp site and goal are spheres, the force on the grasp
an arrow whose length is proportional to the force.

Messages are ``foxglove.messages`` objects: a recorder writes their protobuf encoding to MCAP, a live
server logs them to the Foxglove app.
"""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from foxglove.messages import (
    ArrowPrimitive,
    Color,
    CubePrimitive,
    CylinderPrimitive,
    FrameTransform,
    FrameTransforms,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    SpherePrimitive,
    Timestamp,
    TriangleListPrimitive,
    Vector3,
)

from psm_control.robot import PsmModel
from psm_control.urdf import GRASP_FRAME

__all__ = [
    "COMMANDED_PREFIX",
    "FORCE_ARROW_M_PER_N",
    "RCM_FRAME",
    "LinkShape",
    "PsmScene",
    "link_shapes",
    "pose_message",
    "timestamp",
]

#: Frame prefix of the arm drawn where the chain commanded it.
COMMANDED_PREFIX = "commanded/"
#: The remote centre of motion's frame, the parent of the links' frames.
RCM_FRAME = "rcm"
#: Length of the force arrow per newton [m/N]: 1 N draws 2 cm, on the scale of the flap.
FORCE_ARROW_M_PER_N = 0.02
_COMMANDED_RGBA = (0.2, 0.6, 1.0, 0.45)
_TISSUE_RGBA = (0.85, 0.42, 0.42, 0.9)


@dataclass(frozen=True)
class LinkShape:
    """One URDF visual: a primitive in its link's frame.

    Attributes:
        link: The link's name.
        kind: ``cylinder`` or ``box``.
        size: Box extents, or the cylinder's (diameter, diameter, length) [m].
        pose: 4x4 pose of the primitive's centre in the link frame.
        rgba: Colour.
    """

    link: str
    kind: str
    size: tuple[float, float, float]
    pose: np.ndarray
    rgba: tuple[float, float, float, float]


def _rotation_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def link_shapes(urdf_text: str) -> list[LinkShape]:
    """The visual primitives of every link of a URDF (cylinders and boxes; other shapes are skipped)."""
    shapes = []
    for link in ElementTree.fromstring(urdf_text).iter("link"):
        for visual in link.iter("visual"):
            origin = visual.find("origin")
            pose = np.eye(4)
            if origin is not None:
                pose[:3, 3] = [float(v) for v in origin.get("xyz", "0 0 0").split()]
                pose[:3, :3] = _rotation_rpy(*(float(v) for v in origin.get("rpy", "0 0 0").split()))
            colour = visual.find("material/color")
            rgba = (0.7, 0.7, 0.7, 1.0)
            if colour is not None:
                r, g, b, a = (float(v) for v in colour.get("rgba", "0.7 0.7 0.7 1").split())
                rgba = (r, g, b, a)
            cylinder, box = visual.find("geometry/cylinder"), visual.find("geometry/box")
            if cylinder is not None:
                diameter, length = 2.0 * float(cylinder.get("radius", 0)), float(cylinder.get("length", 0))
                shapes.append(LinkShape(link.get("name", ""), "cylinder", (diameter, diameter, length), pose, rgba))
            elif box is not None:
                x, y, z = (float(v) for v in box.get("size", "0 0 0").split())
                shapes.append(LinkShape(link.get("name", ""), "box", (x, y, z), pose, rgba))
    return shapes


def timestamp(t_s: float) -> Timestamp:
    """A Foxglove timestamp from seconds."""
    sec, nsec = divmod(round(t_s * 1e9), 1_000_000_000)
    return Timestamp(sec, nsec)


def _quaternion(rotation: np.ndarray) -> Quaternion:
    """xyzw quaternion of a rotation matrix (Shepperd's method, robust near 180 degrees)."""
    m = rotation
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * np.sqrt(trace + 1.0)
        w, x, y, z = 0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        w, x, y, z = (m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        w, x, y, z = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        w, x, y, z = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s
    return Quaternion(x=float(x), y=float(y), z=float(z), w=float(w))


def pose_message(transform: np.ndarray) -> Pose:
    """A Foxglove pose from a 4x4 homogeneous transform."""
    x, y, z = (float(v) for v in transform[:3, 3])
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=_quaternion(transform[:3, :3]))


def _color(rgba: Sequence[float]) -> Color:
    return Color(r=float(rgba[0]), g=float(rgba[1]), b=float(rgba[2]), a=float(rgba[3]))


def _along(direction: np.ndarray) -> Quaternion:
    """The rotation taking +x to ``direction`` (an arrow primitive points along its pose's +x)."""
    unit = direction / np.linalg.norm(direction)
    axis = np.cross([1.0, 0.0, 0.0], unit)
    sine, cosine = np.linalg.norm(axis), float(unit[0])
    if sine < 1e-12:
        return Quaternion(x=0.0, y=0.0, z=1.0, w=0.0) if cosine < 0 else Quaternion(w=1.0)
    half = np.arctan2(sine, cosine) / 2.0
    x, y, z = axis / sine * np.sin(half)
    return Quaternion(x=float(x), y=float(y), z=float(z), w=float(np.cos(half)))


class PsmScene:
    """Builds the scene's messages for one arm.

    Args:
        model: The PSM model (its URDF gives the link shapes).
        root_frame: The frame everything is placed in, e.g. ``PSM1_base``.
        base_frame: 4x4 pose of the RCM in the root frame (the dVRK's base frame transform).
    """

    def __init__(self, model: PsmModel, root_frame: str, base_frame: np.ndarray | None = None) -> None:
        self.model = model
        self.root_frame = root_frame
        self.base_frame = np.eye(4) if base_frame is None else np.asarray(base_frame, dtype=float)
        self.shapes = link_shapes(model.urdf_path.read_text(encoding="utf-8"))
        self.links = tuple(dict.fromkeys(shape.link for shape in self.shapes))
        self._configuration = model.configuration()

    def link_poses(self, q: np.ndarray, jaw: float = 0.0) -> dict[str, np.ndarray]:
        """4x4 pose of every link with a shape about the RCM, at joints ``q`` and jaw angle ``jaw``."""
        self._configuration.update(q, jaw)
        return {link: self._configuration.frame_pose_local(link) for link in self.links}

    def grasp_point(self, q: np.ndarray, jaw: float = 0.0) -> np.ndarray:
        """Where the jaws hold, in the root frame [m]."""
        self._configuration.update(q, jaw)
        return (self.base_frame @ self._configuration.frame_pose_local(GRASP_FRAME))[:3, 3]

    def transforms(self, t_s: float, q: np.ndarray, jaw: float = 0.0, prefix: str = "") -> FrameTransforms:
        """The RCM's frame and the links' frames at ``q`` (under ``prefix``), as Foxglove frame transforms."""
        stamp = timestamp(t_s)

        def transform(parent: str, child: str, pose: np.ndarray) -> FrameTransform:
            x, y, z = (float(v) for v in pose[:3, 3])
            return FrameTransform(
                timestamp=stamp,
                parent_frame_id=parent,
                child_frame_id=child,
                translation=Vector3(x=x, y=y, z=z),
                rotation=_quaternion(pose[:3, :3]),
            )

        links = [transform(RCM_FRAME, prefix + link, pose) for link, pose in self.link_poses(q, jaw).items()]
        return FrameTransforms(transforms=[transform(self.root_frame, RCM_FRAME, self.base_frame), *links])

    def arm(self, t_s: float, prefix: str = "") -> SceneUpdate:
        """The link shapes, locked to their frames; the ``commanded/`` arm is translucent blue."""
        stamp = timestamp(t_s)
        entities = []
        for link in self.links:
            cubes, cylinders = [], []
            for shape in (s for s in self.shapes if s.link == link):
                rgba = _COMMANDED_RGBA if prefix == COMMANDED_PREFIX else shape.rgba
                size = Vector3(x=shape.size[0], y=shape.size[1], z=shape.size[2])
                pose = pose_message(shape.pose)
                if shape.kind == "box":
                    cubes.append(CubePrimitive(pose=pose, size=size, color=_color(rgba)))
                else:
                    cylinders.append(
                        CylinderPrimitive(pose=pose, size=size, bottom_scale=1.0, top_scale=1.0, color=_color(rgba))
                    )
            entities.append(
                SceneEntity(
                    timestamp=stamp,
                    frame_id=prefix + link,
                    id=f"{prefix}{link}",
                    frame_locked=True,
                    cubes=cubes,
                    cylinders=cylinders,
                )
            )
        return SceneUpdate(entities=entities)

    def task(
        self,
        t_s: float,
        *,
        nodes: np.ndarray | None = None,
        triangles: np.ndarray | None = None,
        site: np.ndarray | None = None,
        goal: np.ndarray | None = None,
        grasp: np.ndarray | None = None,
        force_n: np.ndarray | None = None,
    ) -> SceneUpdate:
        """The tissue and the task markers, all in the root frame [m]; what is None is left out.

        Args:
            t_s: Time [s].
            nodes: Tissue node positions (N, 3).
            triangles: The flap's triangles (T, 3) of node indices.
            site: The grasp site.
            goal: The goal of the retraction.
            grasp: Where the jaws hold (the arrow's tail).
            force_n: Force the tissue exerts on the grasp (3,) [N].
        """
        stamp = timestamp(t_s)
        entities = []
        if nodes is not None and triangles is not None:
            points = [Point3(x=float(x), y=float(y), z=float(z)) for x, y, z in np.asarray(nodes)]
            flap = TriangleListPrimitive(
                pose=pose_message(np.eye(4)),
                points=points,
                color=_color(_TISSUE_RGBA),
                indices=[int(i) for i in np.asarray(triangles).ravel()],
            )
            entities.append(SceneEntity(timestamp=stamp, frame_id=self.root_frame, id="tissue", triangles=[flap]))
        for name, point, rgba in (("site", site, (1.0, 0.85, 0.1, 1.0)), ("goal", goal, (0.1, 0.8, 0.2, 1.0))):
            if point is not None:
                marker = np.eye(4)
                marker[:3, 3] = point
                sphere = SpherePrimitive(
                    pose=pose_message(marker), size=Vector3(x=0.004, y=0.004, z=0.004), color=_color(rgba)
                )
                entities.append(SceneEntity(timestamp=stamp, frame_id=self.root_frame, id=name, spheres=[sphere]))
        if grasp is not None and force_n is not None and np.linalg.norm(force_n) > 1e-6:
            length = FORCE_ARROW_M_PER_N * float(np.linalg.norm(force_n))
            position = np.asarray(grasp, dtype=float)
            arrow = ArrowPrimitive(
                pose=Pose(
                    position=Vector3(x=float(position[0]), y=float(position[1]), z=float(position[2])),
                    orientation=_along(np.asarray(force_n, dtype=float)),
                ),
                shaft_length=0.8 * length,
                shaft_diameter=0.0015,
                head_length=0.2 * length,
                head_diameter=0.004,
                color=_color((1.0, 0.2, 0.1, 1.0)),
            )
            entities.append(SceneEntity(timestamp=stamp, frame_id=self.root_frame, id="force", arrows=[arrow]))
        return SceneUpdate(entities=entities)
