"""Domain randomization: named parameter ranges, sampled from the environment's seeded generator.

Every parameter is drawn uniformly from its range at each reset (or log-uniformly, where asked: a
sweep's ``x`` range, as :mod:`sim.sweep.space` draws it); ``reset(options={name: value})`` fixes any of
them for that episode; ranges are configurable when the environment is made. Unknown names raise an
error listing the valid ones.

Streams. The parameters are drawn in order from the episode's generator, so a new parameter drawn from
it would shift every later draw. Parameters that only the camera sees (:data:`RENDER_PARAMETERS`) come
from a stream jumped once from the episode generator, and the dynamics disturbances
(:data:`DYNAMICS_PARAMETERS`) from one jumped twice (:meth:`Randomizer.dynamics_stream`), the force
sensing's scale (:data:`SENSING_PARAMETERS`) from one jumped three times; jumping copies
the bit generator without advancing it, so the same seed gives the same episode whatever these are.

Dynamics disturbances (safe-control-gym style, all 0 by default, and 0 changes nothing):

* ``joint_offset_rad``: encoder calibration error. Each arm joint's measurement is offset by this
  magnitude times a seeded unit-normal draw (the insertion joint in metres, at 0.01 m per rad); the
  controller and the observation see the offset joints, the physics the true ones.
* ``base_error_m``: registration error of the RCM/base in the world. The observation reports the tool
  pose through a believed base frame translated by a seeded vector of this norm.
* ``tracking_lag``: in [0, 1); the arm follows its joint set-point with a first-order lag per physics
  substep, ``q += (1 - lag) * (q_cmd - q)``.

``force_sensing_scale`` multiplies every error term of the episode's force-sensing model
(:mod:`sim.force_sensing`; 1 by default, and nothing with ``--force-sensing ideal``): a sweep over it asks
what happens when the robot's sensing is worse, or better, than the model the filter's error bound is from.
"""

from __future__ import annotations

import copy
from collections.abc import Iterable, Mapping

import numpy as np

from psm_control.errors import ConfigurationError, UnknownVariantError

__all__ = [
    "DEFAULT_RANGES",
    "DYNAMICS_PARAMETERS",
    "INSERTION_M_PER_RAD",
    "INTEGER_PARAMETERS",
    "PARAMETER_LIMITS",
    "RENDER_PARAMETERS",
    "SENSING_PARAMETERS",
    "Randomizer",
]

#: Default ranges (low, high), SI units unless the name says otherwise. Colours are RGB in [0, 1].
DEFAULT_RANGES: dict[str, tuple[float, float]] = {
    "tissue_youngs_modulus_kpa": (6.0, 14.0),
    "tissue_damping": (0.03, 0.08),
    "tissue_density_kg_m3": (1000.0, 1100.0),
    "tissue_size_m": (0.07, 0.09),
    "tissue_color_r": (0.7, 0.95),
    "tissue_color_g": (0.3, 0.5),
    "tissue_color_b": (0.3, 0.5),
    "tissue_texture_seed": (0.0, 9999.0),
    "tissue_x_m": (-0.01, 0.01),
    "tissue_y_m": (-0.01, 0.01),
    "site_offset_x_m": (-0.003, 0.003),
    "site_offset_y_m": (-0.002, 0.002),
    "gravity_m_s2": (9.6, 10.0),
    "grip_friction": (0.45, 0.6),
    "rcm_x_m": (-0.01, 0.01),
    "rcm_y_m": (-0.01, 0.01),
    "rcm_z_m": (-0.005, 0.005),
    "observation_noise_m": (0.0, 0.0005),
    "action_latency_steps": (0.0, 1.0),
    "joint_offset_rad": (0.0, 0.0),
    "base_error_m": (0.0, 0.0),
    "tracking_lag": (0.0, 0.0),
    # Drawn last, so that a thickness range leaves every other draw of a seed as it was.
    "tissue_thickness_mm": (3.0, 3.0),
    "force_sensing_scale": (1.0, 1.0),
}

#: Parameters drawn as integers (inclusive range).
INTEGER_PARAMETERS = frozenset({"action_latency_steps", "tissue_texture_seed"})

#: Parameters that change only what the camera sees (see the module's note on their stream).
RENDER_PARAMETERS = frozenset({"tissue_texture_seed"})

#: Dynamics disturbances, drawn from their own stream (see the module's note).
DYNAMICS_PARAMETERS = ("joint_offset_rad", "base_error_m", "tracking_lag")

#: The force sensing's error terms' scale (sim.force_sensing), drawn from a stream of its own.
SENSING_PARAMETERS = frozenset({"force_sensing_scale"})

#: Encoder offset of the insertion joint per unit of ``joint_offset_rad`` [m/rad].
INSERTION_M_PER_RAD = 0.01

