"""What a dVRK PSM senses of the tissue force: the console's ``measured_cf``, built from motor currents.

A PSM has no force sensor. Its console computes the Cartesian wrench as ``pinv(J^T) tau`` from the
measured joint efforts ``tau`` (motor currents), with nothing subtracted for gravity, friction or
dynamics (sawIntuitiveResearchKit, ``mtsIntuitiveResearchKitArm.cpp``; the dVRK documentation calls it
"a rough cartesian force emulation"). This module models those efforts as

    tau = J^T [f; 0] + tau_gravity(q) + tau_coulomb(qd) + tau_viscous(qd) + tau_hysteresis + drift + noise

with ``f`` the tissue's force on the tool and ``J`` the tool tip's 6x6 Jacobian (base axes), and returns
the force part of ``pinv(J^T) tau``, as the console publishes it on ``body``/``spatial/measured_cf``.

The terms and where their sizes come from (the parameters of :data:`SENSING_PRESETS`):

* ``tau_gravity``: an instrument mass the console does not compensate, a point on the shaft
  ``unbalanced_offset_m`` behind the tool tip. The Classic PSM's counterweight balances the arm's
  links, not the instrument (Wang et al. 2019, arXiv 1902.10875, model the counterweight; their
  identified instrument links weigh 0.36-0.5 kg); the console compensates no gravity on the Classic
  PSM, and only from dVRK 2.4 on the Si (release notes, ``use_gravity_compensation``). We take 0.1 kg
  of it unbalanced, 0.25 m behind the tip (about where an instrument's housing sits).
* Coulomb and viscous friction per joint: the identification literature's friction terms (Wang et al.
  2019; Yang et al. 2024, arXiv 2405.07453, who also model the trocar's friction on the shaft). Sizes
  here: 0.04 N m on the outer yaw and pitch, 0.3 N on the insertion stage and cannula, 4 mN m on the
  cable-driven wrist (about 0.4 N at the wrist's 9 mm lever).
* The wrist cables' hysteresis: a Dahl model per wrist joint, +-3 mN m over 0.02 rad of travel.
* A slowly drifting offset per joint (temperature, cable tension): an Ornstein-Uhlenbeck process with a
  60 s time constant.
* Current noise: white, per joint.

What these add up to in free space, by :func:`error_bound_n`, is a few newtons in the worst pose and
motion and about one newton typical: the published estimators that identify the arm's dynamics still
report 2 N RMS (Wu, Yilmaz, Kazanzides, Tumerdem 2020, arXiv 2012.01479) or 3-5 % of range
(Yang et al. 2024) after compensation, which the raw estimate is worse than. ``dvrk-calibrated`` is
what is left after ``tissue-retract calibrate-wrench`` fits the gravity and friction terms: the
hysteresis, drift and noise, and a tenth of the gravity and friction (the fit's error on a held-out
trajectory; Yang et al. 2024 report 5-10 % of range for identified models).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from psm_control.errors import UnknownVariantError
from psm_control.robot import PsmConfiguration, PsmModel
from safety.config import SafetyConfig

__all__ = [
    "SENSING_NAMES",
    "SENSING_PRESETS",
    "ForceSensor",
    "SensingParams",
    "console_force",
    "error_bound_n",
    "sensing_params",
    "tissue_bounds",
    "with_sensing",
]

_GRAVITY_BASE_M_S2 = np.array([0.0, 0.0, -9.81])
#: Speed over which Coulomb friction changes sign [rad/s or m/s] (a smooth sign: the efforts of a joint at
#: rest are whatever holds it, somewhere inside the friction band).
_COULOMB_SPEED = 0.01
#: Pseudo-inverse cut-off of the console's ``pinv(J^T)``, relative to the largest singular value.
_PINV_RCOND = 1e-4


@dataclass(frozen=True)
class SensingParams:
    """One force-sensing model. Per-joint tuples are the six arm joints (N m or N for the insertion).

    Attributes:
        name: The preset's name.
        unbalanced_mass_kg: Instrument mass the console does not compensate [kg].
        unbalanced_offset_m: Its distance behind the tool tip along the shaft [m].
        coulomb: Coulomb friction per joint.
        viscous: Viscous friction per joint [per rad/s or m/s].
        hysteresis: Half-width of each joint's hysteresis band (the wrist cables).
        hysteresis_travel_rad: Travel over which the hysteresis saturates [rad].
        drift: Stationary standard deviation of each joint's drifting offset.
        drift_time_s: The drift's time constant [s].
        noise: Standard deviation of each joint's current noise.
    """

    name: str
    unbalanced_mass_kg: float = 0.0
    unbalanced_offset_m: float = 0.25
    coulomb: tuple[float, ...] = (0.0,) * 6
    viscous: tuple[float, ...] = (0.0,) * 6
    hysteresis: tuple[float, ...] = (0.0,) * 6
    hysteresis_travel_rad: float = 0.02
    drift: tuple[float, ...] = (0.0,) * 6
    drift_time_s: float = 60.0
    noise: tuple[float, ...] = (0.0,) * 6

    @property
    def exact(self) -> bool:
        """The sensor reports the tissue force exactly (the ``ideal`` preset)."""
        return not any(
            [self.unbalanced_mass_kg, *self.coulomb, *self.viscous, *self.hysteresis, *self.drift, *self.noise]
        )

    def scaled(self, factor: float) -> SensingParams:
        """Every error term times ``factor`` (a sweep's ``force_sensing_scale``)."""
        if factor == 1.0:
            return self

        def times(values: tuple[float, ...]) -> tuple[float, ...]:
            return tuple(factor * v for v in values)

        return dataclasses.replace(
            self,
            unbalanced_mass_kg=factor * self.unbalanced_mass_kg,
            coulomb=times(self.coulomb),
            viscous=times(self.viscous),
            hysteresis=times(self.hysteresis),
            drift=times(self.drift),
            noise=times(self.noise),
        )


_UNCOMPENSATED = SensingParams(
    name="dvrk",
    unbalanced_mass_kg=0.1,
    unbalanced_offset_m=0.25,
    coulomb=(0.04, 0.04, 0.3, 0.004, 0.004, 0.004),
    viscous=(0.02, 0.02, 1.0, 0.001, 0.001, 0.001),
    hysteresis=(0.0, 0.0, 0.0, 0.003, 0.003, 0.003),
    drift=(0.005, 0.005, 0.05, 0.0005, 0.0005, 0.0005),
    noise=(0.002, 0.002, 0.02, 0.0003, 0.0003, 0.0003),
)

#: The calibration leaves a tenth of the gravity and friction (its held-out error), and all of the rest.
_CALIBRATED_RESIDUAL = 0.1

#: The force-sensing presets, by name (``--force-sensing``, ``sim-dvrk --wrench``).
SENSING_PRESETS: dict[str, SensingParams] = {
    "ideal": SensingParams(name="ideal"),
    "dvrk": _UNCOMPENSATED,
    "dvrk-calibrated": dataclasses.replace(
        _UNCOMPENSATED,
        name="dvrk-calibrated",
        unbalanced_mass_kg=_CALIBRATED_RESIDUAL * _UNCOMPENSATED.unbalanced_mass_kg,
        coulomb=tuple(_CALIBRATED_RESIDUAL * v for v in _UNCOMPENSATED.coulomb),
        viscous=tuple(_CALIBRATED_RESIDUAL * v for v in _UNCOMPENSATED.viscous),
    ),
}
#: The presets' names, in the order ``--help`` lists them.
SENSING_NAMES = tuple(SENSING_PRESETS)


def sensing_params(name: str) -> SensingParams:
    """The preset called ``name``.

    Raises:
        UnknownVariantError: No such preset (the error lists them).
    """
    if name not in SENSING_PRESETS:
        raise UnknownVariantError("force sensing", name, list(SENSING_NAMES))
    return SENSING_PRESETS[name]


def console_force(jacobian: np.ndarray, efforts: np.ndarray) -> np.ndarray:
    """The force part of the console's ``pinv(J^T) tau`` (3,) [N]."""
    return np.asarray(np.linalg.pinv(jacobian.T, rcond=_PINV_RCOND)[:3] @ efforts)


def _gravity_efforts(params: SensingParams, jacobian: np.ndarray, insertion_m: float) -> np.ndarray:
    """Efforts that hold the unbalanced instrument mass against gravity (6,).

    The mass sits on the shaft, ``unbalanced_offset_m`` behind the tip: the insertion joint's column of
    the tip's Jacobian is the shaft's direction ``s``, and the outer joints swing the point at
    ``(insertion - offset) s`` about the RCM with their angular columns ``w_i``: ``w_i x s`` per unit length.
    """
    if params.unbalanced_mass_kg == 0.0:
        return np.zeros(6)
    weight = params.unbalanced_mass_kg * _GRAVITY_BASE_M_S2
    shaft = jacobian[:3, 2]
    lever = insertion_m - params.unbalanced_offset_m
    efforts = np.zeros(6)
    for joint in (0, 1):
        efforts[joint] = -lever * float(np.cross(jacobian[3:, joint], shaft) @ weight)
    efforts[2] = -float(shaft @ weight)
    return efforts


class ForceSensor:
    """The console's force estimate from simulated joint efforts, tick by tick (see the module notes).

    Args:
        params: The sensing model.
        rng: The generator of the noise and the drift (seeded by the caller, per episode).
    """

    def __init__(self, params: SensingParams, rng: np.random.Generator | None = None) -> None:
        self.params = params
        self._coulomb = np.asarray(params.coulomb, dtype=float)
        self._viscous = np.asarray(params.viscous, dtype=float)
        self._hysteresis = np.asarray(params.hysteresis, dtype=float)
        self._drift_std = np.asarray(params.drift, dtype=float)
        self._noise = np.asarray(params.noise, dtype=float)
        self.reset(rng if rng is not None else np.random.default_rng(0))

    def reset(self, rng: np.random.Generator) -> None:
        """A new episode: a fresh drift (drawn from its stationary spread) and hysteresis state."""
        self._rng = rng
        self._drift = self._drift_std * rng.standard_normal(6)
        self._dahl = np.zeros(6)
        self._last_q: np.ndarray | None = None

    def efforts(self, configuration: PsmConfiguration, qd: np.ndarray, force_n: np.ndarray, dt_s: float) -> np.ndarray:
        """The measured joint efforts (6,) with the tissue's force on the tool ``force_n`` (base axes) [N].

        Args:
            configuration: The arm at its measured joints (base frame set).
            qd: Joint velocities (6,).
            force_n: The tissue's force on the tool (3,) [N], base axes.
            dt_s: Time since the last call [s] (the drift and the hysteresis advance by it).
        """
        jacobian = configuration.base_jacobian()
        efforts = jacobian[:3].T @ np.asarray(force_n, dtype=float)
        if self.params.exact:
            return np.asarray(efforts)
        p = self.params
        qd = np.asarray(qd, dtype=float)
        q = configuration.q
        efforts = efforts + _gravity_efforts(p, jacobian, float(q[2]))
        efforts += self._coulomb * np.tanh(qd / _COULOMB_SPEED) + self._viscous * qd
        if self._last_q is not None and np.any(self._hysteresis):
            step = q - self._last_q  # Dahl: the band's state follows the travel, saturating at +-1
            self._dahl = np.clip(
                self._dahl + step / p.hysteresis_travel_rad * (1.0 - self._dahl * np.sign(step)), -1, 1
            )
        self._last_q = q.copy()
        efforts += self._hysteresis * self._dahl
        if dt_s > 0.0 and np.any(self._drift_std):
            decay = math.exp(-dt_s / p.drift_time_s)
            self._drift = decay * self._drift + self._drift_std * math.sqrt(
                1.0 - decay * decay
            ) * self._rng.standard_normal(6)
        efforts += self._drift + self._noise * self._rng.standard_normal(6)
        return np.asarray(efforts)

    def measure(self, configuration: PsmConfiguration, qd: np.ndarray, force_n: np.ndarray, dt_s: float) -> np.ndarray:
        """The force the console reports (3,) [N], base axes: the force part of ``pinv(J^T) efforts``."""
        if self.params.exact:
            return np.asarray(force_n, dtype=float).copy()
        return console_force(configuration.base_jacobian(), self.efforts(configuration, qd, force_n, dt_s))


#: Joint speeds up to which the bound is drawn [rad/s, m/s]: above what the tasks' motions reach.
_BOUND_SPEEDS = np.array([1.0, 1.0, 0.1, 3.0, 3.0, 3.0])
#: The bound is the largest error drawn, times this.
_BOUND_MARGIN = 1.1


@functools.cache
def _bound(params: SensingParams, samples: int, seed: int) -> float:
    model = PsmModel()
    configuration = model.configuration()
    rng = np.random.default_rng(seed)
    spec = model.spec
    lower, upper = spec.lower.copy(), spec.upper.copy()
    lower[2], upper[2] = 0.05, 0.2  # the workspace box's insertion range
    lower[3:], upper[3:] = np.maximum(lower[3:], -1.2), np.minimum(upper[3:], 1.2)
    sensor = ForceSensor(params, rng)
    worst = 0.0
    for _ in range(samples):
        q = rng.uniform(lower, upper)
        configuration.update(q)
        sensor.reset(rng)
        # The hysteresis and the drift at the edges of their bands, in random directions.
        sensor._dahl = rng.choice([-1.0, 1.0], 6)
        sensor._drift = 3.0 * sensor._drift_std * rng.choice([-1.0, 1.0], 6)
        sensor._last_q = q
        qd = rng.uniform(-_BOUND_SPEEDS, _BOUND_SPEEDS)
        worst = max(worst, float(np.linalg.norm(sensor.measure(configuration, qd, np.zeros(3), 0.0))))
    return _BOUND_MARGIN * worst


def error_bound_n(params: SensingParams, *, samples: int = 2000, seed: int = 0) -> float:
    """How far the sensed force can be from the true one [N], by the model (0 for ``ideal``).

    The largest free-space error of ``samples`` draws, plus 10 %: poses in the workspace box's insertion
    range (5-20 cm) with the wrist within +-1.2 rad, joint speeds up to :data:`_BOUND_SPEEDS`, the
    hysteresis and the drift at the edges of their bands (three standard deviations) in random
    directions, and the current noise. The tissue's force adds exactly (the console's ``pinv(J^T)``
    undoes ``J^T``), so the free-space error is the error at any load.
    """
    if params.exact:
        return 0.0
    return _bound(params, samples, seed)


#: The travel bound's stiffness over ``E t`` (:mod:`safety.force_bound`). Measured: the tasks' expert
#: episodes (ideal sensing, grasp point 1-30 mm from where the jaws closed) met at most 0.96 E t per metre of
#: travel; ``bench safety``'s adversaries up to 2.4 E t (SignFlipPull on a MultiSite site one node from a
#: pinned edge, flap at 3 x E). The bound is that worst plus 10 %, the margin :func:`error_bound_n` takes over
#: its worst draw; the promise (peak <= 1.10 x the limit) then holds up to 2.9 E t.
STIFFNESS_BOUND_PER_E_T = 2.64
#: The held load at the grasp over the flap's whole weight: the flap's weight, and a light press.
HELD_LOAD_PER_WEIGHT = 1.2


def tissue_bounds(ranges: Mapping[str, tuple[float, float]]) -> tuple[float, float]:
    """The tissue stiffness bound [N/m] and held-load bound [N] of a randomization's tissue ranges.

    The stiffest and heaviest flap the ranges allow: ``2.64 E t`` at the largest modulus and thickness,
    and 1.2 times the weight at the largest size, density, thickness and gravity.
    """
    e_pa = 1e3 * ranges["tissue_youngs_modulus_kpa"][1]
    t_m = 1e-3 * ranges["tissue_thickness_mm"][1]
    weight_n = ranges["tissue_density_kg_m3"][1] * ranges["tissue_size_m"][1] ** 2 * t_m * ranges["gravity_m_s2"][1]
    return STIFFNESS_BOUND_PER_E_T * e_pa * t_m, HELD_LOAD_PER_WEIGHT * weight_n


def with_sensing(config: SafetyConfig, error_n: float, ranges: Mapping[str, tuple[float, float]]) -> SafetyConfig:
    """``config`` with a force-sensing error bound [N] and the tissue ranges' bounds (what the filter keeps to)."""
    stiffness, load = tissue_bounds(ranges)
    return dataclasses.replace(
        config,
        force_sensing_error_n=float(error_n),
        tissue_stiffness_bound_n_per_m=stiffness,
        held_load_bound_n=load,
    )
