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

A calibration's bounds are never below what its held-out log showed in the regime each covers (see
:meth:`FreeSpaceError.regimes`), nor below :data:`~hardware_if.wrench.calibration.MIN_BOUND_N`; and a log is
fitted only when it shows an arm moving under its own dynamics
(:func:`~hardware_if.wrench.joint_logs.check_free_space_log`).

Memory does not grow with a log's length: the regressor (338 columns, 16 KB a sample) is made
:data:`CHUNK_SAMPLES` samples at a time and folded into the R factor of a QR decomposition of the weighted
design with its target, one per contiguous block of the ridge's cross-validation (:func:`_fold_factors`). The
R factor is the least-squares problem without its rows (``X = Q R``: same column norms, singular values and
solutions, and the residual of any parameter vector has the same norm), so the fit is the one the whole design
gives, to rounding; unlike the normal equations (``X^T X``) it does not square the design's condition number.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.signal import butter, filtfilt

from hardware_if.wrench.calibration import (
    MIN_BOUND_N,
    RETRACTION_TIP_SPEED_M_S,
    WrenchCalibration,
    bounded_tip_speed,
    within_accelerations,
)
from hardware_if.wrench.joint_logs import MIN_SAMPLES, JointLog, TooFewSamplesError, check_free_space_log
from psm_control.effort_model import independent_columns, shared_regressor
from psm_control.errors import ConfigurationError
from psm_control.robot import PsmModel
from safety.config import SafetyConfig

__all__ = [
    "BOUND_MARGIN",
    "CHUNK_SAMPLES",
    "CUTOFF_HZ",
    "DEPTH_BINS_M",
    "MIN_IMPROVEMENT",
    "MIN_INSERTION_M",
    "MIN_REGIME_SAMPLES",
    "RETRACTION_TIP_SPEED_M_S",
    "SPEED_BINS_M_S",
    "FreeSpaceError",
    "PreparedLog",
    "bound_verdict",
    "check_calibration",
    "coverage_line",
    "covered_acceleration",
    "covered_tip_speed",
    "effort_residuals",
    "fit_calibration",
    "inertia_allowance_n",
    "prepare_log",
    "unimproved",
]

#: Cut-off of the zero-phase filter on logged velocities [Hz] (WPI's identification filtered at 5.4 Hz).
CUTOFF_HZ = 4.0
#: The calibration's error bound over its largest held-out error at retraction speeds.
BOUND_MARGIN = 1.25
#: Fewest held-out samples at retraction speeds whose largest error alone sets the bounds: fewer say little about
#: the error there, and the bounds take the largest held-out error at any speed as well. WPI's full-speed log held
#: out (its last third) has 35, all at one turnaround, whose 1.11 N (a 1.39 N bound) the same path at half speed
#: exceeded 778 times (2.66 N at most); its ``two`` has 278.
MIN_REGIME_SAMPLES = 200
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
#: Samples whose regressor rows are made at a time (16 MB per regressor at 338 columns).
CHUNK_SAMPLES = 1024


@dataclass(frozen=True)
class PreparedLog:
    """A joint log with what the fit and the check need, per sample.

    The regressor is not kept (16 KB a sample): :meth:`regressor` makes it for a part of the log, and
    :meth:`chunks` cuts the log in parts of :data:`CHUNK_SAMPLES`.

    Attributes:
        log: The log.
        qd: Filtered velocities (N, 6).
        qdd: Accelerations (N, 6).
        projector: The console's ``pinv(J^T)`` force rows (N, 3, 6).
        insertion_m: Insertion depth (N,) [m].
        tip_speed_m_s: Tool-tip speed (N,) [m/s].
    """

    log: JointLog
    qd: np.ndarray
    qdd: np.ndarray
    projector: np.ndarray
    insertion_m: np.ndarray
    tip_speed_m_s: np.ndarray

    @property
    def joint_mask(self) -> np.ndarray:
        """The joints the log carries (6,) (the three-joint logs have no wrist)."""
        mask = np.zeros(6, dtype=bool)
        mask[: self.log.joints] = True
        return mask

    def chunks(self) -> Iterator[slice]:
        """The log's samples in consecutive parts of at most :data:`CHUNK_SAMPLES`."""
        for start in range(0, len(self.log.t_s), CHUNK_SAMPLES):
            yield slice(start, min(start + CHUNK_SAMPLES, len(self.log.t_s)))

    def regressor(self, part: slice, acceleration: bool = True) -> np.ndarray:
        """The regressor of the samples in ``part`` (n, 6, columns), zero on joints the log does not carry;
        ``acceleration=False``: with the accelerations left out, as a deploy computes it."""
        regressor, zero = shared_regressor(), np.zeros(6)
        mask = self.joint_mask.astype(float)
        q, qd, qdd = self.log.q[part], self.qd[part], self.qdd[part]
        rows = [regressor.rows(q[k], qd[k], qdd[k] if acceleration else zero) * mask[:, None] for k in range(len(q))]
        return np.stack(rows) if rows else np.zeros((0, 6, regressor.columns))

    def model_efforts(self, parameters: np.ndarray, acceleration: bool = True) -> np.ndarray:
        """The efforts a parameter vector (columns,) gives along the log (N, 6), or several (columns, k): (N, 6, k)."""
        parameters = np.asarray(parameters, dtype=float)
        out = np.zeros((len(self.log.t_s), 6, *parameters.shape[1:]))
        for part in self.chunks():
            out[part] = self.regressor(part, acceleration) @ parameters
        return out


