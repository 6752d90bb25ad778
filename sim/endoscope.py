"""The stereo endoscope: where a dVRK's endoscope looks from, and randomized images of what it sees.

The endoscope is fixed in the world (as the dVRK's ECM is, on its own setup joint), not on the flap:
the flap's placement, size and sag are what the images must reveal. It looks at the flap from in front
of its free edge and above, 12 cm from the flap's nominal centre, down at 48 degrees, through the
port side the PSM does not use. Two pinhole eyes 5 mm apart (the order of a 12 mm stereo endoscope's
interocular distance) see 128 x 96 px each over a 50 degree vertical field: a 640 x 480 SD eye
(the Classic dVRK's video) reduced five times, about 1.2 mm per pixel on the flap.

What a frame randomizes (:class:`Appearance`, drawn by :meth:`Appearance.sample` from its own
generator), on top of the flap's colour and texture: the light's direction (about the scope's axis,
since an endoscope carries its light), colour, ambient, diffuse and specular strength; the eye's pose
(a few mm and degrees: the ECM's pose is read from its kinematics, so the frame carries the pose it was
taken from); lens blur and sensor noise.

Camera frames use the OpenCV convention: x right, y down, z along the optical axis.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from sim.quiet_pybullet import pybullet as p
from sim.rendering import CLASSES

__all__ = ["Appearance", "Endoscope", "StereoFrame", "look_at", "render_stereo"]


@dataclass(frozen=True)
class Endoscope:
    """A stereo pinhole endoscope fixed in the world.

    Attributes:
        eye_m: Left eye's nominal position in the world [m] (the flap's nominal centre is at the origin
            in x and y, 26 mm above the table).
        target_m: Point the endoscope looks at [m].
        baseline_m: Distance from the left to the right eye, along the image's x axis [m].
        fov_deg: Vertical field of view [deg].
        width: Image width per eye [px].
        height: Image height per eye [px].
        near_m: Near clipping plane [m].
        far_m: Far clipping plane [m].
    """

    eye_m: tuple[float, float, float] = (0.0, 0.085, 0.11)
    target_m: tuple[float, float, float] = (0.0, 0.005, 0.02)
    baseline_m: float = 0.005
    fov_deg: float = 50.0
    width: int = 128
    height: int = 96
    near_m: float = 0.01
    far_m: float = 0.5

    @property
    def focal_px(self) -> float:
        """Focal length in pixels (square pixels)."""
        return 0.5 * self.height / float(np.tan(np.radians(self.fov_deg) / 2.0))

    def intrinsics(self) -> np.ndarray:
        """The 3 x 3 camera matrix K (ROS ``CameraInfo.k``)."""
        f = self.focal_px
        return np.array([[f, 0.0, self.width / 2.0], [0.0, f, self.height / 2.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class Appearance:
    """One frame's lighting, pose jitter and image degradation.

    Attributes:
        light_direction: Unit vector towards the light, in the world.
        light_rgb: Light colour, each channel in [0, 1].
        ambient: Ambient coefficient.
        diffuse: Diffuse coefficient.
        specular: Specular coefficient (highlights on the wet-looking flap).
        eye_shift_m: Offset of the eye from its nominal place [m].
        target_shift_m: Offset of the looked-at point [m].
        roll_rad: Roll of the image about the optical axis [rad].
        blur_px: Standard deviation of the Gaussian lens blur [px].
        noise: Standard deviation of the sensor noise, as a fraction of full scale.
    """

    light_direction: tuple[float, float, float] = (0.0, 0.6, 0.8)
    light_rgb: tuple[float, float, float] = (1.0, 1.0, 1.0)
    ambient: float = 0.6
    diffuse: float = 0.35
    specular: float = 0.05
    eye_shift_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    target_shift_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    roll_rad: float = 0.0
    blur_px: float = 0.0
    noise: float = 0.0

    @classmethod
    def sample(cls, rng: np.random.Generator, endoscope: Endoscope) -> Appearance:
        """A random appearance: light within 35 degrees of the scope's axis, warm to cool white, pose jitter.

        Ranges: light colour channels 0.8-1, ambient 0.35-0.75, diffuse 0.2-0.6, specular 0-0.6, eye and
        target shifts up to 4 mm per axis, roll up to 3 degrees, blur 0-1 px, noise 0-3 % of full scale.
        """
        axis = np.subtract(endoscope.eye_m, endoscope.target_m)
        axis /= np.linalg.norm(axis)
        tilt = rng.uniform(0.0, np.radians(35.0))
        spin = rng.uniform(0.0, 2.0 * np.pi)
        side = np.cross(axis, [1.0, 0.0, 0.0])
        side /= np.linalg.norm(side)
        up = np.cross(axis, side)
        direction = np.cos(tilt) * axis + np.sin(tilt) * (np.cos(spin) * side + np.sin(spin) * up)
        return cls(
            light_direction=tuple(float(v) for v in direction),  # type: ignore[arg-type]
            light_rgb=tuple(float(v) for v in rng.uniform(0.8, 1.0, 3)),  # type: ignore[arg-type]
            ambient=float(rng.uniform(0.35, 0.75)),
            diffuse=float(rng.uniform(0.2, 0.6)),
            specular=float(rng.uniform(0.0, 0.6)),
            eye_shift_m=tuple(float(v) for v in rng.uniform(-0.004, 0.004, 3)),  # type: ignore[arg-type]
            target_shift_m=tuple(float(v) for v in rng.uniform(-0.004, 0.004, 3)),  # type: ignore[arg-type]
            roll_rad=float(rng.uniform(-np.radians(3.0), np.radians(3.0))),
            blur_px=float(rng.uniform(0.0, 1.0)),
            noise=float(rng.uniform(0.0, 0.03)),
        )


class StereoFrame(NamedTuple):
    """One stereo pair, with what the simulation knows about the left eye's image.

    Attributes:
        left: (H, W, 3) uint8 left image.
        right: (H, W, 3) uint8 right image.
        world_from_camera: 4 x 4 pose of the left eye's camera frame (OpenCV axes) in the world.
        intrinsics: 3 x 3 camera matrix, the same for both eyes.
        baseline_m: Distance from the left eye to the right, along the camera's x axis [m].
        depth_m: (H, W) left eye's depth along its optical axis [m] (a label: no endoscope measures it).
        labels: (H, W) left eye's class labels, indices into :data:`sim.rendering.CLASSES`.
    """

    left: np.ndarray
    right: np.ndarray
    world_from_camera: np.ndarray
    intrinsics: np.ndarray
    baseline_m: float
    depth_m: np.ndarray
    labels: np.ndarray


def look_at(eye: np.ndarray, target: np.ndarray, roll_rad: float = 0.0) -> np.ndarray:
    """The 4 x 4 world pose of a camera (OpenCV axes) at ``eye`` looking at ``target``, world z up."""
    forward = np.asarray(target, dtype=float) - np.asarray(eye, dtype=float)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    c, s = np.cos(roll_rad), np.sin(roll_rad)
    right, down = c * right + s * down, -s * right + c * down
    pose = np.eye(4)
    pose[:3, :3] = np.stack([right, down, forward], axis=1)
    pose[:3, 3] = eye
    return pose


def _view_matrix(pose: np.ndarray) -> list[float]:
    """PyBullet's (OpenGL, column-major) view matrix of a camera pose with OpenCV axes."""
    gl_from_cv = np.diag([1.0, -1.0, -1.0, 1.0])
    view = gl_from_cv @ np.linalg.inv(pose)
    return [float(v) for v in view.T.ravel()]


