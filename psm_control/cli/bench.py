"""``tissue-retract bench TARGET``: speed measurements that print numbers.

Each target lives in its own module ``psm_control.cli.bench_<target>`` with ``add_arguments(parser)``
and ``run(args) -> int``.
"""

from __future__ import annotations

import argparse
import importlib

__all__ = ["TARGETS", "add_parser", "run"]

#: Benchmark targets of the interface.
TARGETS = {
    "env": "environment steps/s (state-only and rendering)",
    "chain": "control-chain tick latency against a naive reference",
    "ros": "servo_jp -> measured_js round trip over loopback ROS 2",
}


def _module(target: str) -> str:
    return f"psm_control.cli.bench_{target}"


def add_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the subcommand and its targets."""
    parser = subparsers.add_parser("bench", help="measure speed (env, chain, ros)", description=__doc__)
    targets = parser.add_subparsers(dest="target", metavar="TARGET", required=True)
    for name, summary in TARGETS.items():
        sub = targets.add_parser(name, help=summary, description=summary)
        sub.add_argument("--json", metavar="FILE", default=None, help="also write the results as JSON")
        importlib.import_module(_module(name)).add_arguments(sub)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run one benchmark target."""
    return int(importlib.import_module(_module(args.target)).run(args))
