"""``tissue-retract replay``: summarise a deploy or dry-run recording (MCAP) and plot it.

Prints the duration, the commands computed and sent, safety stops and deadman holds, the peak force, the
largest tracking error per joint and each episode's result; ``--plot out.png`` draws joint commands
against measurements and the force over time. Needs no ROS.
"""

from __future__ import annotations

import argparse

__all__ = ["add_parser", "run"]


def add_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the subcommand."""
    parser = subparsers.add_parser("replay", help="summarise and plot a recorded run", description=__doc__)
    parser.add_argument("file", metavar="FILE", help="an .mcap recording written by deploy")
    parser.add_argument("--plot", metavar="PNG", default=None, help="write a plot of commands, measurements, force")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print the summary and write the plot."""
    from hardware_if.replay import load_recording, plot_recording, summarize_recording

    recording = load_recording(args.file)
    for line in summarize_recording(recording).lines():
        print(line)
    if args.plot:
        print(f"plot: {plot_recording(recording, args.plot)}")
    return 0
