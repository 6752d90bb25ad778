"""Safety tuning: Pareto front, recommendation, refused settings and the command end to end."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from psm_control.errors import ConfigurationError, UnknownVariantError
from safety.config import load_safety_config
from sim.sweep import parse_ranges
from sim.tuning import (
    SettingResult,
    pareto_front,
    recommend,
    recommendation_warnings,
    setting_results,
    tunable_fields,
    tuning_trials,
)
from tests.conftest import run_cli


def _result(force_limit: float, successes: int, peak: float) -> SettingResult:
    return SettingResult({"force_limit_n": force_limit}, 10, successes, peak, peak / 2, 0, 0)


def test_pareto_front_keeps_only_undominated_settings() -> None:
    """A setting beaten on both success and peak force by another is not on the front."""
    a, b, c, d = _result(1, 5, 0.5), _result(2, 8, 0.9), _result(3, 7, 1.2), _result(4, 8, 1.5)
    assert pareto_front([a, b, c, d]) == [a, b]


def test_recommendation_respects_the_force_bound() -> None:
    """The recommendation is the most successful setting with limit and peak under the bound, or none."""
    a, b, c = _result(0.5, 5, 0.4), _result(0.9, 8, 0.8), _result(1.2, 10, 1.1)
    assert recommend([a, b, c], 1.0) is b
    assert recommend([a, b, c], 2.0) is c
    assert recommend([a, b, c], 0.3) is None


def test_recommendation_never_has_a_limit_above_the_bound() -> None:
    """A setting whose force limit exceeds the bound is never recommended, however low its observed peaks."""
    low_limit, high_limit = _result(0.5, 6, 0.45), _result(3.0, 10, 0.768)
    assert recommend([low_limit, high_limit], 1.5) is low_limit
    assert recommend([high_limit], 1.5) is None


def test_a_setting_the_policy_never_succeeded_under_is_no_recommendation() -> None:
    """Within the bound but 0 of 10: not recommended, however low its peaks."""
    never, sometimes = _result(0.5, 0, 0.2), _result(1.0, 3, 0.9)
    assert recommend([never, sometimes], 1.5) is sometimes
    assert recommend([never], 1.5) is None


def test_a_weak_recommendation_says_why() -> None:
    """Few episodes, low success and a wide 95 % CI are each named; a strong recommendation has no warning."""
    weak = SettingResult({"force_limit_n": 0.5}, 8, 2, 0.4, 0.2, 0, 0)
    text = " ".join(recommendation_warnings(weak))
    assert "8 episodes" in text and "success 25 %" in text and "95 % CI 7-59 %" in text
    assert recommendation_warnings(SettingResult({"force_limit_n": 1.0}, 100, 97, 0.9, 0.5, 0, 0)) == []


def test_trials_share_seeds_across_settings() -> None:
    """Every setting runs the same episode seeds (common random numbers) and groups back by setting."""
    trials = tuning_trials(parse_ranges("force_limit_n=0.5:2,cbf_gamma=0.5:1"), levels=2, episodes=3)
    assert len(trials) == 12
    seeds = [[t.seed for t in trials[i : i + 3]] for i in range(0, 12, 3)]
    assert all(s == seeds[0] for s in seeds)
    records = [{**t.to_dict(), "success": t.index % 2 == 0, "peak_force_n": 0.1 * t.index} for t in trials]
    grouped = setting_results(records, episodes=3)
    assert [g.episodes for g in grouped] == [3, 3, 3, 3]
    assert grouped[1].setting == trials[3].params and grouped[1].max_peak_force_n == pytest.approx(0.5)


def test_invalid_settings_are_refused_before_running() -> None:
    """A grid value outside the SafetyConfig's allowed range, or an unknown setting, fails up front."""
    with pytest.raises(ConfigurationError, match="force_limit_n"):
        tuning_trials(parse_ranges("force_limit_n=0:2"), levels=3, episodes=1)
    with pytest.raises(UnknownVariantError, match="force_limit_n"):
        parse_ranges("force_limit=1:2", valid_names=tunable_fields())


def test_tune_safety_writes_a_loadable_recommendation(tmp_path: Path) -> None:
    """The command writes the settings table, a Pareto plot and a recommended config that loads back."""
    result = run_cli(
        "tune-safety",
        "--policy",
        "scripted",
        "--task",
        "lift",
        "--grid",
        "force_limit_n=0.2:2",
        "--levels",
        "2",
        "--episodes",
        "2",
        "--jobs",
        "2",
        "--max-force-n",
        "5",
        "--out",
        str(tmp_path),
        "--no-progress",
    )
    assert result.returncode == 0, result.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert len(summary["settings"]) == 2
    config = load_safety_config(tmp_path / "recommended_safety.yaml")
    assert config.force_limit_n == pytest.approx(summary["recommended"]["force_limit_n"])
    assert (tmp_path / "pareto.png").stat().st_size > 1000
    assert "Pareto" in (tmp_path / "settings.md").read_text()


def test_tune_safety_never_writes_a_limit_above_the_bound(tmp_path: Path) -> None:
    """With --max-force-n 1.5 the written limit is at most 1.5 N and the report shows the 95 % CI."""
    result = run_cli(
        "tune-safety", "--policy", "scripted", "--task", "lift", "--grid", "force_limit_n=0.5:3", "--levels", "3",
        "--episodes", "2", "--jobs", "2", "--max-force-n", "1.5", "--out", str(tmp_path), "--no-progress",
    )  # fmt: skip
    assert "Traceback" not in result.stderr
    if result.returncode == 0:
        assert load_safety_config(tmp_path / "recommended_safety.yaml").effective_force_limit_n <= 1.5
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary.get("recommended", {}).get("force_limit_n", 0.0) <= 1.5
    assert "95 % CI" in result.stdout and "WARNING: weak recommendation: only 2 episodes" in result.stdout


def test_limits_below_the_sensing_bound_are_said_at_start_and_in_the_verdict(tmp_path: Path) -> None:
    """With the console's uncalibrated force (its bound above any force limit the filter takes) every swept limit
    is below what it can tell: a start warning, recorded in summary.json and the report, and no recommendation,
    saying why and what to change (calibrate: no limit could be raised above the bound)."""
    result = run_cli(
        "tune-safety", "--policy", "scripted", "--task", "lift", "--grid", "force_limit_n=0.5:1", "--levels", "2",
        "--episodes", "2", "--jobs", "2", "--max-force-n", "1.5", "--force-sensing", "dvrk", "--out", str(tmp_path),
        "--no-progress",
    )  # fmt: skip
    assert result.returncode == 1, result.stdout + result.stderr
    stderr, stdout = " ".join(result.stderr.split()), " ".join(result.stdout.split())
    assert "WARNING: 2 of 2 force limits swept (0.5, 1 N) are below the force sensing's error bound" in stderr
    assert "Nothing recommended" in stdout and "Why: the policy succeeded in no episode" in stdout
    assert "calibrate the force sensing" in stdout and "No force limit the safety filter takes (50 N at most)" in stdout
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["force_sensing"] == "dvrk" and summary["force_sensing_error_n"] > 1.0
    assert any("below the force sensing's error bound" in w for w in summary["warnings"])
    report = (tmp_path / "settings.md").read_text()
    assert "force sensing" in report and "dvrk, error bound" in report
    assert "recommended" not in summary
