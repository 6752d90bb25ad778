"""Robustness sweeps: one policy, many episodes, each under its own sampled conditions.

A sweep parameter is either a randomization parameter of the simulation (passed to
``reset(options=...)``; multipliers of ``x`` ranges apply to the middle of its default range) or a
disturbance in the manner of safe-control-gym (white noise, an impulse or a step on the observation
or the action, and action latency). Short names stand for the common ones (``stiffness``, ``size``,
``obs_noise``, ``latency``...). This module turns a trial's parameters into ``reset`` options and
disturbances; running the trial with a policy is the sweep worker's job.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import NamedTuple

from psm_control.errors import ConfigurationError
from sim.disturbances import Disturbance
from sim.randomization import DEFAULT_RANGES, INTEGER_PARAMETERS, PARAMETER_LIMITS
from sim.sweep.space import ParameterRange, parse_ranges

__all__ = [
    "ALIASES",
    "DISTURBANCE_LIMITS",
    "DISTURBANCE_PARAMETERS",
    "TrainingRanges",
    "allowed_range",
    "check_limits",
    "check_relative_ranges",
    "disturbances",
    "episode_options",
    "integer_parameters",
    "parameter_unit_labels",
    "parameter_units",
    "parse_vary",
    "sweep_parameters",
    "sweep_ranges",
    "training_ranges",
]

#: Short names accepted on the command line.
ALIASES: dict[str, str] = {
    "stiffness": "tissue_youngs_modulus_kpa",
    "youngs_modulus": "tissue_youngs_modulus_kpa",
    "thickness": "tissue_thickness_mm",
    "density": "tissue_density_kg_m3",
    "damping": "tissue_damping",
    "size": "tissue_size_m",
    "gravity": "gravity_m_s2",
    "friction": "grip_friction",
    "obs_noise": "observation_noise_m",
    "latency": "action_latency_steps",
    "joint_offset": "joint_offset_rad",
    "base_error": "base_error_m",
    "sensing_scale": "force_sensing_scale",
}

#: Units a range of these parameters may name (``youngs_modulus=2:30kpa``); the values are in them anyway.
_UNITS = {"tissue_youngs_modulus_kpa": "kpa", "tissue_thickness_mm": "mm"}

#: Units of values by the suffix of their full name, as reports print them (longest suffix first).
_SUFFIX_UNIT_LABELS = (
    ("_kg_m3", "kg/m^3"),
    ("_m_s2", "m/s^2"),
    ("_steps", "policy steps"),
    ("_kpa", "kPa"),
    ("_rad", "rad"),
    ("_mm", "mm"),
    ("_m", "m"),
)

#: Disturbances (safe-control-gym style), all sampled per trial. Observation offsets are in metres
#: (the observation is positions in metres), action offsets in normalised action units.
DISTURBANCE_PARAMETERS: dict[str, str] = {
    "obs_white_m": "white noise on the observation vector, standard deviation [m]",
    "obs_impulse_m": "impulse on the observation for 3 steps from step 10 [m]",
    "obs_step_m": "step offset on the observation from step 10 [m]",
    "action_white": "white noise on the action, standard deviation [action units]",
    "action_impulse": "impulse on the action for 3 steps from step 10 [action units]",
    "action_step": "step offset on the action from step 10 [action units]",
}

#: Allowed magnitudes of the disturbances (standard deviations, offsets' norms): the observation is positions
#: in metres, and 5 cm is farther than the flap's sites are from each other; the action is normalised to
#: [-1, 1], and an offset of 2 already takes any action across it.
DISTURBANCE_LIMITS: dict[str, tuple[float, float]] = {
    "obs_white_m": (0.0, 0.05),
    "obs_impulse_m": (0.0, 0.05),
    "obs_step_m": (0.0, 0.05),
    "action_white": (0.0, 2.0),
    "action_impulse": (0.0, 2.0),
    "action_step": (0.0, 2.0),
}

_IMPULSE_START, _IMPULSE_STEPS = 10, 3


def sweep_parameters() -> tuple[str, ...]:
    """Every name a sweep can vary: randomization parameters, their short names, disturbances."""
    return (*ALIASES, *DEFAULT_RANGES, *DISTURBANCE_PARAMETERS)


def integer_parameters() -> frozenset[str]:
    """Sweep names (short and full) of the parameters that take whole numbers (``latency`` in steps)."""
    return frozenset(INTEGER_PARAMETERS) | {alias for alias, full in ALIASES.items() if full in INTEGER_PARAMETERS}


def parameter_unit_labels() -> dict[str, str]:
    """The unit each sweep name's values are in, for reports (``{"latency": "policy steps", ...}``)."""
    labels = {}
    for name in sweep_parameters():
        full = ALIASES.get(name, name)
        label = next((unit for suffix, unit in _SUFFIX_UNIT_LABELS if full.endswith(suffix)), "")
        if full.startswith("action_") and not label:
            label = "action units"
        if label:
            labels[name] = label
    return labels


