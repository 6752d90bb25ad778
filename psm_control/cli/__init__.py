"""The ``tissue-retract`` command line.

Each subcommand lives in its own module with ``add_parser(subparsers)`` and ``run(args) -> int``;
modules import their heavy dependencies inside ``run`` so that ``--help`` stays fast. A subcommand
that is not built in this version says so and exits non-zero: it never prints a made-up result.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

from psm_control import __version__
from psm_control.cli import kinematics_demo
from psm_control.errors import TissueRetractError

__all__ = ["build_parser", "main"]

#: Exit status of a subcommand that exists in the interface but is not built in this version.
EXIT_NOT_BUILT = 3

# Subcommands named in the interface whose implementation is not part of this version, with what
# they will do. Each moves to a module of its own when it is built.
_NOT_BUILT = {
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
    kinematics_demo.add_parser(subparsers)
    for name, help_text in _NOT_BUILT.items():
        sub = subparsers.add_parser(name, help=f"{help_text} (not built yet)", description=help_text)
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
