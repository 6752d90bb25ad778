"""Options shared by the commands that talk to a dVRK console: its domain and how far discovery reaches."""

from __future__ import annotations

import argparse
import os

from hardware_if.common.network import apply_local_ros_env, environment_domain_id, run_domain_id
from tissue_retract.cli._checks import float_in, int_in

__all__ = [
    "add_bench_domain_argument",
    "add_console_arguments",
    "apply_console_arguments",
    "bench_domain_id",
    "point_argument",
]


def add_console_arguments(parser: argparse.ArgumentParser, *, network_help: str) -> None:
    """``--domain-id`` and ``--network``."""
    parser.add_argument(
        "--domain-id",
        type=int_in(0, 232),
        default=environment_domain_id(),
        help="ROS_DOMAIN_ID, 0-232 (default: $ROS_DOMAIN_ID or 0)",
    )
    parser.add_argument("--network", action="store_true", help=network_help)


def apply_console_arguments(args: argparse.Namespace) -> None:
    """Set the ROS environment the options ask for; call before rclpy is imported (Fast DDS reads it then)."""
    if args.network:
        os.environ["ROS_DOMAIN_ID"] = str(args.domain_id)
    else:
        apply_local_ros_env(args.domain_id)


def add_bench_domain_argument(parser: argparse.ArgumentParser) -> None:
    """``--domain-id`` of a bench that starts its own consoles: loopback only, by default a domain of its own.

    Not ``$ROS_DOMAIN_ID``'s default of a console's commands: a bench must not command a console a user runs.
    """
    parser.add_argument(
        "--domain-id",
        type=int_in(1, 101),
        default=None,
        help="ROS_DOMAIN_ID of the run's loopback traffic, 1-101 (default: one of its own, from the process id)",
    )


def bench_domain_id(args: argparse.Namespace) -> int:
    """The bench's domain (``--domain-id`` or one of its own), with the loopback-only settings applied."""
    domain_id = int(args.domain_id) if args.domain_id is not None else run_domain_id()
    apply_local_ros_env(domain_id)
    return domain_id


def point_argument(parser: argparse.ArgumentParser | argparse._MutuallyExclusiveGroup, flag: str, help: str) -> None:
    """An ``X Y Z`` option in metres in ``<arm>_base``, each coordinate in [-1, 1]."""
    parser.add_argument(flag, type=float_in(-1.0, 1.0), nargs=3, metavar=("X", "Y", "Z"), default=None, help=help)