def parameter_units() -> dict[str, str]:
    """The unit suffix each sweep name with a unit accepts, under its short and its full name."""
    units = dict(_UNITS)
    units.update({alias: _UNITS[full] for alias, full in ALIASES.items() if full in _UNITS})
    return units


def nominal(name: str) -> float:
    """The nominal value of a randomization parameter: the middle of its default range."""
    low, high = DEFAULT_RANGES[ALIASES.get(name, name)]
    return (low + high) / 2.0


def check_relative_ranges(ranges: Iterable[ParameterRange]) -> None:
    """Refuse ``x`` ranges on parameters without a non-zero nominal value (a multiple of 0 is always 0), and
    negative disturbance magnitudes (a standard deviation or an offset's norm is at least 0).

    Raises:
        ConfigurationError: Naming the parameter and asking for an absolute range (of magnitudes >= 0).
    """
    for r in ranges:
        full = ALIASES.get(r.name, r.name)
        if r.relative and (full not in DEFAULT_RANGES or nominal(full) == 0.0):
            raise ConfigurationError(
                f"vary.{r.name}", r.describe(), "an absolute LOW:HIGH range (its nominal value is 0)"
            )
        if r.name in DISTURBANCE_PARAMETERS and r.low < 0.0:
            raise ConfigurationError(f"vary.{r.name}", r.describe(), "a range of magnitudes >= 0")


def allowed_range(name: str) -> tuple[float, float, bool]:
    """The values a sweep parameter may take, in its unit: ``(minimum, maximum, maximum included)``."""
    if name in DISTURBANCE_LIMITS:
        return (*DISTURBANCE_LIMITS[name], True)
    return PARAMETER_LIMITS[ALIASES.get(name, name)]


def check_limits(ranges: Iterable[ParameterRange]) -> None:
    """Refuse a range that reaches outside its parameter's allowed values (:func:`allowed_range`); a multiple
    of nominal is checked as the value it stands for.

    Raises:
        ConfigurationError: Naming the parameter, the allowed values and their unit (and, for a multiple,
            the multiples they allow).
    """
    labels = parameter_unit_labels()
    for r in ranges:
        low, high, closed = allowed_range(r.name)
        scale = nominal(r.name) if r.relative else 1.0
        if all(low <= v * scale and (v * scale <= high if closed else v * scale < high) for v in (r.low, r.high)):
            continue
        unit = f" {labels[r.name]}" if r.name in labels else ""
        allowed = f"values within [{low:.10g}, {high:.10g}{']' if closed else ')'}{unit}"
        if r.relative:
            allowed += f": multiples {low / scale:.4g}-{high / scale:.4g}x of its nominal {scale:.4g}{unit}"
        raise ConfigurationError(f"vary.{r.name}", r.describe(), allowed)


def parse_vary(text: str) -> tuple[ParameterRange, ...]:
    """``--vary`` as ``robustness`` and ``train`` both take it: the names of :func:`sweep_parameters`, their
    units, whole numbers for :func:`integer_parameters`, and the checks of :func:`check_relative_ranges` and
    :func:`check_limits`.

    Raises:
        UnknownVariantError: A name that is no sweep parameter (the valid ones are listed).
        ConfigurationError: A malformed or impossible range, naming it and what is allowed.
    """
    ranges = parse_ranges(
        text,
        valid_names=sweep_parameters(),
        units=parameter_units(),
        integers=integer_parameters(),
        unit_labels=parameter_unit_labels(),
    )
    check_relative_ranges(ranges)
    check_limits(ranges)
    return ranges


