"""The ``--blind`` options that evaluate and train share: the task as a robot without perception sees it."""

from __future__ import annotations

import argparse

from tissue_retract.cli._checks import float_in

__all__ = ["add_blind_arguments"]


def add_blind_arguments(
    parser: argparse.ArgumentParser, *, blind_help: str, default_mm: float, error_help: str
) -> None:
    """``--blind`` and ``--registration-error-mm MM`` (a distance in [0, 50] mm, ``default_mm`` if not given)."""
    parser.add_argument("--blind", action="store_true", help=f"Tasks I-III: {blind_help}")
    parser.add_argument(
        "--registration-error-mm",
        type=float_in(0.0, 50.0),
        default=default_mm,
        metavar="MM",
        help=f"with --blind: {error_help} [mm] (default: {default_mm:g})",
    )