def prepare_log(log: JointLog, cutoff_hz: float = CUTOFF_HZ) -> PreparedLog:
    """Check the log (:func:`~hardware_if.wrench.joint_logs.check_free_space_log`), then filter, differentiate and
    compute the console's projection of every sample.

    Raises:
        JointLogError: A log that does not show an arm moving under its own dynamics, or fewer than
            :data:`~hardware_if.wrench.joint_logs.MIN_SAMPLES` samples away from the RCM (a subclass says which).
    """
    check_free_space_log(log)  # before the filter, which a short or non-finite log would break
    rate = log.rate_hz
    b, a = butter(2, min(cutoff_hz, 0.4 * rate) / (rate / 2.0))
    qd = filtfilt(b, a, log.qd, axis=0)
    qdd = np.gradient(qd, log.t_s, axis=0)
    # The console's estimate near the RCM is a pseudo-inverse of a nearly singular Jacobian (thousands of
    # newtons on the public logs' homing moves), where the dVRK refuses Cartesian control anyway.
    keep = log.q[:, 2] >= MIN_INSERTION_M
    if np.count_nonzero(keep) < MIN_SAMPLES:
        raise TooFewSamplesError(
            log.source,
            f"at least {MIN_SAMPLES} samples with the insertion at {MIN_INSERTION_M} m or more "
            f"(this log has {np.count_nonzero(keep)})",
        )
    kept = dataclasses.replace(log, t_s=log.t_s[keep], q=log.q[keep], qd=log.qd[keep], effort=log.effort[keep])
    configuration = PsmModel().configuration()
    projector, speed = np.zeros((len(kept.q), 3, 6)), np.zeros(len(kept.q))
    for k, q in enumerate(kept.q):
        configuration.update(q)
        jacobian = configuration.base_jacobian()
        projector[k] = np.linalg.pinv(jacobian.T, rcond=1e-4)[:3]
        speed[k] = float(np.linalg.norm(jacobian[:3] @ kept.qd[k]))
    return PreparedLog(kept, qd[keep], qdd[keep], projector, kept.q[:, 2].copy(), speed)


