"""Fitting a calibration of the dVRK's force sensing: the arm's own efforts, identified in free space.

With nothing touching the instrument every joint effort the console reports is error: the links' and the
instrument's gravity against the counterweight, their inertia, friction and offsets. Real PSMs' logs show
all of them (the console's estimate is off by 9 N RMS on a fast excitation, most of it inertia and link
gravity), and they are linear in parameters (:class:`psm_control.effort_model.EffortRegressor`:
Pinocchio's joint torque regressor for the rigid body, plus friction and offsets per joint). So a free-space
log identifies them by least squares, each joint's rows weighed by the spread of its efforts (newtons on
the insertion, newton-metres elsewhere), on the columns the log can identify
(:func:`~psm_control.effort_model.independent_columns`).

Accelerations come from the logged velocities, filtered forwards and backwards (a second-order Butterworth at
:data:`CUTOFF_HZ`, no lag) and differentiated; the filtered velocities feed the friction terms too.

The residual on a held-out log is what the calibrated force can still be off by: its largest at the speeds a
retraction reaches (:data:`RETRACTION_TIP_SPEED_M_S`), times 1.25, is
:attr:`WrenchCalibration.error_bound_with_acceleration_n`. A deploy takes the force from single
``measured_js`` messages, without an acceleration, and the arm's inertia is large: on the public logs'
PSM, the chain's acceleration limits (10 rad/s^2 on the outer joints, 1 m/s^2 on the insertion) reflect to
tens of newtons at the tip. So the bound the filter uses, :attr:`WrenchCalibration.error_bound_n`, adds the
largest tip force the fitted inertia gives at the chain's acceleration limits over the held-out poses.

The rigid body's dynamic columns (inertia, Coriolis) are kept only where the held-out log supports them:
a fit without them is made too, and it is the calibration when the dynamic columns lower the held-out error
by less than :data:`DYNAMICS_GAIN` (an arm whose logs show no inertia; least squares would otherwise fit
the noise with inertial parameters, and the allowance above would then be that noise at the chain's
acceleration limits). Its bound is then only as good as the held-out log's accelerations.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.signal import butter, filtfilt

from hardware_if.wrench.calibration import WrenchCalibration
from hardware_if.wrench.joint_logs import JointLog, JointLogError
from psm_control.effort_model import independent_columns, shared_regressor
from psm_control.errors import ConfigurationError
from psm_control.robot import PsmModel
from safety.config import SafetyConfig

__all__ = [
    "CUTOFF_HZ",
    "DEPTH_BINS_M",
    "MIN_IMPROVEMENT",
    "RETRACTION_TIP_SPEED_M_S",
    "SPEED_BINS_M_S",
    "FreeSpaceError",
    "PreparedLog",
    "check_calibration",
    "fit_calibration",
    "inertia_allowance_n",
    "prepare_log",
    "unimproved",
]

#: Cut-off of the zero-phase filter on logged velocities [Hz] (WPI's identification filtered at 5.4 Hz).
CUTOFF_HZ = 4.0
#: The calibration's error bound over its largest held-out error at retraction speeds.
_BOUND_MARGIN = 1.25
#: Tool-tip speed up to which a retraction moves [m/s]. A full policy action moves the tip 5 mm along each
#: axis (``SafetyConfig.max_step_m``) per 10 Hz policy step: at most sqrt(3) x 0.05 = 0.087 m/s, below this.
#: The public excitation logs run at 0.25-0.42 m/s; only their samples up to this speed set the bound.
RETRACTION_TIP_SPEED_M_S = 0.1
#: Lowest relative drop of the held-out RMS error for which the rigid body's dynamic columns are kept.
DYNAMICS_GAIN = 0.1
#: Insertion-depth bins of the free-space error [m] and tip-speed bins [m/s].
DEPTH_BINS_M = (0.0, 0.08, 0.11, 0.14, 0.17, 0.20, 0.30)
SPEED_BINS_M_S = (0.0, 0.05, 0.1, 0.2, 0.3, 0.5, math.inf)
#: Samples with the tool closer to the RCM are left out [m]: the dVRK's SafeDistanceFromRCM (45 mm).
MIN_INSERTION_M = 0.045
#: How much lower a calibration's held-out free-space RMS error must be than the console's own before it is
#: written: a fit that removes less than a third of the error has fitted something other than the arm's
#: own dynamics (a load in the jaws, an arm away from the excitation's start, a scene touching the tool),
#: and a deploy would trust its bound at poses it never saw. On a fresh sim-dvrk the fit is 18-21x lower;
#: on the public PSM logs 2.5-9x.
MIN_IMPROVEMENT = 1.5


@dataclass(frozen=True)
class PreparedLog:
    """A joint log with what the fit and the check need, per sample.

    Attributes:
        log: The log.
        qd: Filtered velocities (N, 6).
        qdd: Accelerations (N, 6).
        projector: The console's ``pinv(J^T)`` force rows (N, 3, 6).
        insertion_m: Insertion depth (N,) [m].
        tip_speed_m_s: Tool-tip speed (N,) [m/s].
        rows: The regressor (N, 6, columns), with and without accelerations (``rows_static``).
    """

    log: JointLog
    qd: np.ndarray
    qdd: np.ndarray
    projector: np.ndarray
    insertion_m: np.ndarray
    tip_speed_m_s: np.ndarray
    rows: np.ndarray
    rows_static: np.ndarray

    @property
    def joint_mask(self) -> np.ndarray:
        """The joints the log carries (6,) (the three-joint logs have no wrist)."""
        mask = np.zeros(6, dtype=bool)
        mask[: self.log.joints] = True
        return mask


def prepare_log(log: JointLog, cutoff_hz: float = CUTOFF_HZ) -> PreparedLog:
    """Filter, differentiate and compute the regressor and the console's projection of every sample."""
    rate = log.rate_hz
    b, a = butter(2, min(cutoff_hz, 0.4 * rate) / (rate / 2.0))
    qd = filtfilt(b, a, log.qd, axis=0)
    qdd = np.gradient(qd, log.t_s, axis=0)
    regressor = shared_regressor()
    configuration = PsmModel().configuration()
    projector, speed = np.zeros((len(log.q), 3, 6)), np.zeros(len(log.q))
    rows, rows_static = [], []
    zero = np.zeros(6)
    mask = np.zeros(6)
    mask[: log.joints] = 1.0
    for k, q in enumerate(log.q):
        configuration.update(q)
        jacobian = configuration.base_jacobian()
        projector[k] = np.linalg.pinv(jacobian.T, rcond=1e-4)[:3]
        speed[k] = float(np.linalg.norm(jacobian[:3] @ log.qd[k]))
        rows.append(regressor.rows(q, qd[k], qdd[k]) * mask[:, None])
        rows_static.append(regressor.rows(q, qd[k], zero) * mask[:, None])
    # The console's estimate near the RCM is a pseudo-inverse of a nearly singular Jacobian (thousands of
    # newtons on the public logs' homing moves), where the dVRK refuses Cartesian control anyway.
    keep = log.q[:, 2] >= MIN_INSERTION_M
    if not np.any(keep):
        raise JointLogError(log.source, f"samples with the insertion at {MIN_INSERTION_M} m or more")
    kept = dataclasses.replace(log, t_s=log.t_s[keep], q=log.q[keep], qd=log.qd[keep], effort=log.effort[keep])
    return PreparedLog(
        kept,
        qd[keep],
        qdd[keep],
        projector[keep],
        log.q[keep, 2].copy(),
        speed[keep],
        np.stack(rows)[keep],
        np.stack(rows_static)[keep],
    )


