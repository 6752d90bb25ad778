"""Whether a joint's friction moved since the calibration was fitted: its calibrated effort error by direction.

A fit's friction columns (Coulomb, viscous and an offset per joint) take the level the arm's friction had in the
logs it was fitted on. A PSM's friction is not fixed: it changes with temperature and wear, and from one session
to the next. Where it changed, a log checked against the file shows it as an effort error that follows the
direction of motion, of one sign moving forward and of the other moving back, at every speed beyond the
friction's band; no fit of one log's friction removes it from another's.

:func:`friction_shift` gives it per joint: the mean calibrated effort error (accelerations from the log) over the
samples moving forward and over those moving back, beyond :data:`MOVING_SPEED` (the effort model's Coulomb band),
and half their difference, the friction the log has beyond the file's (positive: more), with the
force it makes at the tool tip (the console's ``pinv(J^T)`` column of the joint, median over those samples).
``calibrate-wrench --check`` prints it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from hardware_if.wrench.fit import PreparedLog
from hardware_if.wrench.joint_logs import JOINT_NAMES
from psm_control.effort_model import shared_regressor

__all__ = ["MOVING_SPEED", "friction_line", "friction_shift"]

#: Speed beyond which a joint counts as moving one way [rad/s, m/s on the insertion]: the effort model's Coulomb
#: band (its friction column is three quarters of its full value there), far above a joint's velocity noise.
MOVING_SPEED = shared_regressor().coulomb_speed


def _mean(values: np.ndarray) -> float | None:
    return float(values.mean()) if len(values) else None


def friction_shift(logs: Sequence[PreparedLog], residuals: Sequence[np.ndarray]) -> list[dict[str, Any]]:
    """Per arm joint, the calibrated effort error by direction of motion on ``logs`` (see the module notes);
    ``residuals``: their calibrated effort errors (:func:`~hardware_if.wrench.fit.effort_residuals`).

    Returns:
        One entry per joint: ``joint``, ``unit`` (of the efforts: ``N m``, ``N`` on the insertion),
        ``samples_forward`` and ``samples_back``, ``mean_forward`` and ``mean_back`` (the mean error moving each
        way), ``shift`` (half their difference: the friction beyond the file's) and ``tip_force_n`` (the force
        ``shift`` makes at the tool tip [N]); the figures are None on a joint the logs do not carry or that does
        not move both ways.
    """
    forward: list[list[np.ndarray]] = [[] for _ in JOINT_NAMES]
    back: list[list[np.ndarray]] = [[] for _ in JOINT_NAMES]
    reach: list[list[np.ndarray]] = [[] for _ in JOINT_NAMES]  # the tip force of a unit effort on the joint
    for p, residual in zip(logs, residuals, strict=True):
        for joint in np.flatnonzero(p.joint_mask):
            velocity = p.qd[:, joint]
            ahead, behind = velocity > MOVING_SPEED, velocity < -MOVING_SPEED
            forward[joint].append(residual[ahead, joint])
            back[joint].append(residual[behind, joint])
            reach[joint].append(np.linalg.norm(p.projector[ahead | behind, :, joint], axis=1))
    out = []
    for index, name in enumerate(JOINT_NAMES):
        moving_forward = np.concatenate(forward[index]) if forward[index] else np.zeros(0)
        moving_back = np.concatenate(back[index]) if back[index] else np.zeros(0)
        mean_forward, mean_back = _mean(moving_forward), _mean(moving_back)
        shift = None if mean_forward is None or mean_back is None else (mean_forward - mean_back) / 2.0
        out.append(
            {
                "joint": name,
                "unit": "N" if name == "insertion" else "N m",
                "samples_forward": len(moving_forward),
                "samples_back": len(moving_back),
                "mean_forward": mean_forward,
                "mean_back": mean_back,
                "shift": shift,
                "tip_force_n": None if shift is None else abs(shift) * float(np.median(np.concatenate(reach[index]))),
            }
        )
    return out


def friction_line(rows: Sequence[dict[str, Any]]) -> str:
    """:func:`friction_shift`'s figures in one line."""
    parts = [
        f"{row['joint']} {row['shift']:+.3f} {row['unit']} ({row['tip_force_n']:.2f} N at the tip)"
        for row in rows
        if row["shift"] is not None
    ]
    if not parts:
        return "friction against the file's: not measured, no joint of the logs moves both ways"
    return (
        "friction against the file's, by joint (half the difference of the mean effort error moving forward and "
        "back; positive: more than in the logs it was fitted on): "
        + ", ".join(parts)
        + " (a PSM's friction changes with temperature, wear and between sessions: fit on logs of the session, "
        "and at the speeds, the calibration is used in)"
    )