@dataclass(frozen=True)
class FreeSpaceError:
    """The free-space force error of the console's estimate and of a calibration on some logs.

    Attributes:
        before_n: The console's error per sample (N,) [N].
        after_n: The calibrated error per sample, accelerations from the log (N,) [N].
        after_live_n: ... without accelerations, as a deploy computes it (N,) [N].
        insertion_m: Insertion depth per sample [m].
        tip_speed_m_s: Tool-tip speed per sample [m/s].
        within_acceleration_limits: Whether each sample's joint accelerations are within the control chain's
            acceleration limits (``SafetyConfig().acceleration``), as a deploy's are (N,).
        within_covered_acceleration: Whether each sample's joint accelerations are within those the calibration
            was fitted on (:attr:`WrenchCalibration.covered_acceleration`) (N,).
        bounded_tip_speed_m_s: The fastest tip speed ``error_bound_n`` bounds
            (:attr:`WrenchCalibration.bounded_tip_speed_m_s`) [m/s].
    """

    before_n: np.ndarray
    after_n: np.ndarray
    after_live_n: np.ndarray
    insertion_m: np.ndarray
    tip_speed_m_s: np.ndarray
    within_acceleration_limits: np.ndarray
    within_covered_acceleration: np.ndarray
    bounded_tip_speed_m_s: float

    @staticmethod
    def _rms(values: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.square(values)))) if len(values) else math.nan

    def retraction_max_n(self) -> float:
        """The largest calibrated error (accelerations from the log) at retraction speeds, within the covered
        accelerations [N]; a log with no such sample: :meth:`covered_max_n`."""
        inside = self.in_retraction_regime
        return float(self.after_n[inside].max()) if np.any(inside) else self.covered_max_n()

    def covered_max_n(self) -> float:
        """The largest calibrated error within the covered accelerations at any speed [N]; a log with no such
        sample: the largest of all."""
        inside = self.within_covered_acceleration
        return float(self.after_n[inside].max()) if np.any(inside) else float(self.after_n.max())

    @property
    def in_retraction_regime(self) -> np.ndarray:
        """The samples ``error_bound_with_acceleration_n`` bounds: at retraction speeds, their accelerations within
        those the calibration was fitted on (N,)."""
        return (self.tip_speed_m_s <= RETRACTION_TIP_SPEED_M_S) & self.within_covered_acceleration

    def regimes(self) -> dict[str, tuple[np.ndarray, np.ndarray, str]]:
        """What each of a calibration's bounds covers, by the bound's name: (the samples inside its regime (N,)
        bool, the calibrated error it bounds there (N,) [N], the regime in words).

        ``error_bound_with_acceleration_n`` bounds the error with the acceleration known at tip speeds up to
        :data:`RETRACTION_TIP_SPEED_M_S` and joint accelerations within those the calibration was fitted on (its
        inertia is known up to them); ``error_bound_n`` the error without the acceleration (a deploy's) at every
        tip speed up to :attr:`bounded_tip_speed_m_s` (the fastest its logs reached), while the joints accelerate
        within the chain's limits (its inertia allowance is taken at those limits). Faster, nothing is bounded.
        """
        fast = self.bounded_tip_speed_m_s
        return {
            "error_bound_with_acceleration_n": (
                self.in_retraction_regime,
                self.after_n,
                f"tip speed <= {RETRACTION_TIP_SPEED_M_S:g} m/s and joint accelerations within those fitted on, the "
                "acceleration known",
            ),
            "error_bound_n": (
                (self.tip_speed_m_s <= fast) & self.within_acceleration_limits,
                self.after_live_n,
                f"tip speed <= {fast:.3g} m/s and joint accelerations within the chain's limits, without the "
                "acceleration",
            ),
        }

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
            "samples_beyond_covered_acceleration": int(np.count_nonzero(~self.within_covered_acceleration)),
            "by_depth": self._bins(self.insertion_m, DEPTH_BINS_M, "insertion_m"),
            "by_speed": self._bins(self.tip_speed_m_s, SPEED_BINS_M_S, "tip_speed_m_s"),
        }


def coverage_line(logs: Sequence[PreparedLog]) -> str:
    """Which tip speeds, insertions and outer-joint poses the logs cover, in words (and any log whose rate came
    from its own motion, :attr:`~hardware_if.wrench.joint_logs.JointLog.rate_note`): a calibration's figures
    describe these, not the motions beyond them."""
    speed = np.concatenate([p.tip_speed_m_s for p in logs])
    q = np.concatenate([p.log.q for p in logs])
    line = (
        f"tip speeds {np.percentile(speed, 1):.3f}-{speed.max():.3f} m/s (1 % below the first), "
        f"insertion {100 * q[:, 2].min():.1f}-{100 * q[:, 2].max():.1f} cm, yaw {q[:, 0].min():+.2f} to "
        f"{q[:, 0].max():+.2f} rad, pitch {q[:, 1].min():+.2f} to {q[:, 1].max():+.2f} rad"
    )
    notes = [f"{Path(p.log.source).name} read at {p.log.rate_note}" for p in logs if p.log.rate_note]
    return line + "".join(f"; {note}" for note in notes)


def covered_acceleration(logs: Sequence[PreparedLog]) -> tuple[float | None, ...]:
    """Per joint, the largest acceleration magnitude of the logs (None on a joint none of them carries)."""
    out: list[float | None] = []
    for j in range(6):
        carried = [float(np.abs(p.qdd[:, j]).max()) for p in logs if p.joint_mask[j] and len(p.qdd)]
        out.append(max(carried) if carried else None)
    return tuple(out)


