"""How far a calibration's error moves while the arm moves one way: what a tare at the grasp would leave.

A tare reads the force as zero where the jaws closed and takes the measured force's change from there. It
removes whatever part of the free-space error stays put over a pull (an offset, gravity at the grasp's pose,
friction in the pull's direction), and leaves the error's change over the pull. Whether that change is much
smaller than the error itself decides whether a tare can narrow the bound a force limit keeps to; on a given
arm it is a property of its logs, not of the model.

:func:`error_change` measures it on free-space logs: for each of :data:`CHANGE_LAGS_S`, every pair of samples
that far apart between which the tip stays at retraction speeds with its joint accelerations within those the
calibration was fitted on (the regime of ``error_bound_with_acceleration_n``), and none of the three joints that
move the tip (yaw, pitch, insertion) reverses, as in a pull. ``calibrate-wrench --check`` prints it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from hardware_if.wrench.calibration import WrenchCalibration, within_accelerations
from hardware_if.wrench.fit import RETRACTION_TIP_SPEED_M_S, PreparedLog

__all__ = ["CHANGE_LAGS_S", "REVERSAL_DEADBAND", "change_line", "error_change"]

#: How long after the grasp the error's change is measured [s]: a fifth of a second to a two-second slow pull.
CHANGE_LAGS_S = (0.2, 0.5, 1.0, 2.0)
#: Speed a joint must exceed the other way to count as reversing (yaw, pitch [rad/s]; insertion [m/s]): a joint
#: held still crosses zero with its noise, which is no reversal.
REVERSAL_DEADBAND = np.array([0.01, 0.01, 0.001])


def _reversals(qd: np.ndarray) -> np.ndarray:
    """Whether one of the first three joints reverses at each sample (N,): its velocity beyond the deadband the
    other way from the last time it was beyond it."""
    out = np.zeros(len(qd), dtype=bool)
    for joint, deadband in enumerate(REVERSAL_DEADBAND):
        moving = np.nonzero(np.abs(qd[:, joint]) > deadband)[0]
        signs = np.sign(qd[moving, joint])
        out[moving[1:][signs[1:] != signs[:-1]]] = True
    return out


def _next_break(breaks: np.ndarray) -> np.ndarray:
    """For each sample, the index of the first break after it (N,) (N: none)."""
    at = np.append(np.nonzero(breaks)[0], len(breaks))
    return at[np.searchsorted(at, np.arange(len(breaks)), side="right")]


def error_change(
    calibration: WrenchCalibration, logs: Sequence[PreparedLog], residuals: Sequence[np.ndarray]
) -> list[dict[str, Any]]:
    """The calibrated force error's change over one-directional motion at retraction speeds (see the module notes);
    ``residuals``: the calibrated effort errors of the logs (:func:`~hardware_if.wrench.fit.effort_residuals`).

    Returns:
        Per lag of :data:`CHANGE_LAGS_S`: ``lag_s``, ``pairs`` (samples that far apart within one such stretch),
        ``rms_change_n`` and ``max_change_n`` (of the error vector's change between them [N]: what a tare leaves),
        and ``max_error_n`` (the largest error at those samples [N]: what is left without one); None without pairs.
    """
    changes: dict[float, list[np.ndarray]] = {lag: [] for lag in CHANGE_LAGS_S}
    errors: dict[float, list[np.ndarray]] = {lag: [] for lag in CHANGE_LAGS_S}
    for p, residual in zip(logs, residuals, strict=True):
        error = np.einsum("kij,kj->ki", p.projector, residual)
        inside = (p.tip_speed_m_s <= RETRACTION_TIP_SPEED_M_S) & within_accelerations(
            calibration.covered_acceleration, p.qdd * p.joint_mask
        )
        until = _next_break(~inside | _reversals(p.qd))
        t = p.log.t_s
        for lag in CHANGE_LAGS_S:
            later = np.searchsorted(t, t + lag)
            first = np.nonzero(inside & (later < until))[0]
            second = later[first]
            changes[lag].append(np.linalg.norm(error[second] - error[first], axis=1))
            errors[lag].append(np.maximum(np.linalg.norm(error[first], axis=1), np.linalg.norm(error[second], axis=1)))
    out = []
    for lag in CHANGE_LAGS_S:
        change, error_n = np.concatenate(changes[lag]), np.concatenate(errors[lag])
        some = len(change) > 0
        out.append(
            {
                "lag_s": lag,
                "pairs": len(change),
                "rms_change_n": float(np.sqrt(np.mean(np.square(change)))) if some else None,
                "max_change_n": float(change.max()) if some else None,
                "max_error_n": float(error_n.max()) if some else None,
            }
        )
    return out


def change_line(rows: Sequence[dict[str, Any]]) -> str:
    """:func:`error_change`'s figures in one line."""
    parts = [
        f"{row['lag_s']:g} s: {row['max_change_n']:.2f} N at most ({row['rms_change_n']:.2f} RMS) against "
        f"{row['max_error_n']:.2f} N untared, {row['pairs']} pairs"
        for row in rows
        if row["pairs"]
    ]
    if not parts:
        return (
            "a tare at the grasp: not measured, no stretch of the logs moves one way at retraction speeds for "
            f"{min(CHANGE_LAGS_S):g} s"
        )
    return "a tare at the grasp would leave the error's change over a one-way pull at retraction speeds: " + "; ".join(
        parts
    )