def _degrade(rgb: np.ndarray, appearance: Appearance, rng: np.random.Generator) -> np.ndarray:
    image = rgb.astype(float)
    if appearance.blur_px > 0:
        from scipy.ndimage import gaussian_filter  # only a blurred camera needs it; not every process's start-up

        image = gaussian_filter(image, sigma=(appearance.blur_px, appearance.blur_px, 0.0))
    if appearance.noise > 0:
        image = image + rng.normal(0.0, 255.0 * appearance.noise, image.shape)
    return np.asarray(np.clip(np.rint(image), 0, 255), dtype=np.uint8)


def render_stereo(
    client: int,
    endoscope: Endoscope,
    appearance: Appearance,
    bodies: dict[str, int],
    rng: np.random.Generator,
) -> StereoFrame:
    """Render both eyes under ``appearance``; ``rng`` draws the noise; ``bodies`` as in :func:`sim.rendering.render`."""
    eye = np.add(endoscope.eye_m, appearance.eye_shift_m)
    target = np.add(endoscope.target_m, appearance.target_shift_m)
    left_pose = look_at(eye, target, appearance.roll_rad)
    right_pose = left_pose.copy()
    right_pose[:3, 3] += endoscope.baseline_m * left_pose[:3, 0]
    projection = p.computeProjectionMatrixFOV(
        endoscope.fov_deg, endoscope.width / endoscope.height, endoscope.near_m, endoscope.far_m,
        physicsClientId=client,
    )  # fmt: skip
    light = {
        "lightDirection": list(appearance.light_direction),
        "lightColor": list(appearance.light_rgb),
        "lightDistance": 0.3,
        "shadow": 0,
        "lightAmbientCoeff": appearance.ambient,
        "lightDiffuseCoeff": appearance.diffuse,
        "lightSpecularCoeff": appearance.specular,
    }
    images, depth_m, labels = [], np.zeros(0), np.zeros(0, dtype=np.uint8)
    for pose in (left_pose, right_pose):
        _, _, rgba, depth, segmentation = p.getCameraImage(
            endoscope.width, endoscope.height, _view_matrix(pose), projection,
            renderer=p.ER_TINY_RENDERER, physicsClientId=client, **light,
        )  # fmt: skip
        shape = (endoscope.height, endoscope.width)
        rgb = np.reshape(np.asarray(rgba, dtype=np.uint8), (*shape, 4))[:, :, :3]
        images.append(_degrade(rgb, appearance, rng))
        if not labels.size:
            buffer = np.reshape(np.asarray(depth, dtype=float), shape)
            near, far = endoscope.near_m, endoscope.far_m
            depth_m = far * near / (far - (far - near) * buffer)
            ids = np.reshape(np.asarray(segmentation, dtype=np.int64), shape)
            objects = np.where(ids >= 0, ids & ((1 << 24) - 1), -1)
            labels = np.zeros(shape, dtype=np.uint8)
            for name, body in bodies.items():
                labels[objects == body] = CLASSES.index(name)
    return StereoFrame(images[0], images[1], left_pose, endoscope.intrinsics(), endoscope.baseline_m, depth_m, labels)