def covered_tip_speed(logs: Sequence[PreparedLog]) -> float:
    """The fastest tool-tip speed of the logs [m/s]."""
    return max(float(p.tip_speed_m_s.max()) for p in logs if len(p.tip_speed_m_s))


def _free_space_errors(
    parameters: np.ndarray,
    logs: Sequence[PreparedLog],
    covered: tuple[float | None, ...] | None,
    bounded_tip_speed_m_s: float,
) -> list[FreeSpaceError]:
    """The free-space error of each parameter vector (the columns of ``parameters``, (columns, k)) on ``logs``,
    in one pass over the logs' regressors, a chunk at a time; ``covered``: the accelerations per joint the
    calibration was fitted on, which bound the retraction regime (None: every acceleration);
    ``bounded_tip_speed_m_s``: the fastest tip speed ``error_bound_n`` bounds."""
    k = parameters.shape[1]
    before: list[np.ndarray] = []
    after: list[np.ndarray] = []
    live: list[np.ndarray] = []
    within: list[np.ndarray] = []
    known: list[np.ndarray] = []
    limits = SafetyConfig().acceleration
    for p in logs:
        effort = p.log.effort * p.joint_mask
        before.append(np.linalg.norm(np.einsum("kij,kj->ki", p.projector, effort), axis=1))
        within.append(np.all(np.abs(p.qdd) <= limits, axis=1))
        known.append(within_accelerations(covered, p.qdd * p.joint_mask))
        for acceleration, out in ((True, after), (False, live)):
            errors = np.zeros((len(effort), k))
            for part in p.chunks():
                residual = effort[part][:, :, None] - p.regressor(part, acceleration) @ parameters
                errors[part] = np.linalg.norm(np.einsum("kij,kjm->kim", p.projector[part], residual), axis=1)
            out.append(errors)
    shared = [np.concatenate(x) for x in (before, [p.insertion_m for p in logs], [p.tip_speed_m_s for p in logs])]
    after_all, live_all, within_all = np.concatenate(after), np.concatenate(live), np.concatenate(within)
    known_all = np.concatenate(known)
    return [
        FreeSpaceError(
            shared[0],
            after_all[:, m],
            live_all[:, m],
            shared[1],
            shared[2],
            within_all,
            known_all,
            bounded_tip_speed_m_s,
        )
        for m in range(k)
    ]


def effort_residuals(calibration: WrenchCalibration, logs: Sequence[PreparedLog]) -> list[np.ndarray]:
    """Per log, the calibrated effort error of each sample and joint (N, 6) [N m, N on the insertion], the
    accelerations from the log: what ``--check``'s tare (:mod:`~hardware_if.wrench.drift`) and friction
    (:mod:`~hardware_if.wrench.friction_shift`) figures read, computed once for both."""
    parameters = calibration.parameter_vector()
    return [p.log.effort * p.joint_mask - p.model_efforts(parameters) for p in logs]


def check_calibration(calibration: WrenchCalibration, logs: Sequence[PreparedLog]) -> FreeSpaceError:
    """The free-space error of the console's estimate and of ``calibration`` on ``logs``."""
    parameters = calibration.parameter_vector()[:, None]
    covered, fast = calibration.covered_acceleration, calibration.bounded_tip_speed_m_s
    return _free_space_errors(parameters, logs, covered, fast)[0]


def bound_verdict(calibration: WrenchCalibration, error: FreeSpaceError) -> dict[str, Any]:
    """Whether a calibration's bounds held on logs (``calibrate-wrench --check``'s verdict).

    Each bound is judged on the samples inside its regime (:meth:`FreeSpaceError.regimes`); the others are
    counted, not judged. The bounds held when at least one sample was judged and none exceeded its bound.

    Returns:
        ``bound_n`` (the file's bounds by name), ``bound_held``, and by bound: ``regime``, ``regime_samples``,
        ``outside_regime_samples``, ``max_in_regime_n`` (None with no sample inside) and ``exceeding_samples``.
    """
    out: dict[str, Any] = {
        "bound_n": {},
        "regime": {},
        "regime_samples": {},
        "outside_regime_samples": {},
        "max_in_regime_n": {},
        "exceeding_samples": {},
    }
    for name, (inside, values, words) in error.regimes().items():
        bound = float(getattr(calibration, name))
        judged = values[inside]
        out["bound_n"][name] = bound
        out["regime"][name] = words
        out["regime_samples"][name] = int(inside.sum())
        out["outside_regime_samples"][name] = int(len(inside) - inside.sum())
        out["max_in_regime_n"][name] = float(judged.max()) if len(judged) else None
        out["exceeding_samples"][name] = int(np.count_nonzero(judged > bound))
    judged_any = any(out["regime_samples"].values())
    out["bound_held"] = bool(judged_any and not any(out["exceeding_samples"].values()))
    return out


