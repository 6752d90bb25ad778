"""Command values checked as they are parsed: each names the option, the value and what is allowed.

argparse reports a refused value as ``error: argument --seeds: ...`` with status 2 before anything runs.
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable, Iterable
from pathlib import Path

from psm_control.errors import ConfigurationError, OutputFileError
from psm_control.inputs import check_output_path
from psm_control.outputs import special_file_kind

__all__ = ["MAX_EPISODES", "MAX_SEED", "MAX_TRIALS", "check_out_folder", "float_in", "int_in", "output_file"]

#: Largest episode seed: environment seeds are ``seed * 100000 + i`` and must stay below 2**32.
MAX_SEED = 40_000
#: Most episodes one command runs (a few days of simulation on one core).
MAX_EPISODES = 100_000
#: Most trials of one sweep (robustness or tune-safety), grid products included.
MAX_TRIALS = 100_000


def int_in(low: int, high: int) -> Callable[[str], int]:
    """An argparse type: an integer in ``[low, high]``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{text!r} is not allowed: expected an integer in [{low}, {high}]"
            ) from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"{value} is not allowed: expected an integer in [{low}, {high}]")
        return value

    return parse


def float_in(low: float, high: float, *, open_low: bool = False) -> Callable[[str], float]:
    """An argparse type: a finite number in ``[low, high]`` (``(low, high]`` with ``open_low``)."""
    interval = f"{'(' if open_low else '['}{low:g}, {high:g}]"

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not allowed: expected a number in {interval}") from None
        inside = math.isfinite(value) and (value > low if open_low else value >= low) and value <= high
        if not inside:
            raise argparse.ArgumentTypeError(f"{text} is not allowed: expected a finite number in {interval}")
        return value

    return parse


def output_file(field: str) -> Callable[[str], Path]:
    """An argparse type: a file the command writes when it is done, checked before it starts, so that a path
    it cannot write does not lose the work (:func:`psm_control.inputs.check_output_path`)."""

    def parse(text: str) -> Path:
        try:
            return check_output_path(text, field)
        except ConfigurationError as e:
            raise argparse.ArgumentTypeError(str(e)) from None

    return parse


def check_out_folder(
    out: Path, outputs: Iterable[str], inputs: Iterable[str | Path | None], field: str = "--out", make: bool = True
) -> None:
    """Make an output folder, refusing a file, an unwritable folder, or one where an output replaces an input.

    A device, a FIFO, a socket (or a symlink to one) is refused as the folder and as any of its ``outputs``;
    ``make=False`` checks without making the folder (for a command with two folders to check first).

    Raises:
        ConfigurationError: Naming ``field`` (the option) and what is wrong (the input it would overwrite).
    """
    kind = special_file_kind(out)
    if kind != "folder" and (kind is not None or out.exists()):
        raise OutputFileError(field, str(out), f"a folder (this is a {kind or 'file'})")
    names = set(outputs)
    for name in sorted(names):
        inside = special_file_kind(out / name)
        if inside is not None:
            raise OutputFileError(field, str(out), f"a folder whose {name} is a regular file or new (it is a {inside})")
    for given in inputs:
        if given is None or not Path(given).is_file():
            continue
        source = Path(given).resolve()
        if source.parent == out.resolve() and (source.name in names or source.suffix == ".png"):
            raise ConfigurationError(field, str(out), f"a folder whose outputs do not replace the input {str(given)!r}")
    if not make:
        return
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ConfigurationError(field, str(out), f"a folder that can be created ({e.strerror or e})") from e
    if not os.access(out, os.W_OK):
        raise ConfigurationError(field, str(out), "a writable folder")
