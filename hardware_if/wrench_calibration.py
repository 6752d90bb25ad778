"""A calibration of the dVRK's force sensing: the efforts the console does not model, fitted and removed.

With no tissue in the jaws every joint effort the console reports is error: the instrument's uncompensated
gravity, Coulomb and viscous friction, an offset. They are linear in a handful of parameters, so a short
trajectory in free space identifies them by least squares (the identification literature's approach:
Wang et al. 2019, arXiv 1902.10875), and the residual on a held-out trajectory is what the calibrated
force can still be off by: the safety filter's error bound (:mod:`safety.force_bound`).

The regressor, per sample (six joint rows):

* gravity of an unknown mass on the shaft, at an unknown distance behind the tip, under an unknown gravity
  direction (the arm's mounting): with ``s`` the shaft's direction (the insertion column of the tip's
  Jacobian) and ``w_i`` the outer joints' angular columns, six columns ``(m g_k)`` and ``(m c g_k)`` for
  the three axes ``k`` of the arm's frame;
* per joint: Coulomb friction ``tanh(qd / 0.01)``, viscous friction ``qd`` and a constant offset.

The cables' hysteresis, the offsets' drift and the current noise are not modelled: they remain, and the
held-out error shows them.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from psm_control.errors import ConfigurationError
from psm_control.robot import PsmConfiguration
from sim.force_sensing import console_force

__all__ = ["WrenchCalibration", "fit_calibration", "read_calibration", "regressor"]

_COULOMB_SPEED = 0.01
#: The calibration's error bound over its largest held-out error: the held-out trajectory is short, and
#: the drift it did not see moves on.
_BOUND_MARGIN = 1.25
_GRAVITY_COLUMNS = 6
_PER_JOINT = 3


def regressor(jacobian: np.ndarray, insertion_m: float, qd: np.ndarray) -> np.ndarray:
    """The (6, 6 + 18) regressor of one sample: efforts = ``regressor @ parameters`` (see the module notes).

    Args:
        jacobian: The tool tip's 6x6 Jacobian in the frame the efforts' gravity is expressed in.
        insertion_m: The insertion joint [m].
        qd: Joint velocities (6,).
    """
    shaft = jacobian[:3, 2]
    rows = np.zeros((6, _GRAVITY_COLUMNS + _PER_JOINT * 6))
    for k in range(3):
        axis = np.zeros(3)
        axis[k] = 1.0
        for joint in (0, 1):
            swing = float(np.cross(jacobian[3:, joint], shaft) @ axis)
            rows[joint, k] = -insertion_m * swing  # m g_k
            rows[joint, 3 + k] = swing  # m c g_k
        rows[2, k] = -float(shaft @ axis)
    for joint in range(6):
        base = _GRAVITY_COLUMNS + _PER_JOINT * joint
        rows[joint, base] = math.tanh(float(qd[joint]) / _COULOMB_SPEED)
        rows[joint, base + 1] = float(qd[joint])
        rows[joint, base + 2] = 1.0
    return rows


@dataclass(frozen=True)
class WrenchCalibration:
    """A fitted force-sensing calibration (the JSON file ``calibrate-wrench`` writes).

    Attributes:
        arm: The arm it was fitted on.
        parameters: The regressor's parameters (24,).
        error_bound_n: What the calibrated force may still be off by [N]: the largest held-out free-space
            error times 1.25.
        rms_before_n: Held-out free-space force error of the console's estimate, RMS [N].
        max_before_n: ... and its largest [N].
        rms_after_n: Held-out free-space force error after the calibration, RMS [N].
        max_after_n: ... and its largest [N].
        samples: Samples fitted on.
    """

    arm: str
    parameters: tuple[float, ...]
    error_bound_n: float
    rms_before_n: float
    max_before_n: float
    rms_after_n: float
    max_after_n: float
    samples: int

    def model_efforts(self, jacobian: np.ndarray, insertion_m: float, qd: np.ndarray) -> np.ndarray:
        """The efforts the calibration attributes to gravity, friction and offsets (6,)."""
        return np.asarray(regressor(jacobian, insertion_m, qd) @ np.asarray(self.parameters))

    def force(self, configuration: PsmConfiguration, qd: np.ndarray, efforts: np.ndarray) -> np.ndarray:
        """The calibrated force on the tool (3,) [N], in the configuration's base axes."""
        jacobian = configuration.base_jacobian()
        residual = np.asarray(efforts, dtype=float) - self.model_efforts(jacobian, configuration.insertion_m, qd)
        return console_force(jacobian, residual)

    def write(self, path: Path) -> None:
        """Write the calibration as JSON."""
        path.write_text(json.dumps({"kind": "wrench_calibration", **asdict(self)}, indent=2) + "\n")


