"""The default site estimator: the pink-trained one on a flap that looks pink, else the any-colour one.

Two estimators are shipped. The one trained on the tasks' pink flaps (over the robustness sweep's sizes and
stiffnesses) is the more precise on them and is what the camera policies were trained with; on a flap that
looks otherwise it keys on the wrong colour and misses the site by centimetres. The one trained on flaps of
any colour holds on unseen looks, but is the worse on the sweep's larger and softer pink flaps. Which flap a
run meets is not known in advance, so :class:`SiteChooser` runs the pink one on each frame and looks at the
image where it put the sites: where the flap there is as red over green as the pink flaps are
(:data:`PINK_MIN_RED_OVER_GREEN`), its sites are taken; elsewhere the any-colour one's.

An earlier chooser took the pink one's site where the any-colour one agreed with it within a distance. On the
sweep's flaps the any-colour one then disagreed often and was taken where it was the worse, and a distance
loose enough for those let the pink one's mistakes through on unseen looks (the measurements are at
:data:`PINK_MIN_RED_OVER_GREEN`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from policies.perception.frames import camera_points
from policies.perception.network import SiteEstimator, load_estimator
from sim.endoscope import StereoFrame

__all__ = ["ANY_COLOUR", "PINK", "PINK_MIN_RED_OVER_GREEN", "SiteChooser", "flap_red_over_green", "load_site_estimator"]

#: Least red over green, ``(r - g) / (r + g + b)`` of the left image's mean colour in 9 x 9 px about the pink
#: estimator's three sites, at which its sites are taken. Measured (``--perception camera`` frames, the pink
#: estimator's sites): the flaps of the first 100 trials of the Target camera sweep 0.113-0.327 (1st
#: percentile 0.118), the dark red "liver" 0.195-0.36, the yellow "fat" 0.053-0.136, the beige "serosa"
#: 0.039-0.134, the checkerboard, stripes and speckle of ``tests/data/textures`` -0.121-0.030. The share of
#: frames whose chosen site is 4 mm or more off the true one, at 0.10 / 0.12 / 0.14: the sweep's flaps 8 / 9 /
#: 9 % (the pink one alone 8 %), fat 37 / 18 / 19 % (the any-colour one alone 18 %), serosa 27 / 15 / 13 %
#: (15 %), liver 6 / 6 / 6 % (the pink one alone 6 %), the three test textures as the any-colour one alone.
#: The agreement rule before it, at 4 mm: the sweep's 18.5 %, fat 23 %, serosa 23 %.
PINK_MIN_RED_OVER_GREEN = 0.12
#: Half the side of the image patch about each site whose colour is read [px].
_PATCH_HALF_PX = 4
#: The names ``--perception camera:NAME`` takes for either shipped estimator alone.
PINK, ANY_COLOUR = "pink", "any-colour"


def flap_red_over_green(frame: StereoFrame, world_sites: np.ndarray) -> float:
    """``(r - g) / (r + g + b)`` of the left image's mean colour about ``world_sites`` (N, 3) [m]; NaN if none
    of them is in view."""
    height, width = frame.left.shape[:2]
    pixels = []
    for in_camera in camera_points(frame, np.asarray(world_sites, dtype=float).reshape(-1, 3)):
        if in_camera[2] <= 0.0:
            continue
        u, v, _ = frame.intrinsics @ (in_camera / in_camera[2])
        col, row = int(np.rint(u)), int(np.rint(v))
        if not (0 <= col < width and 0 <= row < height):
            continue
        rows = slice(max(row - _PATCH_HALF_PX, 0), row + _PATCH_HALF_PX + 1)
        cols = slice(max(col - _PATCH_HALF_PX, 0), col + _PATCH_HALF_PX + 1)
        pixels.append(frame.left[rows, cols].reshape(-1, 3))
    if not pixels:
        return float("nan")
    mean = np.concatenate(pixels).astype(float).mean(axis=0)
    total = float(mean.sum())
    return float((mean[0] - mean[1]) / total) if total > 0.0 else float("nan")


class SiteChooser:
    """The pink-trained estimator where the flap about its sites looks pink, else the any-colour one.

    It reads as a :class:`~policies.perception.SiteEstimator` does (``endoscope``, ``mark_sites``,
    ``info``, ``world_sites``) and says which it took for the last frame (:attr:`last_taken`, and why:
    :attr:`last_choice`).

    Args:
        pink: The estimator trained on the tasks' pink flaps.
        any_colour: The estimator trained on flaps of any colour (same endoscope).
        min_red_over_green: See :data:`PINK_MIN_RED_OVER_GREEN`.
    """

    def __init__(
        self, pink: SiteEstimator, any_colour: SiteEstimator, min_red_over_green: float = PINK_MIN_RED_OVER_GREEN
    ) -> None:
        if pink.endoscope != any_colour.endoscope:
            raise ValueError("the two estimators were trained for different endoscopes")
        self.pink, self.any_colour = pink, any_colour
        self.min_red_over_green = float(min_red_over_green)
        self.endoscope = pink.endoscope
        self.info: dict[str, Any] = {"chooser": True, "any_colour": True, "min_red_over_green": self.min_red_over_green}
        #: ``pink`` or ``any-colour``: the estimator whose sites the last frame gave ("" before the first).
        self.last_taken = ""
        #: Red over green of the flap about the pink estimator's sites on the last frame.
        self.last_red_over_green = float("nan")

    @property
    def mark_sites(self) -> bool:
        """Whether the flaps carry inked sites (as the estimators were trained on)."""
        return self.pink.mark_sites or self.any_colour.mark_sites

    def world_sites(self, frame: StereoFrame, site: str | None = None) -> np.ndarray:
        """The three sites (3, 3) in the world [m] from the estimator chosen for this frame.

        Args:
            frame: The stereo pair.
            site: The site the run grasps (one of ``sim.tissue.SITE_NAMES``); the choice is the flap's, not the
                site's, so it is not read.
        """
        pink = self.pink.world_sites(frame)
        self.last_red_over_green = flap_red_over_green(frame, pink)
        pinkish = bool(self.last_red_over_green >= self.min_red_over_green)  # NaN (nothing in view): not pink
        self.last_taken = PINK if pinkish else ANY_COLOUR
        return pink if pinkish else self.any_colour.world_sites(frame)

    @property
    def last_choice(self) -> str:
        """Which estimator the last frame took, and why ("" before the first frame)."""
        seen = f"red over green {self.last_red_over_green:.3f} about the pink estimator's sites"
        if self.last_taken == PINK:
            return f"pink (the flap looks pink: {seen}, at least {self.min_red_over_green:g})"
        if self.last_taken == ANY_COLOUR:
            return (
                f"any-colour ({seen}, under {self.min_red_over_green:g}: the flap does not look like the pink "
                "training flaps)"
            )
        return ""


def load_site_estimator(name: str | None = None) -> SiteChooser | SiteEstimator:
    """What ``--perception camera[:NAME]`` runs: None, the :class:`SiteChooser` of the two shipped estimators;
    ``pink`` or ``any-colour``, that shipped one alone; otherwise a model file (:func:`load_estimator`)."""
    if name is None:
        return SiteChooser(load_estimator(PINK), load_estimator(ANY_COLOUR))
    return load_estimator(name)  # ``pink`` and ``any-colour`` are names of SHIPPED_MODELS
