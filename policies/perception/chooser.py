"""The default site estimator: the pink-trained one where the any-colour one agrees with it, else the latter.

Two estimators are shipped. The one trained on the tasks' pink flaps is the more precise on them and is
what the camera policies were trained with; on a flap that looks otherwise it keys on the wrong colour and
misses the site by centimetres. The one trained on flaps of any colour holds on unseen looks. Which flap
a run meets is not known in advance, so :class:`SiteChooser` runs both on each frame and takes the pink
one's site when the two agree within :data:`AGREE_M`, the any-colour one's when they do not: on a flap the
pink one knows they agree, and where they do not the pink one has left what it knows.

Measured on MultiSite with the shipped camera policy, 100 episodes each (``evaluate --policy pretrained
--task multisite --episodes 100 --seeds 51 --perception camera[:pink|:any-colour] [--texture F]``; the true
site's policy: 97 %): on the tasks' pink flaps 96 % (pink alone 96, any-colour alone 99), the pink one's
site taken in 99 episodes; on three tissue-like textures made for the check, none of them trained on (a dark
red mottled "liver", yellow "fat" with red vessels, a beige "serosa" with a vessel tree): 98, 91 and 92 %
(pink alone 98, 19 and 34 %; any-colour alone 100, 94 and 95 %).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from policies.perception.network import SiteEstimator, load_estimator
from sim.endoscope import StereoFrame
from sim.tissue import SITE_NAMES

__all__ = ["AGREE_M", "ANY_COLOUR", "PINK", "SiteChooser", "load_site_estimator"]

#: Largest distance between the two estimators' sites at which the pink one's is taken [m]. The share of
#: frames whose chosen site is 4 mm or more off the true one, at 2 / 3 / 4 mm: on the flaps of the first 200
#: trials of the Target camera sweep (``robustness --perception camera --vary stiffness=0.3:3x,size=0.8:1.2x,
#: ...``) 31 / 25 / 18.5 %; on 100 of MultiSite's own flaps 14 / 10 / 8 %; on 60 each of the unseen textures
#: (``docs/perception/unseen/``), the yellow "fat" 18 / 20 / 23 %, the beige "serosa" 17 / 17 / 23 %, the dark
#: red "liver" 10 / 5 / 5 % (the pink one alone: 6, 8, 77, 87 and 5 %). The pink one was trained over the
#: sweep's flaps (``train-perception --vary``), the any-colour one over the tasks' own: on pink flaps a tight
#: threshold hands the site to the worse estimate; a loose one lets the pink one's through on a flap it reads
#: wrongly.
AGREE_M = 0.004
#: The names ``--perception camera:NAME`` takes for either shipped estimator alone.
PINK, ANY_COLOUR = "pink", "any-colour"


class SiteChooser:
    """The pink-trained estimator where the any-colour one agrees within ``agree_m``, else the any-colour one.

    It reads as a :class:`~policies.perception.SiteEstimator` does (``endoscope``, ``mark_sites``,
    ``info``, ``world_sites``) and says which it took for the last frame (:attr:`last_taken`, and why:
    :attr:`last_choice`).

    Args:
        pink: The estimator trained on the tasks' pink flaps.
        any_colour: The estimator trained on flaps of any colour (same endoscope).
        agree_m: See :data:`AGREE_M`.
    """

    def __init__(self, pink: SiteEstimator, any_colour: SiteEstimator, agree_m: float = AGREE_M) -> None:
        if pink.endoscope != any_colour.endoscope:
            raise ValueError("the two estimators were trained for different endoscopes")
        self.pink, self.any_colour, self.agree_m = pink, any_colour, float(agree_m)
        self.endoscope = pink.endoscope
        self.info: dict[str, Any] = {"chooser": True, "any_colour": True, "agree_m": self.agree_m}
        #: ``pink`` or ``any-colour``: the estimator whose sites the last frame gave ("" before the first).
        self.last_taken = ""
        #: How far apart the two estimators' deciding sites lay on the last frame [m].
        self.last_apart_m = float("nan")

    @property
    def mark_sites(self) -> bool:
        """Whether the flaps carry inked sites (as the estimators were trained on)."""
        return self.pink.mark_sites or self.any_colour.mark_sites

    def world_sites(self, frame: StereoFrame, site: str | None = None) -> np.ndarray:
        """The three sites (3, 3) in the world [m] from the estimator chosen for this frame.

        Args:
            frame: The stereo pair.
            site: The site the run grasps (one of ``sim.tissue.SITE_NAMES``), whose agreement decides; None:
                the three sites' largest disagreement.
        """
        pink, other = self.pink.world_sites(frame), self.any_colour.world_sites(frame)
        apart = np.linalg.norm(pink - other, axis=1)
        self.last_apart_m = float(apart[SITE_NAMES.index(site)] if site is not None else apart.max())
        self.last_taken = PINK if self.last_apart_m <= self.agree_m else ANY_COLOUR
        return pink if self.last_taken == PINK else other

    @property
    def last_choice(self) -> str:
        """Which estimator the last frame took, and why ("" before the first frame)."""
        distance_mm = 1000 * self.last_apart_m
        if self.last_taken == PINK:
            return f"pink (the any-colour estimator agrees within {distance_mm:.1f} mm)"
        if self.last_taken == ANY_COLOUR:
            return (
                f"any-colour (the pink estimator's site is {distance_mm:.1f} mm from it, over "
                f"{1000 * self.agree_m:g} mm: the flap does not look like the pink training flaps)"
            )
        return ""


def load_site_estimator(name: str | None = None) -> SiteChooser | SiteEstimator:
    """What ``--perception camera[:NAME]`` runs: None, the :class:`SiteChooser` of the two shipped estimators;
    ``pink`` or ``any-colour``, that shipped one alone; otherwise a model file (:func:`load_estimator`)."""
    if name is None:
        return SiteChooser(load_estimator(PINK), load_estimator(ANY_COLOUR))
    return load_estimator(name)  # ``pink`` and ``any-colour`` are names of SHIPPED_MODELS
