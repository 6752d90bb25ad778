"""The ``--live`` option that deploy, evaluate and sim-dvrk share."""

from __future__ import annotations

import argparse

from tissue_retract.cli._checks import int_in

__all__ = ["DEFAULT_LIVE_PORT", "add_live_argument"]

#: Foxglove's default WebSocket port.
DEFAULT_LIVE_PORT = 8765


def add_live_argument(parser: argparse.ArgumentParser) -> None:
    """``--live [PORT]``: serve the 3-D scene for the Foxglove app on ws://127.0.0.1:PORT."""
    parser.add_argument(
        "--live",
        type=int_in(0, 65535),
        nargs="?",
        const=DEFAULT_LIVE_PORT,
        default=None,
        metavar="PORT",
        help=f"serve the 3-D scene for the Foxglove app on ws://127.0.0.1:PORT (default {DEFAULT_LIVE_PORT}; 0: free)",
    )