def verdict_line(verdict: dict[str, Any]) -> str:
    """The verdict of :func:`bound_verdict` in one line."""
    parts = []
    for name, bound in verdict["bound_n"].items():
        inside, largest = verdict["regime_samples"][name], verdict["max_in_regime_n"][name]
        seen = f"largest {largest:.2f} N over {inside} samples" if largest is not None else "no sample inside"
        over = verdict["exceeding_samples"][name]
        parts.append(
            f"{name} {bound:.2f} N: {seen}{f', {over} above it' if over else ''} "
            f"({verdict['outside_regime_samples'][name]} outside its regime, not judged)"
        )
    if verdict["bound_held"]:
        head = "bound held: the calibrated error stayed within the file's bounds"
    elif not any(verdict["regime_samples"].values()):
        head = "BOUND NOT JUDGED: no sample of the logs is inside the regimes the file bounds"
    else:
        head = "BOUND EXCEEDED: the calibrated error went above the file's bounds"
    return f"{head}; " + "; ".join(parts)


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


def _stacked_factor(factors: Sequence[np.ndarray]) -> np.ndarray:
    """The R factor of the rows the ``factors`` (R factors of blocks of rows) stand for."""
    return np.asarray(np.linalg.qr(np.vstack(factors), mode="r"))


def _fold_factors(fit: Sequence[PreparedLog], weights: Sequence[np.ndarray]) -> tuple[list[np.ndarray], int]:
    """The R factors of the weighted design with its target as the last column, ``[X | y]``, one per contiguous
    block of rows the ridge's strength is cross-validated on (:data:`_FOLDS` blocks of the rows in log, sample and
    joint order), each folded in a chunk of :data:`CHUNK_SAMPLES` samples at a time; and the number of rows."""
    rows_total = 6 * sum(len(p.log.t_s) for p in fit)
    edges = np.linspace(0, rows_total, _FOLDS + 1).astype(int)
    factors: list[np.ndarray | None] = [None] * _FOLDS
    offset = 0
    for p, w in zip(fit, weights, strict=True):
        for part in p.chunks():
            rows = p.regressor(part)
            block = np.column_stack(
                [(rows * w[None, :, None]).reshape(-1, rows.shape[2]), (p.log.effort[part] * w).reshape(-1)]
            )
            for fold in range(_FOLDS):
                low, high = max(edges[fold], offset), min(edges[fold + 1], offset + len(block))
                if low < high:
                    piece = block[low - offset : high - offset]
                    previous = factors[fold]
                    factors[fold] = _stacked_factor([piece] if previous is None else [previous, piece])
            offset += len(block)
    return [f for f in factors if f is not None], rows_total


def _ridge_strength(factors: Sequence[np.ndarray], columns: np.ndarray) -> float:
    """The ridge strength with the least error on held-out contiguous blocks of the fit's own rows (``factors``:
    one R factor of ``[X | y]`` per block, :func:`_fold_factors`), on the design's ``columns``.

    Why ridge: the effort regressor has dozens of columns, and a short excitation (the live calibration's 20 s
    about one pose) excites some of them little. Least squares gives those large values that fit the
    effort's correlated noise and extrapolate badly to the next motion; a penalty chosen on blocks the fit did
    not see keeps only what generalises. Contiguous blocks, because the noise is correlated in time.
    """
    target = factors[0].shape[1] - 1
    errors = np.zeros(len(_RIDGE_STRENGTHS))
    for held in range(len(factors)):
        kept = _stacked_factor([f for k, f in enumerate(factors) if k != held])
        solve = _ridge_solver(kept[:, columns], kept[:, target])
        block = factors[held]
        for k, strength in enumerate(_RIDGE_STRENGTHS):
            errors[k] += float(np.sum(np.square(block[:, columns] @ solve(strength) - block[:, target])))
    return _RIDGE_STRENGTHS[int(np.argmin(errors))]


