"""The 3-D scene in Foxglove's schemas: the arm's frames agree with PyBullet's kinematics, shapes match the URDF."""

from __future__ import annotations

from typing import Any

import numpy as np
import pybullet as p
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from psm_control.robot import PsmModel
from sim.psm_body import PsmBody
from sim.scene3d import COMMANDED_PREFIX, FORCE_ARROW_M_PER_N, RCM_FRAME, PsmScene, link_shapes


def decode(message: Any) -> Any:
    """A Foxglove SDK message read back through its own protobuf schema, as Foxglove reads it."""
    schema = message.get_schema()
    files = descriptor_pb2.FileDescriptorSet.FromString(bytes(schema.data))
    pool = descriptor_pool.DescriptorPool()
    for file in files.file:
        pool.Add(file)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
    return cls.FromString(bytes(message.encode()))


def _matrix(translation: Any, rotation: Any) -> np.ndarray:
    x, y, z, w = rotation.x, rotation.y, rotation.z, rotation.w
    transform = np.eye(4)
    transform[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    transform[:3, 3] = [translation.x, translation.y, translation.z]
    return transform


def test_link_frames_agree_with_pybullet_at_random_joints() -> None:
    """Decoded frame transforms equal PyBullet's link poses (an independent FK) at 20 random configurations."""
    model = PsmModel.from_variant("classic")
    base = np.eye(4)
    base[:3, 3] = [0.01, -0.02, 0.15]
    scene = PsmScene(model, "PSM1_base", base_frame=base)
    client = p.connect(p.DIRECT)
    try:
        body = PsmBody(client, model, rcm_position=base[:3, 3])
        rng = np.random.default_rng(7)
        for _ in range(20):
            q = rng.uniform(model.lower, model.upper)
            jaw = float(rng.uniform(0.0, 1.0))
            body.reset_joints(q, jaw)
            message = decode(scene.transforms(2.5, q, jaw, prefix=COMMANDED_PREFIX))
            frames = {t.child_frame_id: t for t in message.transforms}
            assert set(frames) == {RCM_FRAME} | {COMMANDED_PREFIX + link for link in scene.links}
            rcm = frames.pop(RCM_FRAME)
            assert rcm.parent_frame_id == "PSM1_base"
            np.testing.assert_allclose(_matrix(rcm.translation, rcm.rotation), base, atol=1e-12)
            for name, t in frames.items():
                assert t.parent_frame_id == RCM_FRAME
                assert (t.timestamp.seconds, t.timestamp.nanos) == (2, 500_000_000)
                link = name.removeprefix(COMMANDED_PREFIX)
                world = base @ _matrix(t.translation, t.rotation)
                np.testing.assert_allclose(world, body.link_pose(link), atol=1e-6)
            np.testing.assert_allclose(scene.grasp_point(q, jaw), body.link_pose("grasp_link")[:3, 3], atol=1e-6)
    finally:
        p.disconnect(client)


def test_shapes_are_the_urdf_visuals() -> None:
    """The shaft, wrist and both jaws are drawn with the URDF's own primitives and sizes."""
    model = PsmModel.from_variant("classic")
    shapes = link_shapes(model.urdf_path.read_text(encoding="utf-8"))
    kinds = {(s.link, s.kind) for s in shapes}
    assert ("insertion_link", "cylinder") in kinds and ("jaw_left_link", "box") in kinds
    shaft = next(s for s in shapes if s.link == "insertion_link" and s.kind == "cylinder")
    assert shaft.size[2] == model.spec.joints[3].d  # the shaft runs the instrument's length
    update = decode(PsmScene(model, "PSM1_base").arm(0.0, prefix=COMMANDED_PREFIX))
    assert all(e.frame_locked and e.frame_id.startswith(COMMANDED_PREFIX) for e in update.entities)
    assert sum(len(e.cubes) + len(e.cylinders) for e in update.entities) == len(shapes)
    assert all(c.color.b == 1.0 for e in update.entities for c in e.cubes)  # the commanded arm's colour


def test_tissue_markers_and_force_arrow() -> None:
    """The flap is its triangles, site and goal are spheres, the arrow points along the force, scaled by it."""
    scene = PsmScene(PsmModel.from_variant("classic"), "PSM1_base")
    nodes = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]])
    update = decode(
        scene.task(
            1.0,
            nodes=nodes,
            triangles=np.array([[0, 1, 2]]),
            site=np.array([0.0, 0.01, 0.0]),
            goal=np.array([0.0, 0.01, 0.02]),
            grasp=np.array([0.0, 0.01, 0.0]),
            force_n=np.array([0.0, -0.3, 0.4]),
        )
    )
    entities = {e.id: e for e in update.entities}
    assert set(entities) == {"tissue", "site", "goal", "force"}
    assert list(entities["tissue"].triangles[0].indices) == [0, 1, 2]
    assert entities["goal"].spheres[0].pose.position.z == 0.02
    arrow = entities["force"].arrows[0]
    np.testing.assert_allclose(arrow.shaft_length + arrow.head_length, FORCE_ARROW_M_PER_N * 0.5)
    along = _matrix(arrow.pose.position, arrow.pose.orientation)[:3, 0]
    np.testing.assert_allclose(along, [0.0, -0.6, 0.8], atol=1e-9)
