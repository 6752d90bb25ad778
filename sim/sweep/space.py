"""Parameter ranges from the command line, and the seeded trials sampled from them.

Grammar of one range (comma-separated on the command line):

* ``name=LOW:HIGH``   absolute values, sampled uniformly;
* ``name=LOW:HIGHx``  multiples of the nominal value (``stiffness=0.3:3x``), sampled log-uniformly,
  since a factor of 0.3 is as far from nominal as a factor of 3.3;
* ``name=VALUE``      a fixed value;
* ``name=LOW:HIGHkpa`` absolute values with their unit spelt out, for parameters that have one
  (``youngs_modulus=2:30kpa``); another unit is refused, naming the parameter's.

Integer parameters (``latency``, in whole policy steps) are sampled uniformly among the integers of their
range and gridded on integers; a multiple of their nominal value is refused.

Every trial's parameters depend only on the sweep seed and the trial's index, never on the order in
which trials run, so any backend and any resumption give the same trial the same parameters.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np

from psm_control.errors import ConfigurationError, UnknownVariantError

__all__ = ["ParameterRange", "Trial", "make_trials", "parse_ranges"]


@dataclass(frozen=True)
class ParameterRange:
    """One varied parameter.

    Attributes:
        name: Parameter name.
        low: Lower end (a multiplier when ``relative``).
        high: Upper end (a multiplier when ``relative``).
        relative: Values are multiples of the parameter's nominal value.
        integer: Values are whole numbers (the integers within ``low..high``).
        unit: Unit of the values, for reports (``""`` when they have none).
    """

    name: str
    low: float
    high: float
    relative: bool = False
    integer: bool = False
    unit: str = ""

    def sample(self, rng: np.random.Generator) -> float:
        """Draw one value (log-uniform for relative ranges, uniform among the integers for integer ones)."""
        if self.integer:
            return int(rng.integers(math.ceil(self.low), math.floor(self.high) + 1))
        if self.low == self.high:
            return self.low
        if self.relative:
            return float(math.exp(rng.uniform(math.log(self.low), math.log(self.high))))
        return float(rng.uniform(self.low, self.high))

    def levels(self, count: int) -> list[float]:
        """``count`` evenly spaced values (geometrically for relative ranges; distinct integers for integer ones)."""
        if self.integer:
            spaced = np.linspace(math.ceil(self.low), math.floor(self.high), count)
            return [int(v) for v in sorted({round(float(v)) for v in spaced})]
        if self.low == self.high or count == 1:
            return [self.low] if count == 1 or self.low == self.high else [self.low] * count
        if self.relative:
            return [float(v) for v in np.geomspace(self.low, self.high, count)]
        return [float(v) for v in np.linspace(self.low, self.high, count)]

    def describe(self) -> str:
        """The range as the user would write it."""
        suffix = "x" if self.relative else ""
        return f"{self.name}={self.low:g}:{self.high:g}{suffix}"


@dataclass(frozen=True)
class Trial:
    """One episode of a sweep.

    Attributes:
        index: Position in the sweep (stable across resumptions and backends).
        seed: Environment seed of the episode.
        params: Parameter values of this trial (multipliers for relative ranges).
    """

    index: int
    seed: int
    params: Mapping[str, float]

    def to_dict(self) -> dict[str, object]:
        """JSON-ready form."""
        return {"index": self.index, "seed": self.seed, "params": dict(self.params)}


def _number(field: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ConfigurationError(field, text, "a number") from None
    if not math.isfinite(value):
        raise ConfigurationError(field, text, "a finite number")
    return value


def _strip_unit(name: str, spec: str, unit: str | None) -> str:
    """``spec`` without its unit suffix; a suffix other than ``unit`` (or ``x``) is refused."""
    match = re.fullmatch(r"(.*?)([A-Za-z]*)", spec)
    body, suffix = (match.group(1), match.group(2)) if match else (spec, "")
    if suffix in ("", "x"):
        return spec
    if unit is None or suffix.lower() != unit.lower():
        allowed = f"LOW:HIGH{unit} or LOW:HIGHx" if unit else "LOW:HIGH or LOW:HIGHx, without a unit"
        raise ConfigurationError(f"vary.{name}", spec, allowed)
    return body


def parse_ranges(
    text: str,
    valid_names: Iterable[str] | None = None,
    units: Mapping[str, str] | None = None,
    *,
    integers: Iterable[str] = (),
    unit_labels: Mapping[str, str] | None = None,
) -> tuple[ParameterRange, ...]:
    """Parse ``"stiffness=0.3:3x,obs_noise=0:0.002"`` into ranges.

    Args:
        text: Comma-separated ranges (grammar in the module docstring).
        valid_names: If given, names outside it raise :class:`UnknownVariantError` listing them.
        units: The unit a parameter's absolute values may carry as a suffix (``{"youngs_modulus": "kpa"}``).
        integers: Names of the parameters that take whole numbers.
        unit_labels: The unit each parameter's values are in, for reports (``{"latency": "steps"}``).

    Raises:
        ConfigurationError: Malformed item, non-numeric or inverted bounds, duplicate name,
            non-positive relative bounds.
    """
    valid = tuple(valid_names) if valid_names is not None else None
    integer_names = frozenset(integers)
    ranges: list[ParameterRange] = []
    for item in (part.strip() for part in text.split(",")):
        if not item:
            continue
        name, sep, spec = item.partition("=")
        name = name.strip()
        if not sep or not name or not spec:
            raise ConfigurationError("vary", item, "NAME=LOW:HIGH, NAME=LOW:HIGHx or NAME=VALUE")
        if valid is not None and name not in valid:
            raise UnknownVariantError("vary", name, valid)
        if any(r.name == name for r in ranges):
            raise ConfigurationError("vary", name, "each parameter at most once")
        spec = _strip_unit(name, spec.strip(), (units or {}).get(name))
        relative = spec.endswith("x")
        low_text, colon, high_text = spec.rstrip("x").partition(":")
        low = _number(f"vary.{name}", low_text)
        high = _number(f"vary.{name}", high_text) if colon else low
        if high < low:
            raise ConfigurationError(f"vary.{name}", spec, f"LOW <= HIGH (got {low:g} > {high:g})")
        if relative and low <= 0.0:
            raise ConfigurationError(f"vary.{name}", spec, "multipliers > 0")
        integer = name in integer_names
        if integer and (relative or math.ceil(low) > math.floor(high)):
            raise ConfigurationError(
                f"vary.{name}", spec, "whole numbers: an absolute range holding an integer, e.g. 0:3"
            )
        ranges.append(ParameterRange(name, low, high, relative, integer, (unit_labels or {}).get(name, "")))
    if not ranges:
        raise ConfigurationError("vary", text, "at least one NAME=LOW:HIGH range")
    return tuple(ranges)


def make_trials(
    ranges: Iterable[ParameterRange], trials: int, *, mode: Literal["random", "grid"] = "random", seed: int = 0
) -> list[Trial]:
    """The trials of a sweep.

    Args:
        ranges: The varied parameters.
        trials: Number of trials (``random``), or levels per parameter (``grid``: the sweep holds
            ``trials ** len(ranges)`` trials).
        mode: ``"random"`` samples each trial independently; ``"grid"`` takes the Cartesian product of
            evenly spaced levels.
        seed: Sweep seed; trial i's environment seed is ``seed * 1_000_003 + i`` (mod 2**31).

    Raises:
        ConfigurationError: Non-positive trial count or unknown mode.
    """
    ranges = tuple(ranges)
    if trials < 1:
        raise ConfigurationError("trials", trials, "an integer >= 1")
    if mode == "random":
        points = []
        for index in range(trials):
            rng = np.random.default_rng([seed, index])
            points.append({r.name: r.sample(rng) for r in ranges})
    elif mode == "grid":
        levels = [r.levels(trials) for r in ranges]
        points = [dict(zip((r.name for r in ranges), combo, strict=True)) for combo in itertools.product(*levels)]
    else:
        raise ConfigurationError("mode", mode, "'random' or 'grid'")
    return [Trial(index, (seed * 1_000_003 + index) % 2**31, params) for index, params in enumerate(points)]
