"""What a dVRK PSM senses of the tissue force: the console's ``measured_cf``, built from motor currents.

A PSM has no force sensor. Its console computes the Cartesian wrench as ``pinv(J^T) tau`` from the
measured joint efforts ``tau`` (motor currents), with nothing subtracted for gravity, friction or
dynamics (sawIntuitiveResearchKit, ``mtsIntuitiveResearchKitArm.cpp``; the dVRK documentation calls it
"a rough cartesian force emulation"). This module models those efforts as

    tau = J^T [f; 0] + tau_arm(q, qd, qdd) + residual

with ``f`` the tissue's force on the tool and ``J`` the tool tip's 6x6 Jacobian (base axes), and returns
the force part of ``pinv(J^T) tau``, as the console publishes it on ``body``/``spatial/measured_cf``.

``tau_arm`` is a real arm's free-space efforts, identified from its public logs
(:mod:`sim.identified_arm`: inertia, Coriolis, link and instrument gravity with the counterweight, Coulomb
and viscous friction, offsets), and ``residual`` what that identification left unexplained on a log it was
not fitted on, drawn as a coloured noise per joint (an Ornstein-Uhlenbeck process with the residual's
correlation time, times its spread, which grows as the joint slows through its friction band). The
accelerations come from the joint velocities' change between two measurements. On the public logs' fast
excitation this reproduces the console's free-space error, and what a calibration leaves of it, by
insertion depth and tip speed (``tissue-retract bench sensing``; docs/force-sensing.md).

Presets (:data:`SENSING_PRESETS`):

* ``dvrk``: the console's estimate: all of ``tau_arm`` and the residual;
* ``dvrk-calibrated``: what ``tissue-retract calibrate-wrench`` leaves, measured on the public logs: its fit
  removes ``tau_arm`` with the acceleration the chain commands (a deploy has no other: it reads single
  ``measured_js`` messages), so what is left is the held-out residual and the inertia of the difference
  between the arm's acceleration and the commanded one (none where the arm tracks the command, as the
  simulated arm does without a tracking lag);
* ``ideal``: the exact force.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from psm_control.errors import ConfigurationError, UnknownVariantError
from psm_control.robot import PsmConfiguration, PsmModel
from safety.config import SafetyConfig
from sim.identified_arm import IdentifiedArm, identified_arm

__all__ = [
    "HELD_STILL_ERROR_N",
    "SENSING_NAMES",
    "SENSING_PRESETS",
    "ArmResidual",
    "ColouredNoise",
    "ForceSensor",
    "SensingParams",
    "calibrated_sensing",
    "console_force",
    "error_bound_n",
    "sensing_params",
    "tissue_bounds",
    "with_sensing",
]

#: Pseudo-inverse cut-off of the console's ``pinv(J^T)``, relative to the largest singular value.
_PINV_RCOND = 1e-4
#: The identified arm of the dVRK presets.
_ARM = "wpi-psm"
#: Time constant of the accelerations the arm's inertia is computed from [s].
_ACCELERATION_TIME_S = 0.02


@dataclass(frozen=True)
class SensingParams:
    """One force-sensing model (see the module notes).

    Attributes:
        name: The preset's name.
        arm: The identified arm whose free-space efforts the console adds ("" none).
        arm_terms: ``all`` of them (the console's estimate), or ``tracking``: the inertia of the arm's
            acceleration less the commanded one (what a calibration given the commanded acceleration leaves).
        residual: Whether the identification's held-out residual is drawn.
        scale: Every error term times this (a sweep's ``force_sensing_scale``).
    """

    name: str
    arm: str = ""
    arm_terms: str = "all"
    residual: bool = False
    scale: float = 1.0

    @property
    def exact(self) -> bool:
        """The sensor reports the tissue force exactly (the ``ideal`` preset, or any at scale 0)."""
        return self.scale == 0.0 or not (self.arm or self.residual)

    @property
    def identified_arm(self) -> IdentifiedArm | None:
        """The identified arm, or None."""
        return identified_arm(self.arm) if self.arm else None

    def scaled(self, factor: float) -> SensingParams:
        """Every error term times ``factor`` (a sweep's ``force_sensing_scale``)."""
        return self if factor == 1.0 else dataclasses.replace(self, scale=factor * self.scale)


#: The force-sensing presets, by name (``--force-sensing``, ``sim-dvrk --wrench``).
SENSING_PRESETS: dict[str, SensingParams] = {
    "ideal": SensingParams(name="ideal"),
    "dvrk": SensingParams(name="dvrk", arm=_ARM, arm_terms="all", residual=True),
    "dvrk-calibrated": SensingParams(name="dvrk-calibrated", arm=_ARM, arm_terms="tracking", residual=True),
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
    jacobian = np.ascontiguousarray(jacobian, dtype=float)
    return np.asarray(_force_rows(jacobian.tobytes(), jacobian.shape) @ efforts)


@functools.lru_cache(maxsize=8)
def _force_rows(jacobian: bytes, shape: tuple[int, ...]) -> np.ndarray:
    """The force rows of ``pinv(J^T)`` for a Jacobian given by its bytes (read-only). Kept for the last few: an
    arm at rest keeps its Jacobian tick after tick, and this SVD was a third of an idle console's tick."""
    rows = np.linalg.pinv(np.frombuffer(jacobian).reshape(shape).T, rcond=_PINV_RCOND)[:3]
    rows.flags.writeable = False
    return rows


class ColouredNoise:
    """Six unit Ornstein-Uhlenbeck processes with correlation time ``time_s`` [s], started from their
    stationary spread (1).

    Args:
        time_s: Correlation time [s].
        rng: The generator of the draws.
    """

    def __init__(self, time_s: float, rng: np.random.Generator) -> None:
        self.time_s = float(time_s)
        self.reset(rng)

    def reset(self, rng: np.random.Generator) -> None:
        """A fresh draw from the stationary spread."""
        self._rng = rng
        self.value = rng.standard_normal(6)

    def advance(self, dt_s: float) -> np.ndarray:
        """The values ``dt_s`` [s] later (none: as they were)."""
        if dt_s > 0.0:
            decay = math.exp(-dt_s / self.time_s)
            self.value = decay * self.value + math.sqrt(1.0 - decay * decay) * self._rng.standard_normal(6)
        return self.value


class ArmResidual:
    """What an identified arm's model leaves of its efforts (6,), drawn: per joint a unit coloured noise times
    the arm's residual spread at the joint's speed (:meth:`~sim.identified_arm.IdentifiedArm.residual_spread`).

    Args:
        arm: The identified arm; None: no residual.
        scale: The spread times this.
        rng: The generator of the draws.
    """

    def __init__(self, arm: IdentifiedArm | None, scale: float, rng: np.random.Generator) -> None:
        self._arm, self._scale = arm, float(scale)
        self._unit = ColouredNoise(arm.residual_time_s if arm is not None else 1.0, rng)

    def reset(self, rng: np.random.Generator) -> None:
        """A fresh draw from the stationary spread."""
        self._unit.reset(rng)

    def advance(self, dt_s: float, qd: np.ndarray) -> np.ndarray:
        """The residual efforts ``dt_s`` [s] later, the joints at velocities ``qd``."""
        if self._arm is None or self._scale == 0.0:
            return np.zeros(6)
        return self._scale * self._arm.residual_spread(qd) * self._unit.advance(dt_s)

    def largest_spread(self) -> np.ndarray:
        """The residual's standard deviation per joint at its largest, the joints at rest (6,)."""
        return self._scale * self._arm.largest_residual_spread() if self._arm is not None else np.zeros(6)


class ForceSensor:
    """The console's force estimate from simulated joint efforts, tick by tick (see the module notes).

    Args:
        params: The sensing model.
        rng: The generator of the residual (seeded by the caller, per episode).
    """

    def __init__(self, params: SensingParams, rng: np.random.Generator | None = None) -> None:
        self.params = params
        arm = params.identified_arm
        self._arm = arm
        rng = rng if rng is not None else np.random.default_rng(0)
        self.residual = ArmResidual(arm if params.residual else None, params.scale, rng)  # draws the first episode's
        self._arm_state: tuple[bytes, ...] = ()
        self._arm_efforts = np.zeros(6)
        self._at_rest()

    def reset(self, rng: np.random.Generator) -> None:
        """A new episode: a fresh residual (drawn from its stationary spread), no earlier velocity."""
        self.residual.reset(rng)
        self._at_rest()

    def _at_rest(self) -> None:
        """No earlier velocity to take an acceleration from."""
        self._last_qd: np.ndarray | None = None
        self._last_commanded_qd: np.ndarray | None = None
        self._qdd, self._commanded_qdd = np.zeros(6), np.zeros(6)

    def arm_efforts(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, commanded_qdd: np.ndarray) -> np.ndarray:
        """The identified arm's part of the efforts (6,): all of it, or the inertia of the tracking error
        (``arm_terms``). The last state's are kept: an arm at rest asks for them again tick after tick."""
        if self._arm is None:
            return np.zeros(6)
        state = tuple(np.asarray(v, dtype=float).tobytes() for v in (q, qd, qdd, commanded_qdd))
        if state != self._arm_state:
            if self.params.arm_terms == "tracking":
                efforts = self._arm.inertial_efforts(q, qdd - commanded_qdd)
            else:
                efforts = self._arm.efforts(q, qd, qdd)
            self._arm_state, self._arm_efforts = state, self.params.scale * efforts
        return self._arm_efforts.copy()

    def efforts(
        self,
        configuration: PsmConfiguration,
        qd: np.ndarray,
        force_n: np.ndarray,
        dt_s: float,
        commanded_qd: np.ndarray | None = None,
    ) -> np.ndarray:
        """The measured joint efforts (6,) with the tissue's force on the tool ``force_n`` (base axes) [N].

        Args:
            configuration: The arm at its measured joints (base frame set).
            qd: Joint velocities (6,).
            force_n: The tissue's force on the tool (3,) [N], base axes.
            dt_s: Time since the last call [s] (the accelerations and the residual advance by it).
            commanded_qd: The joint velocities the chain commanded (6,); None: the measured ones.
        """
        jacobian = configuration.base_jacobian()
        efforts = jacobian[:3].T @ np.asarray(force_n, dtype=float)
        if self.params.exact:
            return np.asarray(efforts)
        qd = np.asarray(qd, dtype=float)
        commanded = qd if commanded_qd is None else np.asarray(commanded_qd, dtype=float)
        if self._last_qd is not None and self._last_commanded_qd is not None and dt_s > 0.0:
            # The arm's and the chain's mean accelerations over the tick, smoothed as the arm's mass and servo
            # smooth a velocity that steps (a console that differences set-points arriving between its ticks).
            blend = dt_s / (_ACCELERATION_TIME_S + dt_s)
            self._qdd += blend * ((qd - self._last_qd) / dt_s - self._qdd)
            self._commanded_qdd += blend * ((commanded - self._last_commanded_qd) / dt_s - self._commanded_qdd)
        self._last_qd, self._last_commanded_qd = qd.copy(), commanded.copy()
        efforts = efforts + self.arm_efforts(configuration.q, qd, self._qdd, self._commanded_qdd)
        return np.asarray(efforts + self.residual.advance(dt_s, qd))

    def measure(
        self,
        configuration: PsmConfiguration,
        qd: np.ndarray,
        force_n: np.ndarray,
        dt_s: float,
        commanded_qd: np.ndarray | None = None,
    ) -> np.ndarray:
        """The force the console reports (3,) [N], base axes: the force part of ``pinv(J^T) efforts``."""
        if self.params.exact:
            return np.asarray(force_n, dtype=float).copy()
        efforts = self.efforts(configuration, qd, force_n, dt_s, commanded_qd)
        return console_force(configuration.base_jacobian(), efforts)


#: The largest calibrated free-space error measured on a real PSM held still [N]: radiang's arm calibrated on its
#: two slow trajectories, checked on its static holds (``tissue-retract calibrate-wrench --from
#: Data250_6.21.2017 Data_Pos_6.19.2017 --held-out DataHold_6.8.2017``: 5.77 N at most, 2.34 N RMS, 40 of its
#: samples at 5-8 cm insertion). At rest a joint's friction is anywhere in its band, which no fit of motion
#: removes; the identified arm's residual, measured moving, does not cover it.
HELD_STILL_ERROR_N = 5.77
#: A calibration's bound over its largest held-out error (``calibrate-wrench``'s margin).
_CALIBRATION_MARGIN = 1.25
#: The bound is the largest error drawn, times this.
_BOUND_MARGIN = 1.1
#: The residual's edge in the bound's draws, in standard deviations.
_RESIDUAL_EDGE = 3.0


@functools.cache
def _bound(
    params: SensingParams, velocity: tuple[float, ...], acceleration: tuple[float, ...], samples: int, seed: int
) -> float:
    model = PsmModel()
    configuration = model.configuration()
    rng = np.random.default_rng(seed)
    spec = model.spec
    lower, upper = spec.lower.copy(), spec.upper.copy()
    lower[2], upper[2] = 0.05, 0.2  # the workspace box's insertion range
    lower[3:], upper[3:] = np.maximum(lower[3:], -1.2), np.minimum(upper[3:], 1.2)
    sensor = ForceSensor(params, rng)
    speed, accel = np.asarray(velocity), np.asarray(acceleration)
    jacobians, efforts = np.empty((samples, 6, 6)), np.empty((samples, 6))
    for k in range(samples):
        q = rng.uniform(lower, upper)
        configuration.update(q)
        qd = rng.uniform(-speed, speed)
        # The inertia is linear in the acceleration: its largest lies on a corner of the limits' box.
        qdd = accel * rng.choice([-1.0, 1.0], 6)
        residual = _RESIDUAL_EDGE * sensor.residual.largest_spread() * rng.choice([-1.0, 1.0], 6)
        efforts[k] = sensor.arm_efforts(q, qd, qdd, np.zeros(6)) + residual
        jacobians[k] = configuration.base_jacobian()
    # The console's pinv(J^T) of every draw at once (console_force's, one SVD per draw): every deploy waits for it.
    forces = np.einsum("kij,kj->ki", np.linalg.pinv(jacobians.transpose(0, 2, 1), rcond=_PINV_RCOND)[:, :3], efforts)
    return _BOUND_MARGIN * float(np.linalg.norm(forces, axis=1).max())


def error_bound_n(
    params: SensingParams, config: SafetyConfig | None = None, *, samples: int = 2000, seed: int = 0
) -> float:
    """How far the sensed force can be from the true one [N] (0 for ``ideal``).

    The console's estimate (``arm_terms`` ``all``): the largest free-space error of ``samples`` draws, plus
    10 %: poses in the workspace box's insertion range (5-20 cm) with the wrist within +-1.2 rad, joint speeds
    within the chain's velocity limits and accelerations at its acceleration limits (``config``'s; the
    default chain's when None), the residual at three standard deviations in random directions. The chain's
    limits are what a retraction can reach, so they decide the bound; its inertial part, most of it, is
    proportional to the acceleration limits. The tissue's force adds exactly (the console's ``pinv(J^T)``
    undoes ``J^T``), so the free-space error is the error at any load.

    The calibrated estimate (``tracking``): 1.25 x the largest error a calibration left on a held-out real log
    at retraction speeds, as ``calibrate-wrench`` bounds its own fit: the identified arm's
    :attr:`~sim.identified_arm.IdentifiedArm.residual_bound_n` (its own held-out log, moving), or
    :data:`HELD_STILL_ERROR_N` (another arm held still) when larger. It holds while the arm tracks the chain's
    commanded acceleration; the inertia of a tracking error is not in it.
    """
    if params.exact:
        return 0.0
    arm = params.identified_arm
    if params.arm_terms == "tracking" and arm is not None:
        return params.scale * max(arm.residual_bound_n, _CALIBRATION_MARGIN * HELD_STILL_ERROR_N)
    config = config if config is not None else SafetyConfig()
    velocity = tuple(float(v) for v in config.velocity)
    acceleration = tuple(float(a) for a in config.acceleration)
    return _bound(params, velocity, acceleration, samples, seed)


def calibrated_sensing(bound_n: float) -> SensingParams:
    """A calibrated dVRK whose force is off by at most ``bound_n`` [N]: a calibration file's bound.

    The ``dvrk-calibrated`` preset's errors (the held-out residual and the inertia of a tracking error), every
    term scaled so that the preset's bound (:func:`error_bound_n`, 1.25 x the largest calibrated error on the
    held-out real logs) becomes the file's: a robot's calibration, checked on its own held-out log, bounds the
    error its arm leaves as the preset's bound bounds the identified arm's. The filter trusts the force to that
    bound. The name stays ``dvrk-calibrated`` (the policies shipped for it are the ones to run).

    Raises:
        ConfigurationError: A bound that is not finite and positive.
    """
    if not (math.isfinite(bound_n) and bound_n > 0.0):
        raise ConfigurationError("force sensing error bound", bound_n, "a finite bound > 0 N")
    preset = SENSING_PRESETS["dvrk-calibrated"]
    return preset.scaled(bound_n / error_bound_n(preset))


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


#: The safety settings that bound the held tissue, and what each bounds (for the messages).
TISSUE_BOUNDS = {
    "tissue_stiffness_bound_n_per_m": ("N/m", "the stiffest tissue", "2.64 E t at its stiffest modulus and thickness"),
    "held_load_bound_n": ("N", "the heaviest tissue", "1.2 x its weight at its largest size, density and thickness"),
}


def declared_tissue_bounds(config: SafetyConfig) -> dict[str, float]:
    """The tissue bounds ``config`` declares: those set to other than :class:`SafetyConfig`'s defaults (the task
    flap's). A configuration file that sets one declares what the user knows of the tissue."""
    defaults = SafetyConfig()
    return {
        name: float(getattr(config, name)) for name in TISSUE_BOUNDS if getattr(config, name) != getattr(defaults, name)
    }


def with_sensing(
    config: SafetyConfig,
    error_n: float,
    ranges: Mapping[str, tuple[float, float]],
    *,
    tissue_known: bool = True,
) -> SafetyConfig:
    """``config`` with a force-sensing error bound [N] and the tissue's bounds (what the filter keeps to).

    A tissue bound ``config`` declares (:func:`declared_tissue_bounds`) is kept. Where the run's tissue is known
    (``tissue_known``: the simulation draws it from ``ranges``), a declared bound below what those ranges reach
    is refused: the promise would not hold on the tissue the run draws. Where it is not (a dVRK: ``ranges`` are
    only the task flap's, assumed), the declaration is the user's word on the tissue and is taken as it is. A
    bound not declared is the ranges' own (:func:`tissue_bounds`).

    Raises:
        ConfigurationError: A declared bound below the run's tissue ranges' (``tissue_known`` only).
    """
    stiffness, load = tissue_bounds(ranges)
    bounds = {"tissue_stiffness_bound_n_per_m": stiffness, "held_load_bound_n": load}
    for name, value in declared_tissue_bounds(config).items():
        unit, what, rule = TISSUE_BOUNDS[name]
        if tissue_known and value < bounds[name] * (1.0 - 1e-9):
            raise ConfigurationError(
                name,
                value,
                f"at least {bounds[name]:.4g} {unit}, {what} this run draws ({rule}); leave it out to take "
                "that, or narrow the tissue's ranges",
            )
        bounds[name] = value
    return dataclasses.replace(
        config,
        force_sensing_error_n=float(error_n),
        tissue_stiffness_bound_n_per_m=bounds["tissue_stiffness_bound_n_per_m"],
        held_load_bound_n=bounds["held_load_bound_n"],
    )