@dataclass(frozen=True)
class FreeSpaceError:
    """The free-space force error of the console's estimate and of a calibration on some logs.

    Attributes:
        before_n: The console's error per sample (N,) [N].
        after_n: The calibrated error per sample, accelerations from the log (N,) [N].
        after_live_n: ... without accelerations, as a deploy computes it (N,) [N].
        insertion_m: Insertion depth per sample [m].
        tip_speed_m_s: Tool-tip speed per sample [m/s].
    """

    before_n: np.ndarray
    after_n: np.ndarray
    after_live_n: np.ndarray
    insertion_m: np.ndarray
    tip_speed_m_s: np.ndarray

    @staticmethod
    def _rms(values: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.square(values)))) if len(values) else math.nan

    def retraction_max_n(self) -> float:
        """The largest calibrated error (accelerations from the log) at retraction speeds [N]."""
        slow = self.tip_speed_m_s <= RETRACTION_TIP_SPEED_M_S
        if not np.any(slow):
            slow = np.ones_like(slow)  # a log with no slow samples: its whole error
        return float(self.after_n[slow].max())

    def _bins(self, values: np.ndarray, edges: Sequence[float], key: str) -> list[dict[str, Any]]:
        out = []
        for low, high in itertools.pairwise(edges):
            inside = (values >= low) & (values < high)
            if not np.any(inside):
                continue
            out.append(
                {
                    key: [low, high if math.isfinite(high) else None],
                    "samples": int(inside.sum()),
                    "rms_before_n": self._rms(self.before_n[inside]),
                    "max_before_n": float(self.before_n[inside].max()),
                    "rms_after_n": self._rms(self.after_n[inside]),
                    "max_after_n": float(self.after_n[inside].max()),
                }
            )
        return out

    def summary(self) -> dict[str, Any]:
        """Overall and binned figures (the ``--check --json`` file)."""
        return {
            "samples": len(self.before_n),
            "rms_before_n": self._rms(self.before_n),
            "max_before_n": float(self.before_n.max()),
            "rms_after_n": self._rms(self.after_n),
            "max_after_n": float(self.after_n.max()),
            "rms_after_without_acceleration_n": self._rms(self.after_live_n),
            "max_after_retraction_speed_n": self.retraction_max_n(),
            "retraction_tip_speed_m_s": RETRACTION_TIP_SPEED_M_S,
            "by_depth": self._bins(self.insertion_m, DEPTH_BINS_M, "insertion_m"),
            "by_speed": self._bins(self.tip_speed_m_s, SPEED_BINS_M_S, "tip_speed_m_s"),
        }


