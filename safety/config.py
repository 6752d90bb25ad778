"""One validated configuration for the whole safety layer, loadable from TOML or YAML.

Joint velocity limits default to the dVRK's ``move_jp`` trajectory limits; acceleration and jerk limits
default to servo values well above ``move_jp``'s profile (the dVRK applies none to ``servo_jp``); the
minimum insertion is the dVRK's 45 mm SafeDistanceFromRCM plus its 2 mm buffer; the retraction-force
limit comes from a per-tissue preset (table below, sources in ``../shared/facts/tissue-forces.md``)
unless given explicitly.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from psm_control.errors import ConfigurationError, UnknownVariantError
from psm_control.inputs import load_yaml, read_text
from psm_control.spec import PsmSpec, psm_spec

__all__ = [
    "DEADMAN_MIN_PERIODS",
    "FORCE_PRESETS",
    "MAX_CONTROL_RATE_HZ",
    "MAX_FORCE_LIMIT_N",
    "MIN_CONTROL_RATE_HZ",
    "MIN_FORCE_LIMIT_N",
    "ForcePreset",
    "SafetyConfig",
    "load_safety_config",
]


@dataclass(frozen=True)
class ForcePreset:
    """A retraction-force limit for one kind of tissue, with where the number comes from."""

    force_limit_n: float
    source: str


#: Retraction-force limits [N] per tissue. Each stays at or below the published tolerance.
FORCE_PRESETS: dict[str, ForcePreset] = {
    "generic": ForcePreset(
        3.0, "conservative 1-5 N range for delicate tissue; below liver's 3.38 N max grasp (MITAT 2022)"
    ),
    "nerve": ForcePreset(0.4, "nervous tissue about 0.4 N (Golahmadi et al., 2021 systematic review)"),
    "fallopian_tube": ForcePreset(1.25, "suture traction tolerated 1.25 N (Rodrigues et al., Surg Endosc 2012)"),
    "liver": ForcePreset(1.75, "mean grasping force 1.75 N, damage grows with force (MITAT 2022)"),
    "bowel": ForcePreset(
        5.0, "pulled at 5 N without slip (Heijnsdijk et al., Surg Endosc 2004); damage >= 20 N (Surg Endosc 2018)"
    ),
    "ureter": ForcePreset(6.0, "6-8 N safety threshold, lower end (urology scoping review, 2025)"),
    "fascia": ForcePreset(11.43, "suture traction tolerated 11.43 N (Rodrigues et al., Surg Endosc 2012)"),
}

_DVRK_MIN_INSERTION_M = 0.045

#: Allowed control rates [Hz]: 20 Hz for coarse simulation ticks up to 5 kHz for a hardware-side loop.
MIN_CONTROL_RATE_HZ = 20.0
MAX_CONTROL_RATE_HZ = 5000.0
#: The deadman timeout must span at least this many control periods (one for the measurement's age
#: when it is used, one for a single late or dropped message).
DEADMAN_MIN_PERIODS = 2


#: Lowest retraction-force limit [N]: below the smallest forces reported in surgery (sharp dissection
#: 0.03 N, ophthalmology 0.04 N; Golahmadi et al. 2021) no force signal of the PSM tells a pull from
#: noise. Limits near it are allowed (a limit below the held tissue's static load is warned about at
#: grasp); the most delicate preset (nerve) is 0.4 N.
MIN_FORCE_LIMIT_N = 0.01
#: The largest force limit the filter takes [N].
MAX_FORCE_LIMIT_N = 50.0
#: Plausible joint-limit settings as multiples of the dVRK's move_jp limits of each joint: from
#: ``low`` (slower than this never reaches a target) to ``high`` (faster than any arm can servo).
_RATE_FACTORS: dict[str, tuple[float, float]] = {
    "velocity_limit": (1e-3, 10.0),
    "acceleration_limit": (1e-3, 100.0),
    "jerk_limit": (1e-3, 1e5),
}


def _is_number(value: object) -> bool:
    """A real number: an int or a float, never a bool (``true`` is not 1 N) or a string."""
    return isinstance(value, int | float) and not isinstance(value, bool)


def _positive(name: str, value: float, upper: float = math.inf, lower: float = 0.0) -> None:
    """Refuse anything but a finite number in (0, upper], or in [lower, upper] when ``lower`` > 0."""
    inside = _is_number(value) and math.isfinite(value) and value <= upper
    inside = inside and (value >= lower if lower > 0.0 else value > 0.0)
    if not inside:
        interval = f"[{lower:g}, {upper:g}]" if lower > 0.0 else f"(0, {upper:g}]"
        raise ConfigurationError(name, value, f"a finite number in {interval}")


def _vector(name: str, value: object, length: int, *, positive: bool = False) -> None:
    items = list(value) if isinstance(value, list | tuple) else None
    if items is None or len(items) != length or not all(_is_number(v) and math.isfinite(v) for v in items):
        raise ConfigurationError(name, value, f"a list of {length} finite numbers")
    if positive and not all(v > 0.0 for v in items):
        raise ConfigurationError(name, value, f"{length} numbers > 0")


@dataclass(frozen=True)
class SafetyConfig:
    """Every limit and setting of the control chain's safety layer.

    Attributes:
        arm: PSM generation (``"classic"`` or ``"si"``); joint limits come from its specification.
        tool: Instrument part number (None: the arm's large needle driver).
        control_rate_hz: Rate of :meth:`ControlChain.tick` [Hz], 20 to 5000. The default 100 Hz is the
            dVRK's CRTK publishing rate (measured_js and friends every 10 ms), at which a ROS 2 client
            servos; the simulation ticks at 20-100 Hz between physics substeps for speed; a
            hardware-side loop may run up to the dVRK's own 1.5 kHz and beyond.
        horizon_s: Look-ahead over which one tick's goal step may move each joint at its velocity limit [s].
        velocity_limit: Per-joint speed limits (6,) [rad/s, m/s]; None: the dVRK's move_jp limits.
        acceleration_limit: Per-joint acceleration limits (6,); default: the servo limits below; None: the
            dVRK's move_jp limits.
        jerk_limit: Per-joint jerk limits (6,); None: ``jerk_per_acceleration`` times the acceleration limits.
        jerk_per_acceleration: Jerk limit as a multiple of the acceleration limit [1/s].
        position_margin: Distance kept from each joint's position limits (6,) [rad, m].
        min_insertion_m: Lowest insertion past the RCM [m]; at least the dVRK's 0.045.
        workspace_min_m: Lower corner of the tool-tip box in the base frame (3,) [m].
        workspace_max_m: Upper corner of the tool-tip box in the base frame (3,) [m].
        workspace_tolerance_m: How far outside the box the verifier lets a command go [m].
        cbf_gamma: Control-barrier rate in (0, 1]: the fraction of the distance to a face one step may use.
        tissue: Name of the force preset (see :data:`FORCE_PRESETS`).
        force_limit_n: Retraction-force limit [N]; None: the tissue preset's value.
        stiffness_prior_n_per_m: Initial tissue stiffness estimate (deliberately stiff: conservative) [N/m].
        stiffness_min_n_per_m: Lowest stiffness the force limit will ever assume [N/m].
        stiffness_max_n_per_m: Highest stiffness estimate accepted [N/m].
        stiffness_forgetting: RLS forgetting factor in (0.5, 1].
        force_sensing_error_n: How far the measured force may be from the true one [N]: 0 for an exact
            sensor; the force-sensing model's bound for the dVRK's ``measured_cf``, or a wrench
            calibration's (:mod:`safety.force_bound`). The filter trusts a measurement no further.
        tissue_stiffness_bound_n_per_m: The stiffest the held tissue can pull back per metre of the grasp
            point's travel since the grasp [N/m]: keeps the force limit where the measurement cannot.
        held_load_bound_n: The most the held tissue can load the jaws at the moment of the grasp [N]
            (its weight, the press of the grasp).
        deadman_timeout_s: Measurements older than this stop the chain [s]; at least
            :data:`DEADMAN_MIN_PERIODS` control periods, since a fresh measurement is already one period
            old when the tick that uses it runs.
        max_translation_m: Largest accepted translation in one policy target [m]; larger is refused.
        max_yaw_rad: Largest accepted yaw in one policy target [rad].
        solver_eps: OSQP absolute and relative tolerance (of the filter's normalised rows; hard bounds are
            clipped exactly and re-checked after every solve).
        solver_max_iter: OSQP iteration cap.
        hard_tolerance: Violation of a hard constraint after the solve above which the tick stops.
        slack_penalty: Linear and quadratic penalty on the slack of soft constraints, per unit of
            normalised slack (one unit: a violation as large as the limit's largest row moves in one full
            step). While every soft row's multiplier stays below it, the slack is exactly zero.
    """

    arm: str = "classic"
    tool: str | None = None
    control_rate_hz: float = 100.0
    horizon_s: float = 0.05
    velocity_limit: tuple[float, ...] | None = None
    # Servo acceleration limits [rad/s^2, m/s^2]. The dVRK limits only move_jp's trajectory (yaw/pitch
    # 1.57 rad/s^2, insertion 0.2 m/s^2) and applies none to servo_jp; with those the chain moved the tool
    # 1.6 mm per 50 ms when 5 mm was asked (measured in the simulation). Yaw/pitch 10 rad/s^2 is about
    # 1.2 m/s^2 at the tip 0.12 m below the RCM, matching insertion's 1 m/s^2: brisk hand-speed
    # servoing, still bounded. Roll and wrist carry only the instrument's small inertia (move_jp
    # already allows them 8x yaw/pitch); 40 rad/s^2 keeps them from holding back the arm joints,
    # which Ruckig time-synchronises with them.
    acceleration_limit: tuple[float, ...] | None = (10.0, 10.0, 1.0, 40.0, 40.0, 40.0)
    jerk_limit: tuple[float, ...] | None = None
    # Jerk = 100/s x acceleration: full acceleration is reached in 10 ms (10 ticks at 1 kHz, the dVRK
    # servo loop's 15 ticks). At 20/s the 50 ms ramp alone took a whole policy step (measured).
    jerk_per_acceleration: float = 100.0
    position_margin: tuple[float, ...] = (0.02, 0.02, 0.002, 0.05, 0.02, 0.02)
    min_insertion_m: float = 0.047
    workspace_min_m: tuple[float, float, float] = (-0.07, -0.07, -0.20)
    workspace_max_m: tuple[float, float, float] = (0.07, 0.07, -0.05)
    workspace_tolerance_m: float = 0.001
    cbf_gamma: float = 0.5
    tissue: str = "generic"
    force_limit_n: float | None = None
    stiffness_prior_n_per_m: float = 400.0
    stiffness_min_n_per_m: float = 50.0
    stiffness_max_n_per_m: float = 5000.0
    stiffness_forgetting: float = 0.98
    force_sensing_error_n: float = 0.0
    # The task flap's: 2.64 x E t at its stiffest default (14 kPa, 3 mm); sim.force_sensing.tissue_bounds.
    tissue_stiffness_bound_n_per_m: float = 110.88
    # 1.2 x the task flap's weight at its largest default size, density, thickness and gravity (0.32 N),
    # rounded up; sim.force_sensing.tissue_bounds.
    held_load_bound_n: float = 0.33
    # 15 periods of the dVRK's 100 Hz: above the oldest measured_js a deploy met ticking against sim-dvrk on
    # a machine busy with robustness --jobs 2 (69 ms; 14 ms idle), docs/dvrk.md "The deadman's timeout".
    deadman_timeout_s: float = 0.15
    max_translation_m: float = 0.05
    max_yaw_rad: float = 0.5
    solver_eps: float = 1e-4
    solver_max_iter: int = 4000
    hard_tolerance: float = 1e-6
    slack_penalty: float = 1e3
    _spec: PsmSpec = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.arm, str):
            raise ConfigurationError("arm", self.arm, "a string: 'classic' or 'si'")
        if self.tool is not None and not isinstance(self.tool, str):
            raise ConfigurationError("tool", self.tool, "a part number as a string, or none")
        if not isinstance(self.tissue, str):
            raise ConfigurationError("tissue", self.tissue, "one of " + ", ".join(repr(t) for t in FORCE_PRESETS))
        object.__setattr__(self, "_spec", psm_spec(self.arm, self.tool))
        self.validate()

    @property
    def spec(self) -> PsmSpec:
        """The PSM variant the limits apply to."""
        return self._spec

    @property
    def control_period_s(self) -> float:
        """Period of one control tick [s]."""
        return 1.0 / self.control_rate_hz

    @property
    def effective_force_limit_n(self) -> float:
        """The retraction-force limit in force: explicit, or the tissue preset's."""
        return self.force_limit_n if self.force_limit_n is not None else FORCE_PRESETS[self.tissue].force_limit_n

    @property
    def velocity(self) -> np.ndarray:
        """Per-joint velocity limits (6,)."""
        return np.array(self.velocity_limit) if self.velocity_limit is not None else self._spec.velocity_limit

    @property
    def acceleration(self) -> np.ndarray:
        """Per-joint acceleration limits (6,)."""
        if self.acceleration_limit is not None:
            return np.array(self.acceleration_limit)
        return self._spec.acceleration_limit

    @property
    def jerk(self) -> np.ndarray:
        """Per-joint jerk limits (6,)."""
        if self.jerk_limit is not None:
            return np.array(self.jerk_limit)
        return self.jerk_per_acceleration * self.acceleration

    @property
    def lower(self) -> np.ndarray:
        """Hard lower joint limits (6,), including the minimum insertion."""
        lower = self._spec.lower.copy()
        lower[2] = max(lower[2], self.min_insertion_m)
        return lower

    @property
    def upper(self) -> np.ndarray:
        """Hard upper joint limits (6,)."""
        return self._spec.upper.copy()

    def validate(self) -> None:
        """Raise :class:`ConfigurationError` naming the first field outside its allowed range."""
        dof = self._spec.dof
        if not (
            _is_number(self.control_rate_hz) and MIN_CONTROL_RATE_HZ <= self.control_rate_hz <= MAX_CONTROL_RATE_HZ
        ):
            raise ConfigurationError(
                "control_rate_hz",
                self.control_rate_hz,
                f"a number in [{MIN_CONTROL_RATE_HZ:g}, {MAX_CONTROL_RATE_HZ:g}]",
            )
        _positive("horizon_s", self.horizon_s, 1.0)
        if self.horizon_s < self.control_period_s:
            raise ConfigurationError(
                "horizon_s", self.horizon_s, f"at least one control period ({self.control_period_s:g} s)"
            )
        for name in ("velocity_limit", "acceleration_limit", "jerk_limit"):
            value = getattr(self, name)
            if value is not None:
                _vector(name, value, dof, positive=True)
                reference = self._spec.velocity_limit if name == "velocity_limit" else self._spec.acceleration_limit
                low, high = _RATE_FACTORS[name]
                array = np.asarray(value, dtype=float)
                if np.any(array < low * reference) or np.any(array > high * reference):
                    raise ConfigurationError(
                        name,
                        value,
                        f"per joint between {low:g} and {high:g} times the dVRK's move_jp limits: "
                        f"{np.round(low * reference, 6).tolist()} to {np.round(high * reference, 3).tolist()}",
                    )
        _positive("jerk_per_acceleration", self.jerk_per_acceleration, 1e4)
        _vector("position_margin", self.position_margin, dof)
        margin = np.asarray(self.position_margin)
        span = self._spec.upper - self._spec.lower
        if np.any(margin < 0.0) or np.any(2 * margin >= span):
            raise ConfigurationError("position_margin", self.position_margin, f">= 0 and below half of {span.round(3)}")
        upper_insertion = self._spec.joints[2].upper
        if not (_is_number(self.min_insertion_m) and _DVRK_MIN_INSERTION_M <= self.min_insertion_m < upper_insertion):
            raise ConfigurationError(
                "min_insertion_m", self.min_insertion_m, f"[{_DVRK_MIN_INSERTION_M}, {upper_insertion})"
            )
        _vector("workspace_min_m", self.workspace_min_m, 3)
        _vector("workspace_max_m", self.workspace_max_m, 3)
        if not np.all(np.asarray(self.workspace_min_m) < np.asarray(self.workspace_max_m)):
            raise ConfigurationError(
                "workspace_min_m", self.workspace_min_m, f"below workspace_max_m={self.workspace_max_m}"
            )
        _positive("workspace_tolerance_m", self.workspace_tolerance_m, 0.01)
        _positive("cbf_gamma", self.cbf_gamma, 1.0)
        if self.tissue not in FORCE_PRESETS:
            raise UnknownVariantError("tissue", self.tissue, FORCE_PRESETS)
        if self.force_limit_n is not None:
            _positive("force_limit_n", self.force_limit_n, MAX_FORCE_LIMIT_N, lower=MIN_FORCE_LIMIT_N)
        _positive("stiffness_min_n_per_m", self.stiffness_min_n_per_m, 1e5, lower=1.0)
        _positive("stiffness_max_n_per_m", self.stiffness_max_n_per_m, 1e5, lower=1.0)
        _positive("stiffness_prior_n_per_m", self.stiffness_prior_n_per_m, 1e5, lower=1.0)
        if not self.stiffness_min_n_per_m <= self.stiffness_prior_n_per_m <= self.stiffness_max_n_per_m:
            raise ConfigurationError(
                "stiffness_prior_n_per_m",
                self.stiffness_prior_n_per_m,
                f"[{self.stiffness_min_n_per_m}, {self.stiffness_max_n_per_m}] (stiffness_min/max_n_per_m)",
            )
        if not (_is_number(self.stiffness_forgetting) and 0.5 < self.stiffness_forgetting <= 1.0):
            raise ConfigurationError("stiffness_forgetting", self.stiffness_forgetting, "a number in (0.5, 1]")
        if not (_is_number(self.force_sensing_error_n) and 0.0 <= self.force_sensing_error_n <= 1000.0):
            raise ConfigurationError("force_sensing_error_n", self.force_sensing_error_n, "a number in [0, 1000] N")
        _positive("tissue_stiffness_bound_n_per_m", self.tissue_stiffness_bound_n_per_m, 1e5, lower=1.0)
        if not (_is_number(self.held_load_bound_n) and 0.0 <= self.held_load_bound_n <= 50.0):
            raise ConfigurationError("held_load_bound_n", self.held_load_bound_n, "a number in [0, 50] N")
        _positive("deadman_timeout_s", self.deadman_timeout_s, 1.0)
        if self.deadman_timeout_s < DEADMAN_MIN_PERIODS * self.control_period_s * (1.0 - 1e-9):
            raise ConfigurationError(
                "deadman_timeout_s",
                self.deadman_timeout_s,
                f"at least {DEADMAN_MIN_PERIODS} control periods ({DEADMAN_MIN_PERIODS * self.control_period_s:g} s at "
                f"control_rate_hz={self.control_rate_hz:g}): a fresh measurement is one period old when used",
            )
        _positive("max_translation_m", self.max_translation_m, 0.2)
        _positive("max_yaw_rad", self.max_yaw_rad, math.pi)
        _positive("solver_eps", self.solver_eps, 1e-3)
        if not (
            isinstance(self.solver_max_iter, int)
            and not isinstance(self.solver_max_iter, bool)
            and 10 <= self.solver_max_iter <= 100_000
        ):
            raise ConfigurationError("solver_max_iter", self.solver_max_iter, "an integer in [10, 100000]")
        _positive("hard_tolerance", self.hard_tolerance, 1e-3)
        _positive("slack_penalty", self.slack_penalty, 1e9)

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any]) -> SafetyConfig:
        """Build from a mapping (as read from TOML/YAML), refusing unknown keys."""
        known = {f.name for f in dataclasses.fields(cls) if f.init}
        for key in data:
            if key not in known:
                raise ConfigurationError(key, data[key], "a known setting: " + ", ".join(sorted(known)))
        values: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
        return cls(**values)

    def to_dict(self) -> dict[str, Any]:
        """The settings as plain values (what a config file would hold)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.init}


def load_safety_config(path: str | Path) -> SafetyConfig:
    """Load a :class:`SafetyConfig` from a ``.toml`` or ``.yaml``/``.yml`` file.

    The file holds the settings at top level or under a ``[safety]`` table.

    Raises:
        ConfigurationError: Unknown key, unreadable file or a value outside its allowed range.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".toml", ".yaml", ".yml"):
        raise ConfigurationError("--safety-config", str(path), "a .toml, .yaml or .yml file")
    text = read_text(path, "--safety-config")
    if suffix == ".toml":
        try:
            data: Any = tomllib.loads(text)  # refuses duplicate keys itself
        except tomllib.TOMLDecodeError as e:
            raise ConfigurationError("--safety-config", str(path), f"valid TOML without duplicate keys ({e})") from e
    else:
        data = load_yaml(text, "--safety-config", path) or {}
    if not isinstance(data, dict):
        raise ConfigurationError("--safety-config", str(path), "a mapping of settings")
    if "safety" in data and isinstance(data["safety"], dict):
        data = data["safety"]
    return SafetyConfig.from_mapping(data)
