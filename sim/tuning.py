"""Safety-limit tuning: which SafetyConfig settings keep the force low without destroying success?

Every grid setting is evaluated on the same episode seeds (common random numbers), so differences
between settings are differences of the settings, not of luck. Settings are compared on success rate
and on the largest peak retraction force any of their episodes saw; the Pareto front holds those no
other setting beats on both. The recommendation is the most successful setting whose force limit is at
or below the user's bound (the limit is what bounds the next episode; the observed peaks are only a sample)
and whose largest observed peak also stayed under it (ties go to the lower force). Its confidence is the
Wilson interval of its success; a recommendation from few episodes, low success or a wide interval is
flagged as weak.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from psm_control.errors import ConfigurationError
from psm_control.outputs import write_atomic
from safety.config import SafetyConfig
from sim.sweep.space import ParameterRange, Trial
from sim.sweep.stats import wilson_interval

__all__ = [
    "SettingResult",
    "integer_settings",
    "pareto_front",
    "recommend",
    "recommendation_warnings",
    "setting_force_limit_n",
    "setting_results",
    "tunable_fields",
    "tuning_trials",
    "write_config",
]

#: A recommendation from fewer episodes per setting is flagged as weak.
CONFIDENT_EPISODES = 20
#: A recommended setting with a lower success rate is flagged as weak.
CONFIDENT_SUCCESS = 0.8
#: A recommendation whose 95 % CI of success is wider than this (as a fraction) is flagged as weak.
CONFIDENT_CI_WIDTH = 0.25
#: Grid levels are computed in floating point; a limit this close to the bound counts as at the bound [N].
_BOUND_TOLERANCE_N = 1e-9


def tunable_fields() -> tuple[str, ...]:
    """SafetyConfig settings that take one number (the ones a grid can sweep)."""
    default = SafetyConfig()
    return tuple(
        f.name
        for f in dataclasses.fields(SafetyConfig)
        if f.init
        and (isinstance(getattr(default, f.name), int | float) or f.name == "force_limit_n")
        and not isinstance(getattr(default, f.name), bool)
    )


def _base_value(name: str) -> float:
    default = SafetyConfig()
    return default.effective_force_limit_n if name == "force_limit_n" else float(getattr(default, name))


def tuning_trials(ranges: Sequence[ParameterRange], levels: int, episodes: int, seed: int = 0) -> list[Trial]:
    """Grid settings x episode seeds; trial ``i * episodes + j`` is setting i on seed j.

    Relative ranges (``x``) multiply the default configuration's value.
    """
    if episodes < 1:
        raise ConfigurationError("episodes", episodes, "an integer >= 1")
    if levels < 1:
        raise ConfigurationError("levels", levels, "an integer >= 1")
    axes = [[v * _base_value(r.name) if r.relative else v for v in r.levels(levels)] for r in ranges]
    settings = [dict(zip((r.name for r in ranges), combo, strict=True)) for combo in itertools.product(*axes)]
    for setting in settings:
        SafetyConfig.from_mapping(integer_settings(setting))  # refuse an invalid setting before any episode runs
    return [
        Trial(i * episodes + j, (seed * 1_000_003 + j) % 2**31, setting)
        for i, setting in enumerate(settings)
        for j in range(episodes)
    ]


def integer_settings(setting: Mapping[str, float]) -> dict[str, Any]:
    """Grid values as the config wants them: integer settings (solver_max_iter) rounded."""
    default = SafetyConfig()
    return {
        k: round(v) if isinstance(getattr(default, k), int) and not isinstance(getattr(default, k), bool) else float(v)
        for k, v in setting.items()
    }


@dataclass(frozen=True)
class SettingResult:
    """How one setting did over its episodes."""

    setting: dict[str, float]
    episodes: int
    successes: int
    max_peak_force_n: float
    mean_peak_force_n: float
    interventions: int
    errors: int

    @property
    def success_rate(self) -> float:
        """Fraction of successful episodes."""
        return self.successes / self.episodes if self.episodes else math.nan

    @property
    def ci95(self) -> tuple[float, float]:
        """95 % Wilson interval of the success rate."""
        return wilson_interval(self.successes, self.episodes)


def setting_results(records: Sequence[Mapping[str, Any]], episodes: int) -> list[SettingResult]:
    """Group trial records by setting (trial index // episodes)."""
    groups: dict[int, list[Mapping[str, Any]]] = {}
    for record in records:
        groups.setdefault(int(record["index"]) // episodes, []).append(record)
    results = []
    for key in sorted(groups):
        rows = groups[key]
        ok = [r for r in rows if "error" not in r]
        forces = [float(r["peak_force_n"]) for r in ok if r.get("peak_force_n") is not None]
        results.append(
            SettingResult(
                setting={k: float(v) for k, v in rows[0]["params"].items()},
                episodes=len(ok),
                successes=sum(1 for r in ok if r.get("success")),
                max_peak_force_n=max(forces) if forces else math.nan,
                mean_peak_force_n=sum(forces) / len(forces) if forces else math.nan,
                interventions=sum(int((r.get("interventions") or {}).get("total", 0)) for r in ok),
                errors=len(rows) - len(ok),
            )
        )
    return results


def pareto_front(results: Sequence[SettingResult]) -> list[SettingResult]:
    """Settings no other beats on both success (higher) and largest peak force (lower)."""

    def dominated(a: SettingResult) -> bool:
        return any(
            b.success_rate >= a.success_rate
            and b.max_peak_force_n <= a.max_peak_force_n
            and (b.success_rate > a.success_rate or b.max_peak_force_n < a.max_peak_force_n)
            for b in results
        )

    return sorted((r for r in results if not dominated(r)), key=lambda r: r.max_peak_force_n)


def setting_force_limit_n(setting: Mapping[str, float], base_config: Mapping[str, Any] | None = None) -> float:
    """The retraction-force limit [N] a grid setting runs with (its own, else the base configuration's)."""
    config = SafetyConfig.from_mapping({**dict(base_config or {}), **integer_settings(setting)})
    return config.effective_force_limit_n


def recommend(
    results: Sequence[SettingResult], max_force_n: float, base_config: Mapping[str, Any] | None = None
) -> SettingResult | None:
    """The most successful setting whose force limit and largest peak force are at most ``max_force_n``.

    A setting whose limit is above the bound is never recommended, however low its observed peaks: a few
    episodes' largest peak does not bound the next episode's, the limit does. Nor is one under which the
    policy never succeeded: that is no setting to run it with. None if no setting qualifies.
    """
    bound = max_force_n + _BOUND_TOLERANCE_N
    feasible = [
        r
        for r in results
        if r.errors == 0
        and r.successes > 0
        and r.max_peak_force_n <= bound
        and setting_force_limit_n(r.setting, base_config) <= bound
    ]
    if not feasible:
        return None
    return max(feasible, key=lambda r: (r.success_rate, -r.max_peak_force_n))


def recommendation_warnings(result: SettingResult) -> list[str]:
    """Why a recommendation is weak: few episodes, low success or a wide 95 % CI (empty if none applies)."""
    low, high = result.ci95
    warnings = []
    if result.episodes < CONFIDENT_EPISODES:
        warnings.append(
            f"only {result.episodes} episodes per setting (at least {CONFIDENT_EPISODES} for a confident choice)"
        )
    if result.success_rate < CONFIDENT_SUCCESS:
        warnings.append(f"success {100 * result.success_rate:.0f} % is below {100 * CONFIDENT_SUCCESS:.0f} %")
    if high - low > CONFIDENT_CI_WIDTH:
        warnings.append(
            f"95 % CI {100 * low:.0f}-{100 * high:.0f} % is {100 * (high - low):.0f} points wide "
            f"(more than {100 * CONFIDENT_CI_WIDTH:.0f})"
        )
    return warnings


def write_config(
    path: Path, setting: Mapping[str, float], base_config: Mapping[str, Any] | None, note: str
) -> SafetyConfig:
    """Write the recommended SafetyConfig as YAML (only the settings that differ from the defaults)."""
    config = SafetyConfig.from_mapping({**dict(base_config or {}), **integer_settings(setting)})
    defaults = SafetyConfig().to_dict()
    changed = {k: list(v) if isinstance(v, tuple) else v for k, v in config.to_dict().items() if v != defaults[k]}
    path.parent.mkdir(parents=True, exist_ok=True)
    header = "".join(f"# {line}\n" for line in note.splitlines())
    write_atomic(path, header + yaml.safe_dump(changed, sort_keys=True), "--out")
    return config
