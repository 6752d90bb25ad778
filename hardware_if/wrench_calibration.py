"""The old path of the wrench calibration, kept for user scripts; the project imports from its room.

Its names now live in :mod:`hardware_if.wrench.calibration` and :mod:`hardware_if.wrench.fit`.
"""

from hardware_if.wrench.calibration import EXACT_SENSING, MAX_FILE_BYTES, WrenchCalibration, read_calibration
from hardware_if.wrench.fit import (
    CUTOFF_HZ,
    DEPTH_BINS_M,
    MIN_IMPROVEMENT,
    RETRACTION_TIP_SPEED_M_S,
    SPEED_BINS_M_S,
    FreeSpaceError,
    PreparedLog,
    check_calibration,
    fit_calibration,
    inertia_allowance_n,
    prepare_log,
    unimproved,
)

__all__ = [
    "CUTOFF_HZ",
    "DEPTH_BINS_M",
    "EXACT_SENSING",
    "MAX_FILE_BYTES",
    "MIN_IMPROVEMENT",
    "RETRACTION_TIP_SPEED_M_S",
    "SPEED_BINS_M_S",
    "FreeSpaceError",
    "PreparedLog",
    "WrenchCalibration",
    "check_calibration",
    "fit_calibration",
    "inertia_allowance_n",
    "prepare_log",
    "read_calibration",
    "unimproved",
]
