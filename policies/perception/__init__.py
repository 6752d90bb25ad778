"""The camera's site estimator: labelled endoscope frames, a small CNN, its training and its model file.

:mod:`policies.perception.frames` renders randomized stereo frames labelled with the grasp sites from the
simulation; :mod:`policies.perception.network` holds the network and :class:`SiteEstimator` (load, save,
estimate the sites in the world from one stereo pair); :mod:`policies.perception.chooser` is the default,
which takes one of the two shipped estimators per frame; :mod:`policies.perception.training` trains it
within a wall-clock budget and measures its held-out error.
"""

from __future__ import annotations

from policies.perception.chooser import SiteChooser, load_site_estimator
from policies.perception.frames import LabelledFrames, render_frames
from policies.perception.network import SHIPPED_MODEL, SHIPPED_MODELS, SiteEstimator, SiteNet, load_estimator
from policies.perception.training import TrainingReport, train_site_estimator

__all__ = [
    "SHIPPED_MODEL",
    "SHIPPED_MODELS",
    "LabelledFrames",
    "SiteChooser",
    "SiteEstimator",
    "SiteNet",
    "TrainingReport",
    "load_estimator",
    "load_site_estimator",
    "render_frames",
    "train_site_estimator",
]
