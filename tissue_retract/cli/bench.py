"""``tissue-retract bench TARGET``: measurements that print numbers (speed, faults, the force bound).

Each target lives in its own module ``tissue_retract.cli.bench_<target>`` with ``add_arguments(parser)``
and ``run(args) -> int``; every target takes ``--json FILE``.
"""

from __future__ import annotations

import argparse

from tissue_retract.cli._checks import output_file

__all__ = ["COMMANDS", "TARGETS", "add_common_arguments", "module_name"]

#: Benchmark targets and their one-line help.
TARGETS: dict[str, str] = {
    "env": "environment steps/s (state-only and rendering)",
    "chain": "control-chain tick latency against a naive reference",
    "ros": "servo_jp -> measured_js round trip over loopback ROS 2",
    "rehearsal": "the shipped policy deployed through ROS against sim-dvrk beside the same policy in-process",
    "faults": "the deploy's fault matrix: fault -> exit status, hold reason, what the recording kept",
    "safety": "the force bound: adversarial and shipped policies x tasks x force presets x tissue stiffness",
    "sensing": "the force-sensing models' free-space error beside real PSMs' logs, by depth and speed",
    "train": "the default recipe's wall time to a policy confirmed on 100 unseen episodes, per task",
}

#: The targets are this command's own subcommands.
COMMANDS = TARGETS


def module_name(target: str) -> str:
    """The module that implements a benchmark target."""
    return f"{__package__}.bench_{target}"


def add_common_arguments(parser: argparse.ArgumentParser) -> None:
    """The options every target takes."""
    parser.add_argument(
        "--json", metavar="FILE", type=output_file("--json"), default=None, help="also write the results as JSON"
    )
