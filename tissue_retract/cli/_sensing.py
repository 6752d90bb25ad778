"""The ``--force-sensing`` option and the run-start warning it may bring (``safety.force_bound``); a sweep's
``--wrench-calibration``: the sensing of the user's own calibrated arm."""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hardware_if.wrench.calibration import WrenchCalibration, read_calibration
from psm_control.errors import ConfigurationError
from sim.force_sensing import SENSING_NAMES, calibrated_sensing, error_bound_n, sensing_params
from sim.sweep import file_digest

__all__ = ["SweepSensing", "add_force_sensing_argument", "add_wrench_calibration_argument", "announce", "sweep_sensing"]

#: The preset a calibration file stands for: the only ``--force-sensing`` it goes with.
CALIBRATED = "dvrk-calibrated"


def add_force_sensing_argument(
    parser: argparse.ArgumentParser, *, note: str = "", default: str | None = "ideal"
) -> None:
    """``--force-sensing {ideal,dvrk,dvrk-calibrated}``: what the filter and the policy sense of the force.

    ``note`` is added to the help (for deploy: the option is the simulation's; a dVRK senses its console's).
    ``default`` None lets a command tell the option left out (ideal) from given (a sweep's
    ``--wrench-calibration`` goes with dvrk-calibrated only).
    """
    parser.add_argument(
        "--force-sensing",
        choices=SENSING_NAMES,
        default=default,
        help="what the safety filter and the policy sense of the tissue force: ideal (the exact force, the "
        "default), dvrk (the console's measured_cf from motor currents, no gravity or friction model) or "
        "dvrk-calibrated (after calibrate-wrench); the true force is recorded either way" + note,
    )


def add_wrench_calibration_argument(parser: argparse.ArgumentParser) -> None:
    """A sweep's ``--wrench-calibration F.json``: the sensing of the arm that file calibrated."""
    parser.add_argument(
        "--wrench-calibration",
        metavar="F.json",
        default=None,
        help="a calibrate-wrench file (as deploy --target dvrk takes): the sweep's sensing is then a calibrated "
        "dVRK whose force is off by at most the file's error_bound_with_acceleration_n, the bound a calibrated "
        "deploy trusts (the dvrk-calibrated model's errors scaled to it; implies --force-sensing "
        "dvrk-calibrated, and no other)",
    )


@dataclass(frozen=True)
class SweepSensing:
    """What a sweep's filter and policy sense of the force.

    Attributes:
        name: The preset (``dvrk-calibrated`` with a calibration file).
        calibration_file: The ``--wrench-calibration`` file, as given; None: the preset's own bound.
        calibration: The calibration read from it.
        calibration_sha256: The file's SHA-256.
    """

    name: str
    calibration_file: str | None = None
    calibration: WrenchCalibration | None = None
    calibration_sha256: str | None = None

    @property
    def error_n(self) -> float:
        """The error bound the filter trusts the force to [N] (0 for ``ideal``): the file's, or the preset's."""
        if self.calibration is not None:
            return self.calibration.error_bound_with_acceleration_n
        return error_bound_n(sensing_params(self.name))

    @property
    def calibrated_error_n(self) -> float | None:
        """The file's bound the workers' sensing is scaled to [N]; None without a file."""
        return self.error_n if self.calibration is not None else None

    @property
    def label(self) -> str:
        """What the warnings call the sensing."""
        if self.calibration is None:
            return f"{self.name} force sensing"
        return f"{self.name} force sensing of {self.calibration_file}, fitted on {self.calibration.origin}"

    def describe(self) -> str:
        """The report's line: the preset, and the file, its bounds and where it was fitted."""
        if self.calibration is None:
            return self.name if self.name == "ideal" else f"{self.name}, error bound {self.error_n:.2f} N"
        c = self.calibration
        return (
            f"{self.name} from {self.calibration_file} (fitted on {c.origin}): the filter trusts the force to its "
            f"error_bound_with_acceleration_n {c.error_bound_with_acceleration_n:.2f} N, as a calibrated deploy "
            f"does (error_bound_n {c.error_bound_n:.2f} N without the acceleration; held out: {c.rms_before_n:.2f} "
            f"-> {c.rms_after_n:.2f} N RMS); the simulated sensing's errors are the dvrk-calibrated model's scaled "
            "to that bound"
        )

    def calibration_record(self) -> dict[str, Any] | None:
        """The calibration as ``summary.json`` and ``sweep.json`` keep it (None without a file)."""
        if self.calibration is None:
            return None
        c = self.calibration
        return {
            "file": self.calibration_file,
            "sha256": self.calibration_sha256,
            "arm": c.arm,
            "console": c.console,
            "sensing": c.sensing,
            "fitted_on": c.origin,
            "error_bound_with_acceleration_n": c.error_bound_with_acceleration_n,
            "error_bound_n": c.error_bound_n,
            "trusted_bound": "error_bound_with_acceleration_n",
            "rms_before_n": c.rms_before_n,
            "rms_after_n": c.rms_after_n,
        }


def sweep_sensing(force_sensing: str | None, wrench_calibration: str | Path | None) -> SweepSensing:
    """A sweep's sensing from its ``--force-sensing`` (None: left out) and ``--wrench-calibration``.

    Raises:
        ConfigurationError: ``--force-sensing`` other than dvrk-calibrated with a calibration file, or a file
            :func:`~hardware_if.wrench.calibration.read_calibration` refuses (named).
    """
    if wrench_calibration is None:
        return SweepSensing(force_sensing or "ideal")
    if force_sensing not in (None, CALIBRATED):
        raise ConfigurationError(
            "--force-sensing",
            force_sensing,
            f"{CALIBRATED} (or left out) with --wrench-calibration: a calibration file is a calibrated dVRK's "
            "sensing; leave --wrench-calibration out to sweep the preset",
        )
    calibration = read_calibration(wrench_calibration)
    calibrated_sensing(calibration.error_bound_with_acceleration_n)  # refused here, by name, if the model cannot
    return SweepSensing(CALIBRATED, str(wrench_calibration), calibration, file_digest(wrench_calibration))


def announce(warning: str) -> None:
    """Print a run's force-sensing warning once, on stderr (nothing for '')."""
    if warning:
        print(warning, file=sys.stderr, flush=True)
