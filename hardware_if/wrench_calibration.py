"""The old path of :mod:`hardware_if.wrench.calibration`, kept for user scripts; the project imports from there."""

from hardware_if.wrench.calibration import (
    CUTOFF_HZ,
    DEPTH_BINS_M,
    EXACT_SENSING,
    MAX_FILE_BYTES,
    MIN_IMPROVEMENT,
    RETRACTION_TIP_SPEED_M_S,
    SPEED_BINS_M_S,
    FreeSpaceError,
    PreparedLog,
    WrenchCalibration,
    check_calibration,
    fit_calibration,
    inertia_allowance_n,
    prepare_log,
    read_calibration,
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
