"""A fitted calibration of the dVRK's force sensing, and its file: what a deploy takes the force with.

:class:`WrenchCalibration` holds the parameters of the arm's own efforts (gravity, inertia, friction,
offsets) that :mod:`hardware_if.wrench.fit` identified on free-space logs, and the error bounds the fit
checked; the client removes those efforts from the console's joint efforts and computes the force from
what is left. :func:`read_calibration` refuses a file that is not one, not self-consistent, or not for
the arm and console it is used with.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from psm_control.effort_model import shared_regressor
from psm_control.errors import ConfigurationError, InputFileError
from psm_control.inputs import check_regular_file
from psm_control.outputs import write_atomic
from psm_control.robot import PsmConfiguration
from safety.config import SafetyConfig
from safety.force_bound import SensingRegime
from sim.force_sensing import console_force

__all__ = [
    "EXACT_SENSING",
    "MAX_FILE_BYTES",
    "MIN_BOUND_N",
    "RETRACTION_TIP_SPEED_M_S",
    "WrenchCalibration",
    "bounded_tip_speed",
    "read_calibration",
    "within_accelerations",
]

#: Largest calibration file read [bytes] (1 MiB): one holds a few hundred numbers, a few kilobytes.
MAX_FILE_BYTES = 1024 * 1024
#: ``sensing`` of a calibration fitted where the console's free-space efforts were all zero: a console that
#: reports the exact force (``sim-dvrk --wrench ideal``), or one that sends no efforts.
EXACT_SENSING = "ideal"
#: Smallest error bound a calibration may have [N]: no fit of a real PSM's motor currents is exact. The least any
#: calibration left on a public PSM log held out is 1.72 N at most (radiang's three-joint logs, 0.38 N RMS), and a
#: dedicated 3-axis tip sensor's RMS error is 0.15 N; a bound below this says a log showed no sensor at all.
MIN_BOUND_N = 0.5
#: Tool-tip speed up to which a retraction moves [m/s]. A full policy action moves the tip 5 mm along each
#: axis (``SafetyConfig.max_step_m``) per 10 Hz policy step: at most sqrt(3) x 0.05 = 0.087 m/s, below this.
#: The public excitation logs run at 0.25-0.42 m/s; only their samples up to this speed set the tight bound.
RETRACTION_TIP_SPEED_M_S = 0.1


@dataclass(frozen=True)
class WrenchCalibration:
    """A fitted force-sensing calibration (the JSON file ``calibrate-wrench`` writes).

    Attributes:
        arm: The arm it was fitted on.
        columns: The regressor's columns it identified (:class:`~psm_control.effort_model.EffortRegressor`).
        parameters: Their values.
        error_bound_n: What the calibrated force may still be off by without an acceleration (a deploy's) [N]:
            1.25 x (the largest held-out free-space error at retraction speeds + the inertia allowance).
        error_bound_with_acceleration_n: ... with the acceleration known [N]: 1.25 x the largest held-out
            free-space error at retraction speeds; a live calibration's is at least 1.25 x that error as a
            deploy computes it, with the chain's commanded acceleration.
        rms_before_n: Held-out free-space force error of the console's estimate, RMS [N].
        max_before_n: ... and its largest [N].
        rms_after_n: Held-out free-space force error after the calibration, RMS [N].
        max_after_n: ... and its largest [N].
        samples: Samples fitted on.
        sensing: What it was fitted on: ``measured_js`` (a live console's joint efforts), ``ideal`` (a live
            console whose free-space efforts were all zero: one that reports the exact force, as
            ``sim-dvrk --wrench ideal`` does, or sends no efforts), or ``logs: <layouts>`` (offline).
        console: The console of the arm it was fitted on: ``sim-dvrk``, ``dvrk`` or ``unknown``.
        max_after_retraction_speed_n: The largest held-out error (the acceleration known) at retraction speeds,
            which ``error_bound_with_acceleration_n`` covers [N]; None in files of earlier versions.
        max_after_without_acceleration_n: The largest held-out error without the acceleration in the regime
            ``error_bound_n`` covers (retraction speeds, accelerations within the chain's limits) [N]; None in
            files of earlier versions or when the held-out log had no sample there.
        covered_acceleration: Per joint, the largest acceleration magnitude of the logs it was fitted on (rad/s^2;
            m/s^2 on the insertion), None on a joint the logs do not carry: the inertia it identified is known up
            to these, so ``error_bound_with_acceleration_n`` bounds only motions whose accelerations are within
            them (:meth:`covers`); beyond, ``error_bound_n`` (the inertia taken as unknown up to the chain's
            limits). None in files of earlier versions: every acceleration covered.
        covered_tip_speed_m_s: The fastest tool-tip speed of the logs it was fitted on [m/s]: ``error_bound_n``
            bounds motions up to it (``error_bound_with_acceleration_n`` only up to
            :data:`RETRACTION_TIP_SPEED_M_S`), and a deploy does not trust the force beyond it. None in files of
            earlier versions: ``error_bound_n`` was judged only up to the retraction speeds, and is trusted only there.
    """

    arm: str
    columns: tuple[int, ...]
    parameters: tuple[float, ...]
    error_bound_n: float
    error_bound_with_acceleration_n: float
    rms_before_n: float
    max_before_n: float
    rms_after_n: float
    max_after_n: float
    samples: int
    sensing: str = "measured_js"
    console: str = "unknown"
    max_after_retraction_speed_n: float | None = None
    max_after_without_acceleration_n: float | None = None
    covered_acceleration: tuple[float | None, ...] | None = None
    covered_tip_speed_m_s: float | None = None

    def covers(self, qdd: np.ndarray) -> np.ndarray:
        """Whether each acceleration (6,) or each row of (N, 6) is within :attr:`covered_acceleration`."""
        return within_accelerations(self.covered_acceleration, qdd)

    @property
    def bounded_tip_speed_m_s(self) -> float:
        """The fastest tool-tip speed :attr:`error_bound_n` bounds [m/s]: :attr:`covered_tip_speed_m_s`, at least the
        retraction speeds; only those for a file of an earlier version."""
        return bounded_tip_speed(self.covered_tip_speed_m_s)

    def sensing_regime(self) -> SensingRegime:
        """Where :attr:`error_bound_with_acceleration_n` holds, for the safety filter; :attr:`error_bound_n` beyond it
        up to :attr:`bounded_tip_speed_m_s`; faster, no bound."""
        return SensingRegime(
            _acceleration_limits(self.covered_acceleration),
            self.error_bound_n,
            RETRACTION_TIP_SPEED_M_S,
            self.bounded_tip_speed_m_s,
        )

    def regime_words(self) -> str:
        """The motions :attr:`error_bound_with_acceleration_n` bounds, for a user."""
        speed = f"tip speeds up to {RETRACTION_TIP_SPEED_M_S:g} m/s"
        if self.covered_acceleration is None:
            return f"{speed} and any acceleration (a file of an earlier version records none)"
        units = ["rad/s^2", "rad/s^2", "m/s^2", "rad/s^2", "rad/s^2", "rad/s^2"]
        shown = [f"{v:.3g} {u}" for v, u in zip(self.covered_acceleration, units, strict=True) if v is not None]
        return f"{speed} and joint accelerations within those it was fitted on (" + ", ".join(shown) + ")"

    @property
    def origin(self) -> str:
        """Where it was fitted, for a user: ``PSM1 on sim-dvrk, measured_js``."""
        console = "an unknown console" if self.console == "unknown" else self.console
        return f"{self.arm} on {console}, {self.sensing}"

    def parameter_vector(self) -> np.ndarray:
        """The parameters on all of the regressor's columns, zero where the calibration identified none."""
        full = np.zeros(shared_regressor().columns)
        full[list(self.columns)] = self.parameters
        return full

    def model_efforts(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray | None = None) -> np.ndarray:
        """The efforts the calibration attributes to the arm itself (6,); no acceleration: its inertia left out."""
        qdd = np.zeros(6) if qdd is None else np.asarray(qdd, dtype=float)
        return np.asarray(
            shared_regressor().rows(np.asarray(q, dtype=float), np.asarray(qd, dtype=float), qdd)
            @ self.parameter_vector()
        )

    def force(
        self, configuration: PsmConfiguration, qd: np.ndarray, efforts: np.ndarray, qdd: np.ndarray | None = None
    ) -> np.ndarray:
        """The calibrated force on the tool (3,) [N], in the configuration's base axes."""
        residual = np.asarray(efforts, dtype=float) - self.model_efforts(configuration.q, qd, qdd)
        return console_force(configuration.base_jacobian(), residual)

    def write(self, path: Path, field: str = "--out") -> None:
        """Write the calibration as JSON, whole or not at all (:func:`psm_control.outputs.write_atomic`)."""
        write_atomic(path, json.dumps({"kind": "wrench_calibration", **asdict(self)}, indent=2) + "\n", field)


def bounded_tip_speed(covered_tip_speed_m_s: float | None) -> float:
    """The fastest tool-tip speed ``error_bound_n`` bounds for logs that reached ``covered_tip_speed_m_s`` [m/s]: that
    speed, at least the retraction speeds (those alone for None, a file of an earlier version)."""
    if covered_tip_speed_m_s is None:
        return RETRACTION_TIP_SPEED_M_S
    return max(covered_tip_speed_m_s, RETRACTION_TIP_SPEED_M_S)


def within_accelerations(covered: tuple[float | None, ...] | None, qdd: np.ndarray) -> np.ndarray:
    """Whether each acceleration (6,) or each row of (N, 6) is within ``covered`` per joint (None: no limit)."""
    magnitude = np.abs(np.asarray(qdd, dtype=float))
    if covered is None:
        return np.ones(magnitude.shape[:-1], dtype=bool)
    return np.asarray(np.all(magnitude <= _acceleration_limits(covered), axis=-1))


def _acceleration_limits(covered: tuple[float | None, ...] | None) -> np.ndarray:
    """``covered`` per joint as an array (6,), inf where nothing limits it (a joint, or a file, without one)."""
    return np.array([math.inf if v is None else v for v in covered or (None,) * 6])


_FIGURES = (
    "error_bound_n",
    "error_bound_with_acceleration_n",
    "rms_before_n",
    "max_before_n",
    "rms_after_n",
    "max_after_n",
)
#: Held-out maxima of the regimes the bounds cover, by the bound each must not be below (absent in older files).
_REGIME_MAXIMA = {
    "max_after_retraction_speed_n": "error_bound_with_acceleration_n",
    "max_after_without_acceleration_n": "error_bound_n",
}


def read_calibration(path: str | Path, arm: str | None = None, *, exact_console: bool = False) -> WrenchCalibration:
    """Read a calibration file, with a named error for anything that is not one, or not one to trust.

    Args:
        path: The file (at most :data:`MAX_FILE_BYTES`).
        arm: The arm it is for; None: any.
        exact_console: Whether it is used where the force is exact (a check on logs); False (a console a
            deploy drives) refuses a calibration fitted on a console that reported the exact force.

    Raises:
        ConfigurationError: Missing, too large, unreadable, not a wrench calibration, an older file without
            the sensing and console it was fitted on, another arm's, a bound below its own held-out error (in
            the regime it covers), below :data:`MIN_BOUND_N` or beyond what the safety filter takes, or fitted on
            exact forces for a console that is not exact.
    """
    field = "--wrench-calibration"
    size = check_regular_file(path, field, max_bytes=2**62).stat().st_size  # a regular file, then its size
    if size > MAX_FILE_BYTES:
        raise InputFileError(
            field, path, f"a file of at most 1 MiB, as calibrate-wrench writes (this one is {size / 2**20:.1f} MiB)"
        )
    try:
        data: Any = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        raise InputFileError(field, path, f"a JSON file calibrate-wrench wrote ({e})") from e
    try:
        if data.get("kind") != "wrench_calibration":
            raise ValueError("not a wrench calibration")
    except (AttributeError, ValueError) as e:
        raise InputFileError(field, path, f"a file calibrate-wrench wrote ({e})") from e
    if "sensing" not in data or "console" not in data:
        raise InputFileError(
            field,
            path,
            "a calibration that records the sensing and the console it was fitted on (this file is from an "
            "earlier calibrate-wrench: re-run calibrate-wrench)",
        )
    try:
        calibration = WrenchCalibration(
            arm=str(data["arm"]),
            columns=tuple(int(c) for c in data["columns"]),
            parameters=tuple(float(p) for p in data["parameters"]),
            **{k: float(data[k]) for k in _FIGURES},
            samples=int(data["samples"]),
            sensing=str(data["sensing"]),
            console=str(data["console"]),
            max_after_retraction_speed_n=_optional_float(data, "max_after_retraction_speed_n"),
            max_after_without_acceleration_n=_optional_float(data, "max_after_without_acceleration_n"),
            covered_acceleration=_optional_accelerations(data),
            covered_tip_speed_m_s=_optional_float(data, "covered_tip_speed_m_s"),
        )
    except (AttributeError, KeyError, TypeError, ValueError) as e:
        raise InputFileError(field, path, f"a file this version of calibrate-wrench wrote ({e})") from e
    _check(calibration, str(path), arm, exact_console)
    return calibration


def _optional_float(data: dict[str, Any], key: str) -> float | None:
    """``data[key]`` as a float, None when it is missing or null (a regime the held-out log did not reach)."""
    if data.get(key) is None:
        return None
    try:
        return float(data[key])
    except (TypeError, ValueError) as e:
        raise ValueError(f"{key}: a number or null ({e})") from None


def _optional_accelerations(data: dict[str, Any]) -> tuple[float | None, ...] | None:
    """``data["covered_acceleration"]``: six numbers or nulls, or None when the file has none."""
    values = data.get("covered_acceleration")
    if values is None:
        return None
    if not isinstance(values, list) or len(values) != 6:
        raise ValueError("covered_acceleration: six numbers (or null for a joint the logs did not carry)")
    return tuple(None if v is None else float(v) for v in values)


def _check(calibration: WrenchCalibration, path: str, arm: str | None, exact_console: bool) -> None:
    """Refuse a calibration that is not self-consistent, or not for this arm and console (see read_calibration)."""
    field = "--wrench-calibration"
    total = shared_regressor().columns
    if len(calibration.parameters) != len(calibration.columns) or not all(0 <= c < total for c in calibration.columns):
        raise InputFileError(field, path, f"one parameter per column, columns 0-{total - 1}")
    if not all(map(math.isfinite, calibration.parameters)):
        raise InputFileError(field, path, "finite parameters")
    for name in (*_FIGURES, *_REGIME_MAXIMA):
        value = getattr(calibration, name)
        if value is not None and not (math.isfinite(value) and value >= 0.0):
            raise InputFileError(field, path, f"a finite, non-negative {name} (this file has {value!r})")
    covered = [v for v in calibration.covered_acceleration or () if v is not None]
    if not all(math.isfinite(v) and v > 0.0 for v in covered):
        raise InputFileError(field, path, f"covered_acceleration: finite and > 0 (this file has {covered!r})")
    speed = calibration.covered_tip_speed_m_s
    if speed is not None and not (math.isfinite(speed) and speed > 0.0):
        raise InputFileError(field, path, f"covered_tip_speed_m_s: finite and > 0 (this file has {speed!r})")
    if arm is not None and calibration.arm != arm:
        raise InputFileError(field, path, f"a calibration of {arm} (this one is {calibration.arm}'s)")
    bound = calibration.error_bound_n
    try:
        SafetyConfig(force_sensing_error_n=bound)
    except ConfigurationError as e:
        raise InputFileError(
            field, path, f"an error_bound_n the safety filter takes, {e.allowed} (this file has {bound:g} N)"
        ) from None
    for name in ("max_after_n", "error_bound_with_acceleration_n"):
        if bound < getattr(calibration, name):
            raise InputFileError(
                field,
                path,
                f"an error_bound_n at least its own {name} (this file has {bound:g} N beside "
                f"{getattr(calibration, name):g} N: the bound contradicts the fit)",
            )
    for name, bound_name in _REGIME_MAXIMA.items():
        shown = getattr(calibration, name)
        if shown is not None and getattr(calibration, bound_name) < shown:
            raise InputFileError(
                field,
                path,
                f"an {bound_name} at least its own held-out {name} (this file has "
                f"{getattr(calibration, bound_name):g} N beside {shown:g} N: the bound is below what its log showed)",
            )
    if calibration.sensing == EXACT_SENSING and not exact_console:
        raise InputFileError(
            field,
            path,
            "a calibration fitted on the console it is used with (this one was fitted where the console's "
            "free-space efforts were all zero, as on sim-dvrk --wrench ideal: it trusts the force to "
            f"{bound:g} N, which holds on no dVRK; re-run calibrate-wrench against this console)",
        )
    for name in ("error_bound_n", "error_bound_with_acceleration_n"):
        if getattr(calibration, name) < MIN_BOUND_N:
            raise InputFileError(
                field,
                path,
                f"an {name} of at least {MIN_BOUND_N:g} N (this file has {getattr(calibration, name):g} N): no "
                "calibration of a real arm's sensing is that exact; a log whose efforts show no arm (an exact "
                "console, a frozen one) made it. Re-run calibrate-wrench",
            )