def _solve(factors: Sequence[np.ndarray], rows_total: int, samples: int, exclude: int) -> tuple[np.ndarray, np.ndarray]:
    """Ridge least squares (:func:`_ridge_strength`) on the identifiable columns from ``exclude`` on: (their
    indices, the full parameter vector).

    Raises:
        ConfigurationError: Too few samples for the columns.
    """
    whole = _stacked_factor(factors)
    target = whole.shape[1] - 1
    columns = exclude + independent_columns(whole[:, exclude:target])
    if rows_total < 4 * len(columns):
        raise ConfigurationError(
            "samples", samples, f"at least {4 * len(columns) // 6} to fit {len(columns)} parameters"
        )
    values = _ridge_solver(whole[:, columns], whole[:, target])(_ridge_strength(factors, columns))
    parameters = np.zeros(target)
    parameters[columns] = values
    return columns, parameters


def unimproved(calibration: WrenchCalibration) -> str:
    """Why a fitted calibration must not be written (its held-out error not :data:`MIN_IMPROVEMENT` x lower
    than the console's, or no console error at all), or "" when it may."""
    before, after = calibration.rms_before_n, calibration.rms_after_n
    if not before > 0.0:
        return (
            "the console's held-out free-space force error is 0 N: its efforts show no arm dynamics (a console "
            "that reports the exact force needs no calibration)"
        )
    if after * MIN_IMPROVEMENT <= before:
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

    The bounds: ``error_bound_with_acceleration_n`` is 1.25 x the largest held-out error at retraction speeds (at
    any speed too when fewer than :data:`MIN_REGIME_SAMPLES` held-out samples are that slow);
    ``error_bound_n`` 1.25 x that plus the inertia allowance, and at least the largest held-out error without
    the acceleration in its regime (:meth:`FreeSpaceError.regimes`), the largest held-out error at any speed
    and the other bound; both at least :data:`~hardware_if.wrench.calibration.MIN_BOUND_N`.

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
    factors, rows_total = _fold_factors(fit, weights)
    dynamic = shared_regressor().friction_start // 4  # the first columns: the rigid body's inertia and Coriolis
    fits = [_solve(factors, rows_total, samples, exclude=0), _solve(factors, rows_total, samples, exclude=dynamic)]
    # Only what the fit saw is bounded: its inertia is known up to the accelerations of its own logs.
    coverage, fastest = covered_acceleration(fit), covered_tip_speed(fit)
    candidates = _free_space_errors(
        np.column_stack([parameters for _, parameters in fits]),
        held_out,
        coverage,
        bounded_tip_speed(fastest),
    )
    errors = [FreeSpaceError._rms(candidate.after_n) for candidate in candidates]
    with_dynamics = not errors[0] > (1.0 - DYNAMICS_GAIN) * errors[1]
    columns, parameters = fits[0] if with_dynamics else fits[1]
    error = candidates[0] if with_dynamics else candidates[1]
    values = parameters[columns]
    slow = error.retraction_max_n()
    shown_slow = int(np.count_nonzero(error.in_retraction_regime))
    basis = slow if shown_slow >= MIN_REGIME_SAMPLES else max(slow, error.covered_max_n())
    with_acceleration = max(BOUND_MARGIN * basis, MIN_BOUND_N)
    inside, live, _ = error.regimes()["error_bound_n"]
    shown = [float(error.after_n.max()), with_acceleration] + ([float(live[inside].max())] if np.any(inside) else [])
    allowance = inertia_allowance_n(parameters, held_out) if with_dynamics else 0.0
    calibration = WrenchCalibration(
        arm=arm,
        columns=tuple(int(c) for c in columns),
        parameters=tuple(float(v) for v in values),
        error_bound_n=max(BOUND_MARGIN * (basis + allowance), *shown),
        error_bound_with_acceleration_n=with_acceleration,
        rms_before_n=FreeSpaceError._rms(error.before_n),
        max_before_n=float(error.before_n.max()),
        rms_after_n=FreeSpaceError._rms(error.after_n),
        max_after_n=float(error.after_n.max()),
        samples=samples,
        max_after_retraction_speed_n=slow,
        max_after_without_acceleration_n=float(live[inside].max()) if np.any(inside) else None,
        covered_acceleration=coverage,
        covered_tip_speed_m_s=fastest,
    )
    return calibration, error
