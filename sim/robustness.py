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

from psm_control.errors import ConfigurationError
from sim.disturbances import Disturbance
from sim.randomization import DEFAULT_RANGES, INTEGER_PARAMETERS
from sim.sweep.space import ParameterRange

__all__ = [
    "ALIASES",
    "DISTURBANCE_PARAMETERS",
    "check_relative_ranges",
    "disturbances",
    "episode_options",
    "parameter_units",
    "sweep_parameters",
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
}

#: Units a range of these parameters may name (``youngs_modulus=2:30kpa``); the values are in them anyway.
_UNITS = {"tissue_youngs_modulus_kpa": "kpa", "tissue_thickness_mm": "mm"}

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

_IMPULSE_START, _IMPULSE_STEPS = 10, 3


def sweep_parameters() -> tuple[str, ...]:
    """Every name a sweep can vary: randomization parameters, their short names, disturbances."""
    return (*ALIASES, *DEFAULT_RANGES, *DISTURBANCE_PARAMETERS)


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
    """Refuse ``x`` ranges on parameters without a non-zero nominal value (a multiple of 0 is always 0).

    Raises:
        ConfigurationError: Naming the parameter and asking for an absolute range.
    """
    for r in ranges:
        if not r.relative:
            continue
        full = ALIASES.get(r.name, r.name)
        if full not in DEFAULT_RANGES or nominal(full) == 0.0:
            raise ConfigurationError(
                f"vary.{r.name}", r.describe(), "an absolute LOW:HIGH range (its nominal value is 0)"
            )


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