def _free_space_error(parameters: np.ndarray, logs: Sequence[PreparedLog]) -> FreeSpaceError:
    before: list[np.ndarray] = []
    after: list[np.ndarray] = []
    live: list[np.ndarray] = []
    for p in logs:
        effort = p.log.effort * p.joint_mask
        before.append(np.linalg.norm(np.einsum("kij,kj->ki", p.projector, effort), axis=1))
        for rows, out in ((p.rows, after), (p.rows_static, live)):
            residual = effort - rows @ parameters
            out.append(np.linalg.norm(np.einsum("kij,kj->ki", p.projector, residual), axis=1))
    return FreeSpaceError(
        np.concatenate(before),
        np.concatenate(after),
        np.concatenate(live),
        np.concatenate([p.insertion_m for p in logs]),
        np.concatenate([p.tip_speed_m_s for p in logs]),
    )


def check_calibration(calibration: WrenchCalibration, logs: Sequence[PreparedLog]) -> FreeSpaceError:
    """The free-space error of the console's estimate and of ``calibration`` on ``logs``."""
    return _free_space_error(calibration.parameter_vector(), logs)


def inertia_allowance_n(
    parameters: np.ndarray, logs: Sequence[PreparedLog], accelerations: np.ndarray | None = None, every: int = 20
) -> float:
    """The largest tip force the fitted inertia gives at the chain's acceleration limits, over the logs' poses [N].

    The inertial efforts are linear in the accelerations, so the largest over the box of accelerations is at
    one of its 64 corners.
    """
    limits = SafetyConfig().acceleration if accelerations is None else np.asarray(accelerations, dtype=float)
    corners = np.array(np.meshgrid(*[[-1.0, 1.0]] * 6, indexing="ij")).reshape(6, -1) * limits[:, None]
    regressor, zero, worst = shared_regressor(), np.zeros(6), 0.0
    for p in logs:
        for k in range(0, len(p.log.q), every):
            q = p.log.q[k]
            rest = regressor.rows(q, zero, zero) @ parameters
            columns = np.column_stack([regressor.rows(q, zero, np.eye(6)[j]) @ parameters - rest for j in range(6)])
            worst = max(worst, float(np.linalg.norm(p.projector[k] @ columns @ corners, axis=0).max()))
    return worst


#: Ridge strengths tried, relative to the mean of the normalised normal matrix's diagonal (1), and the number of
#: contiguous blocks of the fit's samples the strength is cross-validated on.
_RIDGE_STRENGTHS = (0.0, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2)
_FOLDS = 5


def _ridge_solver(design: np.ndarray, target: np.ndarray) -> Callable[[float], np.ndarray]:
    """Ridge least squares on unit-norm columns (a strength means the same for every column's units), one SVD
    for every strength: the solver returns the parameters for a strength (0: plain least squares)."""
    norms = np.maximum(np.linalg.norm(design, axis=0), 1e-12)
    u, s, vt = np.linalg.svd(design / norms, full_matrices=False)
    projected = u.T @ target
    kept = s > s[0] * 1e-10

    def solve(strength: float) -> np.ndarray:
        gains = np.divide(s, s * s + strength, out=np.zeros_like(s), where=kept)
        return np.asarray((vt.T @ (gains * projected)) / norms)

    return solve


