"""``tissue-retract train-perception``: train the endoscope's site estimator on randomized renders.

Renders stereo endoscope frames of the task's randomized flap (colour, texture, placement, sag) under
randomized lighting, endoscope pose jitter, blur and noise, labelled with the three grasp sites from the
simulation; trains the small CNN of :mod:`policies.perception.network` to estimate the sites; prints
its error on held-out frames (median and 95th percentile, mm) against the true sites, against their
named places, and the floor the sites' invisible offset sets. Within ``--budget-s`` of wall time from
the command's start (default 570 s). Writes ``--out/site-estimator.safetensors`` (for
``--perception camera:FILE``), ``--out/report.json`` and ``--out/frames.png``: eight randomized frames
of other flaps with the true sites (green) and the estimates (blue), left eye, twice the size.

SIGINT (Ctrl-C, also when started in the background of a script) and SIGTERM stop it within a batch and
keep what it computed: the held-out frames (``--out/heldout-frames.npz``: ``images``, ``sites_camera_m``,
``named_camera_m``) and, once training has begun, the unfinished model
(``--out/site-estimator-partial.safetensors``, not measured); it exits with 130 or 143.

``--mark-sites`` inks the sites on the flap (a surgeon's marker): the offset becomes visible, and the
commands that use the model ink them too. ``--texture FILE ...`` trains on your own flap images
instead of the procedural textures.
``--vary`` trains over ranges as ``robustness --vary`` names them (e.g. the sweep's
``stiffness=0.3:3x,size=0.8:1.2x``): an estimator trained on the tasks' own flaps misses the site by more on
a sweep's larger and softer ones.
"""

from __future__ import annotations

import argparse
import json
import signal
import time
from pathlib import Path
from typing import Any

import imageio.v2 as imageio
import numpy as np

from psm_control.errors import ConfigurationError
from psm_control.outputs import atomic_path, write_atomic
from sim.registration import gym_id
from sim.robustness import TrainingRanges, parse_vary, training_ranges
from sim.sweep.stopping import handling
from tissue_retract.cli._camera import check_texture
from tissue_retract.cli._checks import check_out_folder, float_in, int_in
from tissue_retract.cli.train import _command_started_s

__all__ = ["add_arguments", "run"]

_MODEL = "site-estimator.safetensors"
_PARTIAL_MODEL = "site-estimator-partial.safetensors"
_HELDOUT = "heldout-frames.npz"
#: The signals that stop a training (it keeps what it computed).
_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class _Stopped(KeyboardInterrupt):
    """A stop signal arrived.

    Attributes:
        signum: The signal's number (the exit status is 128 + it).
    """

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(signal.Signals(signum).name)