def sweep_ranges(
    ranges: Iterable[tuple[str, float, float, bool]],
) -> dict[str, tuple[float, float]]:
    """The randomization ranges an environment of a sweep declares: the defaults widened to the swept ones.

    A sweep fixes each swept parameter per episode (:func:`episode_options`), so these ranges draw nothing
    new; they tell the safety layer what tissue the sweep may meet (its stiffness and load bounds,
    :func:`sim.force_sensing.tissue_bounds`), as a user declares the tissue range they deploy on.

    Args:
        ranges: ``(name, low, high, relative)`` per swept parameter.
    """
    declared: dict[str, tuple[float, float]] = {}
    for name, low, high, relative in ranges:
        full = ALIASES.get(name, name)
        if full not in DEFAULT_RANGES:
            continue
        scale = nominal(full) if relative else 1.0
        default_low, default_high = DEFAULT_RANGES[full]
        declared[full] = (min(default_low, low * scale), max(default_high, high * scale))
    return declared


class TrainingRanges(NamedTuple):
    """What a training run draws each episode from ``--vary``'s ranges.

    Attributes:
        randomization: The simulation's randomization ranges by full name, absolute
            (:class:`sim.randomization.Randomizer` draws them at each reset).
        log_uniform: The full names of those given as multiples of nominal (``x``), drawn log-uniformly
            as a sweep draws them.
        disturbances: The disturbances' ranges, as parsed (:class:`sim.drawn_disturbances.DrawnDisturbanceWrapper`
            draws their magnitudes at each reset, as a sweep draws a trial's).
    """

    randomization: dict[str, tuple[float, float]]
    log_uniform: frozenset[str]
    disturbances: tuple[ParameterRange, ...]


def training_ranges(ranges: Iterable[ParameterRange]) -> TrainingRanges:
    """What a training run draws from: each randomization parameter's range made absolute (log-uniform where
    it was a multiple), and the disturbances' ranges as they are."""
    drawn: dict[str, tuple[float, float]] = {}
    log_uniform: set[str] = set()
    disturbed: list[ParameterRange] = []
    for r in ranges:
        if r.name in DISTURBANCE_PARAMETERS:
            disturbed.append(r)
            continue
        full = ALIASES.get(r.name, r.name)
        scale = nominal(full) if r.relative else 1.0
        drawn[full] = (r.low * scale, r.high * scale)
        if r.relative:
            log_uniform.add(full)
        else:
            log_uniform.discard(full)  # the last range of a parameter is the one drawn (stiffness, youngs_modulus)
    return TrainingRanges(drawn, frozenset(log_uniform), tuple(disturbed))


def episode_options(params: Mapping[str, float], relative: Mapping[str, bool]) -> dict[str, float]:
    """The ``reset`` options of a trial: its randomization parameters as absolute values."""
    options: dict[str, float] = {}
    for name, value in params.items():
        if name in DISTURBANCE_PARAMETERS:
            continue
        full = ALIASES.get(name, name)
        absolute = value * nominal(full) if relative.get(name, False) else value
        options[full] = float(round(absolute)) if full in INTEGER_PARAMETERS else float(absolute)
    return options


def disturbances(params: Mapping[str, float]) -> tuple[tuple[Disturbance, ...], tuple[Disturbance, ...]]:
    """The observation and action disturbances a trial's parameters ask for."""

    def make(prefix: str, unit: str) -> tuple[Disturbance, ...]:
        made = []
        if params.get(f"{prefix}_white{unit}", 0.0) > 0.0:
            made.append(Disturbance("white_noise", params[f"{prefix}_white{unit}"]))
        if params.get(f"{prefix}_impulse{unit}", 0.0) > 0.0:
            made.append(Disturbance("impulse", params[f"{prefix}_impulse{unit}"], _IMPULSE_START, _IMPULSE_STEPS))
        if params.get(f"{prefix}_step{unit}", 0.0) > 0.0:
            made.append(Disturbance("step", params[f"{prefix}_step{unit}"], _IMPULSE_START))
        return tuple(made)

    return make("obs", "_m"), make("action", "")