def _ridge_strength(design: np.ndarray, target: np.ndarray) -> float:
    """The ridge strength with the least error on held-out contiguous blocks of the fit's own rows.

    Why ridge: the effort regressor has dozens of columns, and a short excitation (the live calibration's 20 s
    about one pose) excites some of them little. Least squares gives those large values that fit the
    effort's correlated noise and extrapolate badly to the next motion; a penalty chosen on blocks the fit did
    not see keeps only what generalises. Contiguous blocks, because the noise is correlated in time.
    """
    edges = np.linspace(0, len(target), _FOLDS + 1).astype(int)
    errors = np.zeros(len(_RIDGE_STRENGTHS))
    for start, stop in itertools.pairwise(edges):
        keep = np.ones(len(target), dtype=bool)
        keep[start:stop] = False
        solve = _ridge_solver(design[keep], target[keep])
        for k, strength in enumerate(_RIDGE_STRENGTHS):
            errors[k] += float(np.sum(np.square(design[start:stop] @ solve(strength) - target[start:stop])))
    return _RIDGE_STRENGTHS[int(np.argmin(errors))]


def _solve(design: np.ndarray, target: np.ndarray, samples: int, exclude: int) -> tuple[np.ndarray, np.ndarray]:
    """Ridge least squares (:func:`_ridge_strength`) on the identifiable columns from ``exclude`` on: (their
    indices, the full parameter vector).

    Raises:
        ConfigurationError: Too few samples for the columns.
    """
    columns = exclude + independent_columns(design[:, exclude:])
    if len(target) < 4 * len(columns):
        raise ConfigurationError(
            "samples", samples, f"at least {4 * len(columns) // 6} to fit {len(columns)} parameters"
        )
    chosen = design[:, columns]
    values = _ridge_solver(chosen, target)(_ridge_strength(chosen, target))
    parameters = np.zeros(design.shape[1])
    parameters[columns] = values
    return columns, parameters


def unimproved(calibration: WrenchCalibration) -> str:
    """Why a fitted calibration must not be written (its held-out error not :data:`MIN_IMPROVEMENT` x lower
    than the console's), or "" when it may. A console whose free-space efforts were all zero (an exact force)
    has nothing to improve and may be written, marked as such."""
    before, after = calibration.rms_before_n, calibration.rms_after_n
    if before == 0.0 or after * MIN_IMPROVEMENT <= before:
        return ""
    return (
        f"the fit lowers the held-out free-space force error only from {before:.3f} to {after:.3f} N RMS "
        f"({before / max(after, 1e-12):.2f} x; a calibration must be at least {MIN_IMPROVEMENT:g} x lower): "
        "something other than the arm's own dynamics moved the efforts (tissue or a load in the jaws, the arm "
        "not free to move, or a log of another arm)"
    )


def fit_calibration(
    arm: str, fit: Sequence[PreparedLog], held_out: Sequence[PreparedLog]
) -> tuple[WrenchCalibration, FreeSpaceError]:
    """Fit on free-space logs and check on others (see the module notes).

    Returns:
        The calibration and its free-space error on ``held_out``.

    Raises:
        ConfigurationError: Too few samples to fit, or nothing held out.
    """
    samples = sum(len(p.log.t_s) for p in fit)
    if not held_out:
        raise ConfigurationError("held_out", 0, "at least one log to check the fit on")
    weights = []
    for p in fit:
        spread = np.std(p.log.effort, axis=0)
        weights.append(np.where(p.joint_mask, 1.0 / np.maximum(spread, 1e-3), 0.0))
    design = np.concatenate(
        [(p.rows * w[None, :, None]).reshape(-1, p.rows.shape[2]) for p, w in zip(fit, weights, strict=True)]
    )
    target = np.concatenate([(p.log.effort * w).reshape(-1) for p, w in zip(fit, weights, strict=True)])
    dynamic = shared_regressor().friction_start // 4  # the first columns: the rigid body's inertia and Coriolis
    fits = [_solve(design, target, samples, exclude=0), _solve(design, target, samples, exclude=dynamic)]
    errors = [FreeSpaceError._rms(_free_space_error(parameters, held_out).after_n) for _, parameters in fits]
    with_dynamics = not errors[0] > (1.0 - DYNAMICS_GAIN) * errors[1]
    columns, parameters = fits[0] if with_dynamics else fits[1]
    values = parameters[columns]
    error = _free_space_error(parameters, held_out)
    slow = error.retraction_max_n()
    calibration = WrenchCalibration(
        arm=arm,
        columns=tuple(int(c) for c in columns),
        parameters=tuple(float(v) for v in values),
        error_bound_n=_BOUND_MARGIN * (slow + (inertia_allowance_n(parameters, held_out) if with_dynamics else 0.0)),
        error_bound_with_acceleration_n=_BOUND_MARGIN * slow,
        rms_before_n=FreeSpaceError._rms(error.before_n),
        max_before_n=float(error.before_n.max()),
        rms_after_n=FreeSpaceError._rms(error.after_n),
        max_after_n=float(error.after_n.max()),
        samples=samples,
    )
    return calibration, error