def fit_calibration(
    arm: str,
    fit: list[tuple[np.ndarray, float, np.ndarray, np.ndarray]],
    held_out: list[tuple[np.ndarray, float, np.ndarray, np.ndarray]],
) -> WrenchCalibration:
    """Fit on free-space samples and check on others.

    Args:
        arm: The arm's name.
        fit: ``(jacobian, insertion_m, qd, efforts)`` per sample, no tissue held.
        held_out: Samples of another trajectory, the same way.

    Raises:
        ConfigurationError: Too few samples to fit the parameters.
    """
    columns = _GRAVITY_COLUMNS + _PER_JOINT * 6
    if len(fit) * 6 < 4 * columns or not held_out:
        raise ConfigurationError("samples", len(fit), f"at least {4 * columns // 6} to fit and some held out")
    Y = np.vstack([regressor(J, ins, qd) for J, ins, qd, _ in fit])
    tau = np.concatenate([np.asarray(e, dtype=float) for *_, e in fit])
    # Each joint's rows weighed by its efforts' spread: newtons on the insertion and newton-metres elsewhere.
    scale = np.tile(1.0 / np.maximum(np.std(tau.reshape(-1, 6), axis=0), 1e-6), len(fit))
    parameters, *_ = np.linalg.lstsq(Y * scale[:, None], tau * scale, rcond=None)
    before, after = [], []
    for J, ins, qd, efforts in held_out:
        model = regressor(J, ins, qd) @ parameters
        before.append(float(np.linalg.norm(console_force(J, np.asarray(efforts)))))
        after.append(float(np.linalg.norm(console_force(J, np.asarray(efforts) - model))))
    return WrenchCalibration(
        arm=arm,
        parameters=tuple(float(p) for p in parameters),
        error_bound_n=_BOUND_MARGIN * max(after),
        rms_before_n=float(np.sqrt(np.mean(np.square(before)))),
        max_before_n=max(before),
        rms_after_n=float(np.sqrt(np.mean(np.square(after)))),
        max_after_n=max(after),
        samples=len(fit),
    )


def read_calibration(path: str | Path) -> WrenchCalibration:
    """Read a calibration file, with a named error for anything that is not one.

    Raises:
        ConfigurationError: Missing, unreadable or not a wrench calibration.
    """
    try:
        data: Any = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        raise ConfigurationError("--wrench-calibration", str(path), f"a JSON file calibrate-wrench wrote ({e})") from e
    columns = _GRAVITY_COLUMNS + _PER_JOINT * 6
    try:
        if data.get("kind") != "wrench_calibration":
            raise ValueError("not a wrench calibration")
        calibration = WrenchCalibration(
            arm=str(data["arm"]),
            parameters=tuple(float(p) for p in data["parameters"]),
            **{
                k: float(data[k])
                for k in ("error_bound_n", "rms_before_n", "max_before_n", "rms_after_n", "max_after_n")
            },
            samples=int(data["samples"]),
        )
    except (AttributeError, KeyError, TypeError, ValueError) as e:
        raise ConfigurationError("--wrench-calibration", str(path), f"a file calibrate-wrench wrote ({e})") from e
    if len(calibration.parameters) != columns or not all(map(math.isfinite, calibration.parameters)):
        raise ConfigurationError("--wrench-calibration", str(path), f"{columns} finite parameters")
    if not (math.isfinite(calibration.error_bound_n) and calibration.error_bound_n >= 0.0):
        raise ConfigurationError("--wrench-calibration", str(path), "a finite, non-negative error_bound_n")
    return calibration
