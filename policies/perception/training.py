"""Training the site estimator within a wall-clock budget, and its held-out error.

The budget is the whole command's, from the process's start: held-out frames first (a fixed number, so
the error of two budgets is measured on the same frames), then training frames until
:data:`RENDER_SHARE` of what remains is spent (or :data:`MAX_FRAMES` are held), then training until the
budget's end less the time the last measurement and the save take. The learning rate follows a cosine
over the training's time, so a short budget still ends on a small step.

The error is the 3-D distance of each estimated site to the true site, over the three sites of every
held-out frame. The true site lies at its named place on the flap plus an offset drawn per episode
(uniform, +-3 mm along the edge, +-2 mm across, :mod:`sim.randomization`) that an unmarked flap does not
show: the distance of the named place to the true site (``floor``) is what an estimator that finds the
named place exactly still gets wrong; with inked sites (``mark_sites``) the offset is visible.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch

from policies.perception.frames import ANY_COLOUR, LabelledFrames, render_frames
from policies.perception.network import SiteEstimator, SiteNet
from sim.endoscope import Endoscope
from sim.robustness import TrainingRanges

__all__ = [
    "MAX_FRAMES",
    "RENDER_SHARE",
    "TrainingReport",
    "TrainingState",
    "error_stats_mm",
    "train_site_estimator",
]

#: Share of the budget (after the held-out frames) spent rendering training frames.
RENDER_SHARE = 0.35
#: Most training frames held in memory (6 x 96 x 128 bytes each: 74 kB, so 6,000 take 440 MB).
MAX_FRAMES = 6000
_TRAIN_SEED_BASE = 90_000_000
_HELDOUT_SEED_BASE = 91_000_000
_LABEL_SCALE_M = 0.01
_RESERVE_S = 10.0  # the last measurement, the save and the exit


@dataclass
class TrainingReport:
    """What a training did and how well its estimator does on held-out frames.

    Attributes:
        train_frames: Training frames rendered.
        heldout_frames: Held-out frames (each gives three site errors).
        epochs: Passes over the training frames.
        render_s: Time spent rendering [s].
        train_s: Time spent training [s].
        median_mm: Median held-out error to the true site [mm].
        p95_mm: 95th percentile of that error [mm].
        named_median_mm: Median error to the sites' named places (the estimator's own share) [mm].
        named_p95_mm: 95th percentile of that [mm].
        floor_median_mm: Median distance of the named place to the true site on these frames [mm].
        floor_p95_mm: 95th percentile of that distance [mm].
    """

    train_frames: int
    heldout_frames: int
    epochs: int
    render_s: float
    train_s: float
    median_mm: float
    p95_mm: float
    named_median_mm: float
    named_p95_mm: float
    floor_median_mm: float
    floor_p95_mm: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return asdict(self)


@dataclass
class TrainingState:
    """What a training has computed so far: a stopped training's caller keeps it.

    Attributes:
        heldout: The held-out frames, once rendered.
        estimator: The estimator being trained (its network changes in place), once training has begun.
        epochs: Passes over the training frames begun so far.
    """

    heldout: LabelledFrames | None = None
    estimator: SiteEstimator | None = None
    epochs: int = 0


def error_stats_mm(estimated_m: np.ndarray, true_m: np.ndarray) -> tuple[float, float]:
    """Median and 95th percentile of the point distances [mm]."""
    distances = 1000.0 * np.linalg.norm(np.asarray(estimated_m) - np.asarray(true_m), axis=-1).ravel()
    return float(np.median(distances)), float(np.percentile(distances, 95))


def _train(
    net: SiteNet,
    frames: LabelledFrames,
    mean_m: np.ndarray,
    deadline_s: float,
    seed: int,
    state: TrainingState,
    progress: Callable[[str], None],
) -> tuple[int, float]:
    """Train until ``deadline_s`` (monotonic), one batch at least; return the epochs begun and the time spent [s]."""
    start = time.monotonic()
    generator = torch.Generator().manual_seed(seed)
    images = torch.from_numpy(frames.images)
    labels = torch.from_numpy(((frames.sites_camera_m.reshape(-1, 9) - mean_m) / _LABEL_SCALE_M).astype(np.float32))
    optimizer = torch.optim.AdamW(net.parameters(), lr=3e-3, weight_decay=1e-4)
    loss_fn = torch.nn.SmoothL1Loss(beta=0.1)
    total = max(deadline_s - start, 1e-6)
    batch = 32  # few epochs fit a budget on a shared CPU: more, smaller steps learn faster
    epochs = 0
    net.train()
    while epochs == 0 or time.monotonic() < deadline_s:
        epochs += 1
        state.epochs = epochs
        order = torch.randperm(len(images), generator=generator)
        for first in range(0, len(order), batch):
            fraction = min(1.0, (time.monotonic() - start) / total)
            for group in optimizer.param_groups:
                group["lr"] = 1e-5 + 0.5 * (3e-3 - 1e-5) * (1.0 + math.cos(math.pi * fraction))
            index = order[first : first + batch]
            optimizer.zero_grad()
            loss = loss_fn(net(images[index]), labels[index])
            loss.backward()
            optimizer.step()
            if time.monotonic() >= deadline_s:
                break
        else:
            progress(
                f"training: epoch {epochs} done at {time.monotonic() - start:.1f} s, last batch loss {loss.item():.4f}"
            )
    net.eval()
    return epochs, time.monotonic() - start


def train_site_estimator(
    task: str,
    *,
    budget_s: float,
    started_s: float,
    seed: int = 0,
    heldout: int = 300,
    mark_sites: bool = False,
    textures: Sequence[str] = (),
    any_colour: bool = False,
    vary: TrainingRanges | None = None,
    endoscope: Endoscope | None = None,
    progress: Callable[[str], None] = print,
    state: TrainingState | None = None,
) -> tuple[SiteEstimator, TrainingReport]:
    """Render, train and measure within ``budget_s`` seconds from ``started_s`` (:func:`time.monotonic`).

    Args:
        task: The task whose randomization the frames follow.
        budget_s: Wall-clock budget of the whole command [s].
        started_s: When the command started (monotonic) [s].
        seed: Seeds the network's initialisation and the training order; the frames' seeds follow from it.
        heldout: Held-out resets (one frame each).
        mark_sites: Ink the sites on the flap.
        textures: Image files for the flap (none: the procedural textures).
        any_colour: Train and measure on flaps of any colour (:data:`~policies.perception.frames.ANY_COLOUR`).
        vary: Train and measure over these ranges (``--vary``, :func:`sim.robustness.training_ranges`), e.g. a
            robustness sweep's stiffness and size; the flap's drawn as the sweep draws them.
        endoscope: The endoscope (default :class:`Endoscope`).
        progress: Receives one line per stage.
        state: Filled in as the training goes (the held-out frames, the estimator in training), for a
            caller to keep what was computed when the training is stopped.
    """
    state = state if state is not None else TrainingState()
    torch.manual_seed(seed)
    endoscope = endoscope or Endoscope()
    deadline = started_s + budget_s
    options: dict[str, Any] = {
        "endoscope": endoscope,
        "mark_sites": mark_sites,
        "textures": textures,
        "randomization": {**(ANY_COLOUR if any_colour else {}), **(vary.randomization if vary is not None else {})},
        "log_uniform": vary.log_uniform if vary is not None else (),
    }
    test = render_frames(
        task, [_HELDOUT_SEED_BASE + 10_000 * seed + i for i in range(heldout)], frames_per_reset=1, **options
    )
    state.heldout = test
    progress(f"held-out: {len(test)} frames rendered in {test.seconds:.1f} s")
    render_until = time.monotonic() + RENDER_SHARE * max(0.0, deadline - time.monotonic() - _RESERVE_S)
    resets = range(_TRAIN_SEED_BASE + 100_000 * seed, _TRAIN_SEED_BASE + 100_000 * seed + MAX_FRAMES // 2)
    frames = render_frames(task, list(resets), frames_per_reset=2, deadline_s=render_until, **options)
    progress(f"training: {len(frames)} frames rendered in {frames.seconds:.1f} s")
    mean = frames.sites_camera_m.reshape(-1, 9).mean(axis=0)
    net = SiteNet()
    estimator = SiteEstimator(net, endoscope, mean, _LABEL_SCALE_M, {})
    state.estimator = estimator
    epochs, train_s = _train(net, frames, mean, deadline - _RESERVE_S, seed, state, progress)
    estimated = estimator.camera_sites(test.images)
    median, p95 = error_stats_mm(estimated, test.sites_camera_m)
    named_median, named_p95 = error_stats_mm(estimated, test.named_camera_m)
    floor_median, floor_p95 = error_stats_mm(test.named_camera_m, test.sites_camera_m)
    report = TrainingReport(
        train_frames=len(frames),
        heldout_frames=len(test),
        epochs=epochs,
        render_s=test.seconds + frames.seconds,
        train_s=train_s,
        median_mm=median,
        p95_mm=p95,
        named_median_mm=named_median,
        named_p95_mm=named_p95,
        floor_median_mm=floor_median,
        floor_p95_mm=floor_p95,
    )
    estimator.info.update(
        task=task,
        seed=seed,
        mark_sites=mark_sites,
        textures=list(textures),
        any_colour=any_colour,
        vary={name: list(r) for name, r in vary.randomization.items()} if vary is not None else {},
        report=report.to_dict(),
    )
    return estimator, report
