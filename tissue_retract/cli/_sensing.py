"""The ``--force-sensing`` option and the run-start warning it may bring (``safety.force_bound``)."""

from __future__ import annotations

import argparse
import sys

from sim.force_sensing import SENSING_NAMES

__all__ = ["add_force_sensing_argument", "announce"]


def add_force_sensing_argument(parser: argparse.ArgumentParser, *, note: str = "") -> None:
    """``--force-sensing {ideal,dvrk,dvrk-calibrated}``: what the filter and the policy sense of the force.

    ``note`` is added to the help (for deploy: the option is the simulation's; a dVRK senses its console's).
    """
    parser.add_argument(
        "--force-sensing",
        choices=SENSING_NAMES,
        default="ideal",
        help="what the safety filter and the policy sense of the tissue force: ideal (the exact force, the "
        "default), dvrk (the console's measured_cf from motor currents, no gravity or friction model) or "
        "dvrk-calibrated (after calibrate-wrench); the true force is recorded either way" + note,
    )


def announce(warning: str) -> None:
    """Print a run's force-sensing warning once, on stderr (nothing for '')."""
    if warning:
        print(warning, file=sys.stderr, flush=True)
