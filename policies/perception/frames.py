"""Randomized endoscope frames labelled with the grasp sites, rendered from the simulation.

Each episode reset draws a new flap (placement, size, material, so its sag, colour, texture and the
site's hidden offset) and a new RCM; each frame of it draws its own lighting, endoscope pose jitter, blur
and noise (:class:`sim.endoscope.Appearance`). The labels are the three sites of
:data:`sim.tissue.SITE_NAMES` in the left eye's camera frame, each at its named place plus the episode's
offset (the offset the environment gives the episode's site), and the same without the offset (the
named places, for the error floor the invisible offset sets).
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

import sim.envs
from sim.endoscope import Appearance, Endoscope, StereoFrame
from sim.tissue import SITE_NAMES, TissueParams

__all__ = ["ANY_COLOUR", "LabelledFrames", "camera_points", "render_frames", "stereo_input", "true_sites"]

#: Flaps of any colour: each channel of the flap's tint 0.15-1, where the tasks' flaps are pink (0.7-0.95,
#: 0.3-0.5, 0.3-0.5). An estimator trained on pink flaps keys on their colour and loses a flap of another look.
ANY_COLOUR: dict[str, tuple[float, float]] = {f"tissue_color_{c}": (0.15, 1.0) for c in "rgb"}


@dataclass
class LabelledFrames:
    """Stereo frames and their labels.

    Attributes:
        images: (N, 6, H, W) uint8, left RGB then right RGB.
        sites_camera_m: (N, 3, 3) the sites (with the episode's offset) in the left camera frame [m].
        named_camera_m: (N, 3, 3) the sites' named places (no offset) in the left camera frame [m].
        seconds: Wall time the rendering took [s].
    """

    images: np.ndarray
    sites_camera_m: np.ndarray
    named_camera_m: np.ndarray
    seconds: float

    def __len__(self) -> int:
        return len(self.images)


def stereo_input(frame: StereoFrame) -> np.ndarray:
    """The network's input of one frame: (6, H, W) uint8, left RGB then right RGB."""
    return np.concatenate([frame.left, frame.right], axis=2).transpose(2, 0, 1).copy()


def camera_points(frame: StereoFrame, world_points: np.ndarray) -> np.ndarray:
    """World points (..., 3) in the frame's left camera frame [m]."""
    camera_from_world = np.linalg.inv(frame.world_from_camera)
    return np.asarray(world_points @ camera_from_world[:3, :3].T + camera_from_world[:3, 3])


def true_sites(task: Any, *, with_offset: bool = True) -> np.ndarray:
    """The three sites (3, 3) of the episode in the world [m], with or without the episode's offset."""
    tissue = task.scene.tissue
    offset = np.array([task.values["site_offset_x_m"], task.values["site_offset_y_m"], 0.0]) * with_offset
    nodes = tissue.positions()
    points = []
    for name in SITE_NAMES:
        indices, weights = tissue.site_binding(tissue.site_local[name] + offset)
        points.append(weights @ nodes[indices])
    return np.array(points)


def render_frames(
    task: str,
    seeds: Sequence[int],
    *,
    frames_per_reset: int = 2,
    endoscope: Endoscope | None = None,
    mark_sites: bool = False,
    textures: Sequence[str] = (),
    randomization: Mapping[str, tuple[float, float]] | None = None,
    log_uniform: Iterable[str] = (),
    deadline_s: float = float("inf"),
) -> LabelledFrames:
    """Render ``frames_per_reset`` frames after each reset of ``task`` with the given seeds.

    Args:
        task: A task name (its randomization ranges are used).
        seeds: Episode seeds; each also seeds its frames' appearance.
        frames_per_reset: Frames per reset, each with its own appearance.
        endoscope: The endoscope (default :class:`Endoscope`).
        mark_sites: Ink the sites (:attr:`sim.tissue.TissueParams.mark_sites`).
        textures: Image files for the flap, used in turn (none: the procedural textures).
        randomization: Overrides of the task's randomization ranges (e.g. :data:`ANY_COLOUR`).
        log_uniform: Those of them drawn log-uniformly, as a sweep's multiples are (``train-perception --vary``).
        deadline_s: Stop early at this :func:`time.monotonic` time (at least one reset is rendered).
    """
    start = time.monotonic()
    endoscope = endoscope or Endoscope()
    images, sites, named = [], [], []
    sources: list[str | None] = [*textures] or [None]
    envs = {
        path: sim.envs.make(
            task,
            endoscope=endoscope,
            tissue=TissueParams(texture_path=path, mark_sites=mark_sites),
            randomization=dict(randomization or {}),
        )
        for path in sources
    }
    if log_uniform:
        for env in envs.values():
            env.unwrapped.use_randomization(dict(randomization or {}), log_uniform)
    try:
        for index, seed in enumerate(seeds):
            env = list(envs.values())[index % len(envs)]
            env.reset(seed=int(seed))
            unwrapped = env.unwrapped
            world_sites = true_sites(unwrapped)
            world_named = true_sites(unwrapped, with_offset=False)
            rng = np.random.default_rng([int(seed), 36])
            for _ in range(frames_per_reset):
                frame = unwrapped.render_endoscope(Appearance.sample(rng, endoscope), rng)
                images.append(stereo_input(frame))
                sites.append(camera_points(frame, world_sites))
                named.append(camera_points(frame, world_named))
            if time.monotonic() > deadline_s:
                break
    finally:
        for env in envs.values():
            env.close()
    return LabelledFrames(np.stack(images), np.stack(sites), np.stack(named), time.monotonic() - start)