#: Allowed values of every parameter: (minimum, maximum, maximum included). Physical bounds, wide enough for
#: any sweep of a soft-tissue flap on the PSM, narrow enough that every episode stays a meaningful one
#: (docs/robustness.md lists the reasons): a latency beyond an episode's steps never applies an action, an
#: observation noise of centimetres hides the flap, a 1e9-step latency once filled memory.
PARAMETER_LIMITS: dict[str, tuple[float, float, bool]] = {
    "tissue_youngs_modulus_kpa": (0.1, 1000.0, True),  # brain to skin and tendon
    "tissue_damping": (0.0, 1.0, True),
    "tissue_density_kg_m3": (500.0, 2000.0, True),  # fat to bone
    "tissue_size_m": (0.06, 0.16, True),  # the three sites, offset as below, stay on the flap
    "tissue_color_r": (0.0, 1.0, True),
    "tissue_color_g": (0.0, 1.0, True),
    "tissue_color_b": (0.0, 1.0, True),
    "tissue_texture_seed": (0.0, 2**31 - 1, True),
    "tissue_x_m": (-0.05, 0.05, True),
    "tissue_y_m": (-0.05, 0.05, True),
    "site_offset_x_m": (-0.003, 0.003, True),
    "site_offset_y_m": (-0.003, 0.003, True),
    "gravity_m_s2": (0.0, 20.0, True),
    "grip_friction": (0.0, 2.0, True),
    "rcm_x_m": (-0.05, 0.05, True),
    "rcm_y_m": (-0.05, 0.05, True),
    "rcm_z_m": (-0.03, 0.03, True),
    "observation_noise_m": (0.0, 0.01, True),  # 1 cm: near half the flap's site spacing (22 mm)
    "action_latency_steps": (0.0, 50.0, True),  # an episode's steps (sim.envs.MAX_EPISODE_STEPS)
    "joint_offset_rad": (0.0, 0.2, True),
    "base_error_m": (0.0, 0.05, True),
    "tracking_lag": (0.0, 1.0, False),
    "tissue_thickness_mm": (0.5, 20.0, True),
    "force_sensing_scale": (0.0, 100.0, True),
}


def _check_limits(name: str, value: float) -> None:
    if name not in PARAMETER_LIMITS:
        return
    low, high, closed = PARAMETER_LIMITS[name]
    if not (value >= low and (value <= high if closed else value < high)):
        bracket = "]" if closed else ")"
        raise ConfigurationError(name, value, f"a value in [{low:g}, {high:g}{bracket}")


def _jumped(rng: np.random.Generator, jumps: int) -> np.random.Generator:
    """A generator on ``rng``'s bit generator jumped ``jumps`` times (a copy where it cannot jump)."""
    jump = getattr(rng.bit_generator, "jumped", None)
    if jump is not None:
        return np.random.Generator(jump(jumps))
    return copy.deepcopy(rng)


class Randomizer:
    """Samples one episode's parameters.

    Args:
        ranges: Overrides of :data:`DEFAULT_RANGES` by name; ``(v, v)`` fixes a parameter for good.
        log_uniform: Parameters drawn log-uniformly (a factor of 0.3 as likely as one of 3.3); their
            ranges must be above 0. One draw each, as a uniform one, so no other draw moves.

    Raises:
        UnknownVariantError: A name that is not a parameter (the valid names are listed).
        ConfigurationError: A range whose low end is above its high end, or not finite; a log-uniform
            range that reaches 0, or an integer parameter drawn log-uniformly.
    """

    def __init__(
        self, ranges: Mapping[str, tuple[float, float]] | None = None, log_uniform: Iterable[str] = ()
    ) -> None:
        self.ranges = dict(DEFAULT_RANGES)
        for name, bounds in (ranges or {}).items():
            self.check_name(name)
            low, high = (float(v) for v in bounds)
            if not (np.isfinite(low) and np.isfinite(high) and low <= high):
                raise ConfigurationError(name, bounds, "a finite (low, high) range with low <= high")
            _check_limits(name, low)
            _check_limits(name, high)
            self.ranges[name] = (low, high)
        self.log_uniform = frozenset(log_uniform)
        for name in self.log_uniform:
            self.check_name(name)
            if name in INTEGER_PARAMETERS or not self.ranges[name][0] > 0.0:
                raise ConfigurationError(
                    f"{name} (log-uniform)", self.ranges[name], "a range above 0 of a parameter that is no integer"
                )

    def check_name(self, name: str) -> None:
        """Raise if ``name`` is not a randomization parameter."""
        if name not in self.ranges:
            raise UnknownVariantError("randomization parameter", name, sorted(self.ranges))

    @staticmethod
    def dynamics_stream(rng: np.random.Generator) -> np.random.Generator:
        """The dynamics disturbances' stream: ``rng``'s bit generator jumped twice (``rng`` is not advanced)."""
        return _jumped(rng, 2)

    @staticmethod
    def sensing_stream(rng: np.random.Generator) -> np.random.Generator:
        """The force sensing's stream: ``rng``'s bit generator jumped three times (``rng`` is not advanced)."""
        return _jumped(rng, 3)

    def sample(
        self,
        rng: np.random.Generator,
        fixed: Mapping[str, float] | None = None,
        dynamics_rng: np.random.Generator | None = None,
    ) -> dict[str, float]:
        """Draw every parameter, keeping the ``fixed`` ones at their given values.

        Args:
            rng: The episode generator.
            fixed: Values that replace the draws (they are still drawn, so later draws do not move).
            dynamics_rng: Stream of the dynamics disturbances; None: :meth:`dynamics_stream` of ``rng``.
        """
        fixed = dict(fixed or {})
        for name in fixed:
            self.check_name(name)
        jump = getattr(rng.bit_generator, "jumped", None)
        render_rng = np.random.Generator(jump()) if jump is not None else rng
        dynamics = dynamics_rng if dynamics_rng is not None else self.dynamics_stream(rng)
        sensing = self.sensing_stream(rng)
        values: dict[str, float] = {}
        for name, (low, high) in self.ranges.items():
            if name in DYNAMICS_PARAMETERS:
                source = dynamics
            elif name in SENSING_PARAMETERS:
                source = sensing
            else:
                source = render_rng if name in RENDER_PARAMETERS else rng
            if name in INTEGER_PARAMETERS:
                drawn = float(source.integers(int(low), int(high) + 1))
            elif name in self.log_uniform:
                drawn = float(np.exp(source.uniform(np.log(low), np.log(high))))
            else:
                drawn = float(source.uniform(low, high))
            value = float(fixed.get(name, drawn))
            if not np.isfinite(value):
                raise ConfigurationError(name, value, "a finite number")
            _check_limits(name, value)
            values[name] = value
        return values
