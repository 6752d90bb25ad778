"""``tissue-retract replay``: summarise a deploy or dry-run recording (MCAP) and plot it.

Prints the duration, the commands computed and sent, safety stops and deadman holds, the peak force, the
largest tracking error per joint (with its unit) and each episode's result; ``--plot out.png`` draws a
figure (:mod:`hardware_if.recording.replay_figure`): each episode on its own clock with its boundary and result, the
force with the force limit, the jaw, the tool tip's tracking error [mm], and the safety filter's
interventions, safety stops and holds, labelled. Needs no ROS.
"""

from __future__ import annotations

import argparse

from hardware_if.recording.replay import load_recording, summarize_recording
from psm_control.inputs import check_output_path

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the subcommand to its parser."""
    parser.add_argument("file", metavar="FILE", help="an .mcap recording written by deploy")
    parser.add_argument(
        "--plot",
        metavar="PNG",
        default=None,
        help="write a figure: force and limit, jaw, tip tracking error, filter events, per episode",
    )


def run(args: argparse.Namespace) -> int:
    """Print the summary and write the plot."""
    if args.plot:
        check_output_path(args.plot, "--plot", (args.file,))
    recording = load_recording(args.file)
    for line in summarize_recording(recording).lines():
        print(line)
    if args.plot:
        from hardware_if.recording.replay_figure import plot_recording  # matplotlib: only for --plot

        print(f"plot: {plot_recording(recording, args.plot)}")
    return 0
