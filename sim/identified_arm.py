"""A real PSM's free-space joint efforts, identified from its public logs: what the force-sensing model adds.

The console's ``measured_cf`` is ``pinv(J^T) tau`` of the measured efforts, and in free space those efforts are
the arm's own dynamics: inertia, Coriolis, link and instrument gravity with the counterweight, friction and
offsets. :class:`IdentifiedArm` holds one real arm's, as a parameter vector on the columns of
:class:`psm_control.effort_model.EffortRegressor` (Pinocchio's joint torque regressor, gravity along three
axes, friction and offsets per joint), and what the identification left unexplained on a log it was not
fitted on: a per-joint residual with a correlation time (drawn as a coloured noise), whose spread grows as a
joint slows to a stop. Where a joint's velocity crosses zero its friction is anywhere in its band (stiction,
the Stribeck dip), which a fit of ``sign(qd)`` friction cannot follow: on the WPI PSM's held-out log the
residual of its first two joints doubles below 0.08 rad/s, of its insertion below 5 mm/s.

``tissue-retract bench sensing`` sets it beside the sensing presets of :mod:`sim.force_sensing` on real
logs: on the WPI PSM's held-out log it reproduces the console's free-space error by insertion depth and
tip speed, where the ``dvrk`` preset is 5-8 times below it.

The shipped arm (:data:`ARM_FILES`) is fitted by ``tissue-retract bench sensing --write-arm`` on the WPI
PSM's excitation logs (WPI-AIM/dvrk_dynamics_identification, ``data/psm/measured_trajectory``); the file
records the command, the logs and the held-out figures. The logs themselves are not shipped (they have no
licence): only the fitted numbers are.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from psm_control.effort_model import shared_regressor
from psm_control.errors import UnknownVariantError
from psm_control.outputs import write_atomic

__all__ = ["ARM_FILES", "IdentifiedArm", "identified_arm"]

#: The identified arms shipped with the package, by name (files in ``sim/data``).
ARM_FILES = {"wpi-psm": "identified_arm_wpi_psm.json"}


@dataclass(frozen=True)
class IdentifiedArm:
    """One PSM's identified free-space efforts (see the module notes).

    Attributes:
        name: Its name (a key of :data:`ARM_FILES`, or a file's stem).
        columns: The regressor's identified columns.
        parameters: Their values.
        residual: Standard deviation of what the identification left per joint on a held-out log, the
            joint moving (6,) [N m, N for the insertion].
        residual_band: What the friction band adds to it with the joint at rest (6,), as a standard deviation
            added in quadrature (see :meth:`residual_spread`).
        residual_band_speed: The joint speed at which the band's variance falls to 1/e (6,) [rad/s, m/s].
        residual_time_s: The residual's correlation time (the 1/e lag of its autocorrelation, divided by its
            spread, the median over the joints) [s].
        residual_bound_n: 1.25 x the largest force error the identification left on the held-out log at
            retraction speeds (tool tip at most 0.1 m/s) [N]: what a calibration of this arm is trusted to.
        provenance: Where the numbers come from: the command, the logs fitted and held out, the figures.
    """

    name: str
    columns: tuple[int, ...]
    parameters: tuple[float, ...]
    residual: tuple[float, ...]
    residual_band: tuple[float, ...]
    residual_band_speed: tuple[float, ...]
    residual_time_s: float
    residual_bound_n: float
    provenance: str

    @functools.cached_property
    def _vector(self) -> np.ndarray:
        full = np.zeros(shared_regressor().columns)
        full[list(self.columns)] = self.parameters
        return full

    def parameter_vector(self) -> np.ndarray:
        """The parameters on all of the regressor's columns, zero where the identification found none."""
        return self._vector.copy()

    def efforts(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """The arm's free-space joint efforts (6,) at ``q, qd, qdd``."""
        return np.asarray(shared_regressor().rows(q, qd, qdd) @ self._vector)

    def inertial_efforts(self, q: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """The part of :meth:`efforts` the acceleration makes, ``M(q) qdd`` (6,): what a calibration that is
        given no acceleration (a deploy's, from single ``measured_js`` messages) leaves."""
        zero = np.zeros(6)
        rows = shared_regressor().rows
        return np.asarray((rows(q, zero, qdd) - rows(q, zero, zero)) @ self._vector)

    def residual_spread(self, qd: np.ndarray) -> np.ndarray:
        """The residual's standard deviation per joint at the joint velocities ``qd`` (6,):
        ``sqrt(residual**2 + residual_band**2 * exp(-|qd| / residual_band_speed))``."""
        band = np.square(self.residual_band) * np.exp(-np.abs(qd) / np.asarray(self.residual_band_speed))
        return np.sqrt(np.square(self.residual) + band)

    def largest_residual_spread(self) -> np.ndarray:
        """The residual's standard deviation per joint at rest, its largest (6,)."""
        return self.residual_spread(np.zeros(6))

    def to_json(self) -> dict[str, Any]:
        """The file's content."""
        return {
            "kind": "identified_arm",
            "name": self.name,
            "columns": list(self.columns),
            "parameters": list(self.parameters),
            "residual": list(self.residual),
            "residual_band": list(self.residual_band),
            "residual_band_speed": list(self.residual_band_speed),
            "residual_time_s": self.residual_time_s,
            "residual_bound_n": self.residual_bound_n,
            "provenance": self.provenance,
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> IdentifiedArm:
        """An arm from :meth:`to_json`'s content."""
        return cls(
            name=str(data["name"]),
            columns=tuple(int(c) for c in data["columns"]),
            parameters=tuple(float(v) for v in data["parameters"]),
            residual=tuple(float(v) for v in data["residual"]),
            residual_band=tuple(float(v) for v in data["residual_band"]),
            residual_band_speed=tuple(float(v) for v in data["residual_band_speed"]),
            residual_time_s=float(data["residual_time_s"]),
            residual_bound_n=float(data["residual_bound_n"]),
            provenance=str(data["provenance"]),
        )

    def write(self, path: Path, field: str = "--write-arm") -> None:
        """Write the arm as JSON, whole or not at all (:func:`psm_control.outputs.write_atomic`)."""
        write_atomic(path, json.dumps(self.to_json(), indent=2) + "\n", field)


@functools.cache
def identified_arm(name: str) -> IdentifiedArm:
    """The shipped identified arm called ``name``.

    Raises:
        UnknownVariantError: No such arm (the error lists them).
    """
    if name not in ARM_FILES:
        raise UnknownVariantError("identified arm", name, list(ARM_FILES))
    text = resources.files("sim").joinpath("data", ARM_FILES[name]).read_text(encoding="utf-8")
    return IdentifiedArm.from_json(json.loads(text))
