"""The ``tissue-retract`` command line.

Each subcommand lives in its own module ``tissue_retract.cli.<name>`` (dashes become underscores) with
``add_arguments(parser)`` and ``run(args) -> int``; its docstring is the subcommand's description. A command
with subcommands of its own (``bench``) has ``COMMANDS``, ``module_name(name)`` and
``add_common_arguments(parser)`` instead. Only the
module of the subcommand being run is imported: the others would cost seconds of torch, numba and
Pinocchio start-up for nothing, and ``--help`` would need every optional extra.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import faulthandler
import importlib
import os
import shlex
import signal
import sys
from collections.abc import Callable, Mapping, Sequence

from psm_control import __version__
from psm_control.errors import TissueRetractError
from tissue_retract.cli._help_text import plain_description
from tissue_retract.cli.bench import TARGETS as BENCH_TARGETS

__all__ = ["SUBCOMMANDS", "add_commands", "build_parser", "main"]

#: Every subcommand and its one-line help, in the order ``--help`` lists them.
SUBCOMMANDS: dict[str, str] = {
    "demo": "run scripted-expert episodes (record demos, video); --kinematics: the FK cross-check",
    "train": "train a policy (DDPG+HER, SQIL, DDPGBC, CoL, DEX) on a task",
    "evaluate": "evaluate a policy on a task",
    "train-perception": "train the endoscope's site estimator on randomized renders",
    "deploy": "deploy a policy to the simulation or a dVRK over ROS 2",
    "robustness": "randomized robustness evaluation of a policy",
    "tune-safety": "sweep safety limits and recommend a configuration",
    "tissue-test": "tension and shear tests of the flap's material, against the closed forms",
    "reproduce": "train and evaluate the paper's Tables 1 and 2",
    "ready-arm": "enable and home the arm and move it to the episodes' start (before calibrate-wrench, a dry run)",
    "calibrate-wrench": "fit the dVRK's force-sensing errors in free space (for deploy --wrench-calibration)",
    "register": "register the grasp site by holding the jaws on it (for deploy --site)",
    "sim-dvrk": "serve the dVRK's CRTK topics from the simulation",
    "replay": "summarise and plot a recorded run",
    "bench": "measurements that print numbers: " + ", ".join(BENCH_TARGETS),
    "safety": "show the effective safety limits",
}


#: Commands that run for long and stop on SIGINT, SIGTERM or SIGHUP with handlers of their own, whatever the
#: disposition or signal mask they inherited (exit 130, 143 or 129; what finished is kept, the child
#: processes they started are stopped first, see :mod:`sim.sweep.stopping`).
STOPPABLE_COMMANDS = ("evaluate", "robustness", "tune-safety", "reproduce", "train", "bench")


def _exit_now(status: int) -> None:
    """End a stopped sweep at once: exit handlers run, the loaded modules (torch) are not torn down.

    Tearing down torch and the simulation took 1.5 s on an idle machine and over 4 s on a loaded one,
    more than a stop may take; what matters at exit (temporary files, the pool's semaphores, output) is
    done by the exit handlers and the flush.
    """
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(status)


def module_name(command: str) -> str:
    """The module that implements a subcommand."""
    return f"{__name__}.{command.replace('-', '_')}"


def add_commands(
    subparsers: argparse._SubParsersAction[argparse.ArgumentParser],
    commands: Mapping[str, str],
    module_of: Callable[[str], str],
    argv: Sequence[str],
    common: Callable[[argparse.ArgumentParser], None] | None = None,
) -> None:
    """Add one subparser per command; import and fill in only the one ``argv`` names.

    Args:
        subparsers: Where the commands go.
        commands: Command name -> one-line help.
        module_of: The module implementing a command (``add_arguments`` and ``run``).
        argv: The arguments after the parent command; the first that is not an option names the command.
        common: Adds the options every one of these commands takes.
    """
    chosen = next((i for i, a in enumerate(argv) if not a.startswith("-")), None)
    for name, summary in commands.items():
        if chosen is None or name != argv[chosen]:
            subparsers.add_parser(name, help=summary)
            continue
        module = importlib.import_module(module_of(name))
        parser = subparsers.add_parser(
            name,
            help=summary,
            description=plain_description(module.__doc__),
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        if common is not None:
            common(parser)
        children = getattr(module, "COMMANDS", None)
        if children is None:
            module.add_arguments(parser)
            parser.set_defaults(func=module.run)
        else:
            nested = parser.add_subparsers(dest=f"{name}_command", metavar="COMMAND", required=True)
            add_commands(nested, children, module.module_name, argv[chosen + 1 :], module.add_common_arguments)


def build_parser(argv: Sequence[str] = ()) -> argparse.ArgumentParser:
    """Return the argument parser, with the arguments of the subcommand ``argv`` names."""
    parser = argparse.ArgumentParser(
        prog="tissue-retract",
        description="Sim-to-real control stack for autonomous soft-tissue retraction with the dVRK PSM.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    add_commands(subparsers, SUBCOMMANDS, module_name, argv)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``tissue-retract``."""
    # A crash in native code (ROS, DDS, physics) then prints every thread's Python stack before the exit;
    # called in-process with a stderr that has no file descriptor (captured output), there is nowhere to.
    with contextlib.suppress(OSError, ValueError):
        faulthandler.enable()
    arguments = sys.argv[1:] if argv is None else argv
    parser = build_parser(arguments)
    args = parser.parse_args(arguments)
    if args.command is None:
        parser.print_help()
        return 2
    args.command_line = shlex.join(["tissue-retract", *arguments])  # for reports: what exactly ran
    stopping: contextlib.AbstractContextManager[None] = contextlib.nullcontext()
    if args.command in STOPPABLE_COMMANDS:
        from sim.sweep.stopping import stop_signals  # these commands load the simulation anyway

        stopping = stop_signals()
    try:
        with stopping:
            return int(args.func(args))
    except TissueRetractError as e:
        print(f"tissue-retract {args.command}: error: {e}", file=sys.stderr)
        return 1
    except OSError as e:  # a file the user named could not be read or written (disk full, permissions)
        print(f"tissue-retract {args.command}: error: {e.strerror or e}: {e.filename or ''}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as e:
        print(f"tissue-retract {args.command}: interrupted", file=sys.stderr)
        status = 128 + int(getattr(e, "signum", signal.SIGINT))  # 130 for Ctrl-C, 143 for SIGTERM, 129 for SIGHUP
        if args.command in STOPPABLE_COMMANDS:
            _exit_now(status)
        return status
