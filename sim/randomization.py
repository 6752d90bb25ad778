"""Domain randomization: named parameter ranges, sampled from the environment's seeded generator.

Every parameter is drawn uniformly from its range at each reset; ``reset(options={name: value})``
fixes any of them for that episode; ranges are configurable when the environment is made. Unknown
names raise an error listing the valid ones.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from psm_control.errors import ConfigurationError, UnknownVariantError

__all__ = ["DEFAULT_RANGES", "INTEGER_PARAMETERS", "RENDER_PARAMETERS", "Randomizer"]

#: Default ranges (low, high), SI units. Colours are RGB in [0, 1].
DEFAULT_RANGES: dict[str, tuple[float, float]] = {
    "tissue_stiffness_n_per_m": (15.0, 30.0),
    "tissue_damping": (0.03, 0.08),
    "tissue_mass_kg": (0.015, 0.025),
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
}

#: Parameters drawn as integers (inclusive range).
INTEGER_PARAMETERS = frozenset({"action_latency_steps", "tissue_texture_seed"})

#: Parameters that change only what the camera sees (see the module's note on their stream).
RENDER_PARAMETERS = frozenset({"tissue_texture_seed"})


class Randomizer:
    """Samples one episode's parameters.

    Args:
        ranges: Overrides of :data:`DEFAULT_RANGES` by name; ``(v, v)`` fixes a parameter for good.

    Raises:
        UnknownVariantError: A name that is not a parameter (the valid names are listed).
        ConfigurationError: A range whose low end is above its high end, or not finite.
    """

    def __init__(self, ranges: Mapping[str, tuple[float, float]] | None = None) -> None:
        self.ranges = dict(DEFAULT_RANGES)
        for name, bounds in (ranges or {}).items():
            self.check_name(name)
            low, high = (float(v) for v in bounds)
            if not (np.isfinite(low) and np.isfinite(high) and low <= high):
                raise ConfigurationError(name, bounds, "a finite (low, high) range with low <= high")
            self.ranges[name] = (low, high)

    def check_name(self, name: str) -> None:
        """Raise if ``name`` is not a randomization parameter."""
        if name not in self.ranges:
            raise UnknownVariantError("randomization parameter", name, sorted(self.ranges))

    def sample(self, rng: np.random.Generator, fixed: Mapping[str, float] | None = None) -> dict[str, float]:
        """Draw every parameter, keeping the ``fixed`` ones at their given values."""
        fixed = dict(fixed or {})
        for name in fixed:
            self.check_name(name)
        jump = getattr(rng.bit_generator, "jumped", None)
        render_rng = np.random.Generator(jump()) if jump is not None else rng
        values: dict[str, float] = {}
        for name, (low, high) in self.ranges.items():
            source = render_rng if name in RENDER_PARAMETERS else rng
            if name in INTEGER_PARAMETERS:
                drawn = float(source.integers(int(low), int(high) + 1))
            else:
                drawn = float(source.uniform(low, high))
            value = float(fixed.get(name, drawn))
            if not np.isfinite(value):
                raise ConfigurationError(name, value, "a finite number")
            values[name] = value
        return values

    def extremes(self, rng: np.random.Generator) -> dict[str, float]:
        """Every parameter at its low or high end, chosen at random (for robustness tests)."""
        return {name: float(bounds[int(rng.integers(2))]) for name, bounds in self.ranges.items()}