def _stop(signum: int, _frame: Any) -> None:
    raise _Stopped(signum)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the subcommand to its parser."""
    parser.add_argument("--task", default="multisite", help="lift, target, multisite (default: multisite)")
    parser.add_argument(
        "--budget-s", type=float_in(20.0, 86400.0), default=570.0, help="wall-clock budget [s] (default: 570)"
    )
    parser.add_argument("--out", required=True, metavar="DIR", help="folder for the model and report.json")
    parser.add_argument("--seed", type=int_in(0, 999), default=0, help="seed of the network and frames (default 0)")
    parser.add_argument("--heldout", type=int_in(10, 5000), default=300, help="held-out frames (default: 300)")
    parser.add_argument("--mark-sites", action="store_true", help="ink the sites on the flap (visible offset)")
    parser.add_argument("--texture", nargs="+", metavar="FILE.png", default=[], help="train on these flap images")
    parser.add_argument(
        "--any-colour",
        action="store_true",
        help="train and measure on flaps of any colour (each channel 0.15-1), not only the tasks' pink ones",
    )
    parser.add_argument(
        "--vary",
        default=None,
        help="train and measure over these ranges, as robustness's --vary takes them (the same names and parser), "
        "e.g. stiffness=0.3:3x,size=0.8:1.2x: the flaps a sweep with them meets; only what changes a frame "
        "(the flap's size, stiffness, thickness, density, placement) changes the frames",
    )


def run(args: argparse.Namespace) -> int:
    """Train, measure, save and print."""
    started = _command_started_s() if args.command_line.split()[1:2] == ["train-perception"] else time.monotonic()
    task = gym_id(args.task)
    textures = [check_texture(path) for path in args.texture]
    out = Path(args.out)
    vary = _ranges(args.vary)
    check_out_folder(out, [_MODEL, _PARTIAL_MODEL, _HELDOUT, "report.json", "frames.png"], textures)
    from policies.perception import train_site_estimator  # torch: imported once the arguments are good
    from policies.perception.training import TrainingState

    state = TrainingState()
    # Handlers of its own, unblocked: a process started in the background of a script inherits SIGINT
    # ignored, and Python's default SIGTERM would end it at once, losing what it rendered.
    with handling(_STOP_SIGNALS, _stop):
        try:
            print(f"train-perception: {task}, budget {args.budget_s:g} s", flush=True)
            estimator, report = train_site_estimator(
                task,
                budget_s=args.budget_s,
                started_s=started,
                seed=args.seed,
                heldout=args.heldout,
                mark_sites=args.mark_sites,
                textures=textures,
                any_colour=args.any_colour,
                vary=vary,
                progress=lambda line: print(line, flush=True),
                state=state,
            )
        except _Stopped as e:
            print(f"train-perception: stopped by {signal.Signals(e.signum).name}: {_keep(out, state, args)}")
            return 128 + e.signum
    estimator.info["command"] = args.command_line
    estimator.save(out / _MODEL)
    elapsed = time.monotonic() - started
    estimator.info["elapsed_s"] = elapsed
    write_atomic(out / "report.json", json.dumps({**estimator.info, "elapsed_s": elapsed}, indent=2), "--out")
    print(f"trained {report.epochs} epoch(s) on {report.train_frames} frames in {report.train_s:.1f} s")
    print(
        f"held-out site error ({report.heldout_frames} frames x 3 sites): "
        f"median {report.median_mm:.2f} mm, p95 {report.p95_mm:.2f} mm"
    )
    print(f"  to the sites' named places: median {report.named_median_mm:.2f} mm, p95 {report.named_p95_mm:.2f} mm")
    marked = "inked: visible" if args.mark_sites else "not visible on an unmarked flap"
    print(
        f"  floor of the sites' offset ({marked}): median {report.floor_median_mm:.2f} mm, "
        f"p95 {report.floor_p95_mm:.2f} mm"
    )
    print(f"model: {out / _MODEL} ({(out / _MODEL).stat().st_size / 1e6:.2f} MB); {elapsed:.1f} s in all")
    write_frames_picture(out / "frames.png", estimator)
    print(f"frames: {out / 'frames.png'} (held-out frames; true sites green, estimates blue)")
    return 0


def _ranges(vary: str | None) -> TrainingRanges | None:
    """``--vary``'s ranges, parsed as ``robustness`` and ``train`` parse them; a disturbance is refused (it acts on
    an episode's observations and actions, never on a frame)."""
    if not vary:
        return None
    ranges = training_ranges(parse_vary(vary))
    if ranges.disturbances:
        names = ", ".join(r.name for r in ranges.disturbances)
        raise ConfigurationError("--vary", vary, f"the flap's parameters ({names}: a disturbance draws no frame)")
    return ranges


def _keep(out: Path, state: Any, args: argparse.Namespace) -> str:
    """Write what a stopped training computed; say what was kept."""
    if state.heldout is None:
        return "nothing to keep (stopped while rendering the held-out frames)"
    # Not interrupted again while it writes: a second signal would lose what the first one keeps.
    with handling(_STOP_SIGNALS, lambda _signum, _frame: None):
        heldout = state.heldout
        with atomic_path(out / _HELDOUT, "--out") as temporary:
            np.savez_compressed(
                temporary,
                images=heldout.images,
                sites_camera_m=heldout.sites_camera_m,
                named_camera_m=heldout.named_camera_m,
            )
        kept = f"kept {len(heldout)} held-out frames in {out / _HELDOUT}"
        if state.estimator is None or state.epochs == 0:
            return kept + " (stopped before training began: no model)"
        state.estimator.info.update(
            command=args.command_line, unfinished=True, epochs_begun=state.epochs, mark_sites=args.mark_sites
        )
        state.estimator.save(out / _PARTIAL_MODEL)
    return f"{kept} and the unfinished model ({state.epochs} epoch(s) begun, not measured) in {out / _PARTIAL_MODEL}"


def write_frames_picture(path: Path, estimator: Any, count: int = 8) -> None:
    """A grid of randomized held-out left-eye frames: true sites in green, estimated ones in blue (2x size)."""
    from policies.perception import render_frames

    seeds = [92_000_000 + i for i in range(count)]
    textures = estimator.info.get("textures", [])
    frames = render_frames("multisite", seeds, frames_per_reset=1, mark_sites=estimator.mark_sites, textures=textures)
    estimated = estimator.camera_sites(frames.images)
    intrinsics = estimator.endoscope.intrinsics()
    tiles = []
    for index in range(count):
        image = np.repeat(np.repeat(frames.images[index, :3].transpose(1, 2, 0), 2, axis=0), 2, axis=1).copy()
        for points, colour in ((frames.sites_camera_m[index], (0, 255, 0)), (estimated[index], (40, 90, 255))):
            for point in points:
                u, v, w = intrinsics @ point
                col, row = int(2 * u / w), int(2 * v / w)
                image[max(row - 1, 0) : row + 2, max(col - 1, 0) : col + 2] = colour
        tiles.append(image)
    rows = [np.concatenate(tiles[i : i + 4], axis=1) for i in range(0, count, 4)]
    with atomic_path(path, "--out") as temporary:
        imageio.imwrite(temporary, np.concatenate(rows, axis=0))
