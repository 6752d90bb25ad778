"""The ``tissue-retract`` command line.

Each subcommand lives in its own module ``psm_control.cli.<name>`` (dashes become underscores) with
``add_parser(subparsers)`` and ``run(args) -> int``; modules import their heavy dependencies inside
``run`` so that ``--help`` stays fast and works without optional extras (ROS 2, Ray).
"""

from __future__ import annotations

import argparse
import importlib
import sys

from psm_control import __version__
from psm_control.errors import TissueRetractError

__all__ = ["SUBCOMMANDS", "build_parser", "main"]

#: Every subcommand, in the order ``--help`` lists them.
SUBCOMMANDS = (
    "demo",
    "train",
    "evaluate",
    "deploy",
    "robustness",
    "tune-safety",
    "reproduce",
    "sim-dvrk",
    "replay",
    "bench",
    "safety",
)


def module_name(command: str) -> str:
    """The module that implements a subcommand."""
    return f"psm_control.cli.{command.replace('-', '_')}"


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="tissue-retract",
        description="Sim-to-real control stack for autonomous soft-tissue retraction with the dVRK PSM.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in SUBCOMMANDS:
        importlib.import_module(module_name(name)).add_parser(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``tissue-retract``."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    try:
        return int(args.func(args))
    except TissueRetractError as e:
        print(f"tissue-retract {args.command}: error: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"tissue-retract {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
