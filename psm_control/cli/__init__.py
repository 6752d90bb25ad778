"""The ``tissue-retract`` command line.

Each subcommand lives in its own module ``psm_control.cli.<name>`` (dashes become underscores) with
``add_parser(subparsers)`` and ``run(args) -> int``; modules import their heavy dependencies inside
``run`` so that ``--help`` stays fast. A subcommand whose module is not in this version says so and
exits non-zero: it never prints a made-up result.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys
from collections.abc import Callable

from psm_control import __version__
from psm_control.errors import TissueRetractError

__all__ = ["EXIT_NOT_BUILT", "SUBCOMMANDS", "build_parser", "main"]

#: Exit status of a subcommand that exists in the interface but is not built in this version.
EXIT_NOT_BUILT = 3

#: Every subcommand of the interface, with a one-line summary.
SUBCOMMANDS = {
    "demo": "run the scripted expert in the simulation, record demonstrations or a video; check kinematics",
    "train": "train a policy (DDPG+HER, SQIL, DDPGBC, CoL, DEX) on a task",
    "evaluate": "evaluate a policy through the safety chain",
    "deploy": "deploy a policy to the simulation or a dVRK over ROS 2",
    "robustness": "randomized robustness evaluation of a policy",
    "tune-safety": "sweep safety limits and recommend a configuration",
    "sim-dvrk": "serve the dVRK's CRTK topics from the simulation",
    "replay": "summarise and plot a recorded run",
    "bench": "measure speed (env, chain, ros)",
    "safety": "show the effective safety limits",
}


def module_name(command: str) -> str:
    """The module that implements a subcommand."""
    return f"psm_control.cli.{command.replace('-', '_')}"


def is_built(command: str) -> bool:
    """Whether this version implements a subcommand."""
    return importlib.util.find_spec(module_name(command)) is not None


def _not_built(name: str) -> Callable[[argparse.Namespace], int]:
    def run(args: argparse.Namespace) -> int:
        print(f"tissue-retract {name}: not built in version {__version__} yet.", file=sys.stderr)
        return EXIT_NOT_BUILT

    return run


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="tissue-retract",
        description="Sim-to-real control stack for autonomous soft-tissue retraction with the dVRK PSM.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, summary in SUBCOMMANDS.items():
        if is_built(name):
            importlib.import_module(module_name(name)).add_parser(subparsers)
        else:
            sub = subparsers.add_parser(name, help=f"{summary} (not built yet)", description=summary)
            sub.add_argument("rest", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
            sub.set_defaults(func=_not_built(name))
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
