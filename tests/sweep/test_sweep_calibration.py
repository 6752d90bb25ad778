"""Sweeps on the user's own calibrated arm (--wrench-calibration), tune-safety's warnings and verdict on the grid's
own limits, and its Pareto figure drawn by the recommendation's rule."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from hardware_if.wrench.calibration import WrenchCalibration
from sim.tuning import SettingResult, recommend
from tests.conftest import run_cli

#: The bound a calibrated deploy trusts (error_bound_with_acceleration_n) and the one without the acceleration.
TRUSTED_N, WITHOUT_ACCELERATION_N = 4.6, 70.99


def _calibration(path: Path) -> Path:
    """A calibration file as calibrate-wrench writes it on sim-dvrk (its parameters do not matter to a sweep)."""
    WrenchCalibration(
        arm="PSM1",
        columns=(),
        parameters=(),
        error_bound_n=WITHOUT_ACCELERATION_N,
        error_bound_with_acceleration_n=TRUSTED_N,
        rms_before_n=11.94,
        max_before_n=37.84,
        rms_after_n=3.42,
        max_after_n=18.96,
        samples=2000,
        sensing="measured_js",
        console="sim-dvrk",
    ).write(path)
    return path


@pytest.fixture(scope="module")
def tuned(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """tune-safety over force limits 1-1.5 N under a 1.5 N bound, on a calibration trusting the force to 4.6 N."""
    folder = tmp_path_factory.mktemp("tuned")
    calibration = _calibration(folder / "wrench.json")
    out = folder / "out"
    result = run_cli(
        "tune-safety", "--policy", "scripted", "--task", "lift", "--grid", "force_limit_n=1:1.5", "--levels", "2",
        "--episodes", "1", "--jobs", "1", "--max-force-n", "1.5", "--wrench-calibration", str(calibration),
        "--out", str(out), "--no-progress",
    )  # fmt: skip
    return {"result": result, "out": out, "calibration": calibration}


@pytest.fixture(scope="module")
def tuned_preset(tmp_path_factory: pytest.TempPathFactory) -> Any:
    """tune-safety over force limits 1-1.5 N under a 1.5 N bound with the dvrk-calibrated preset (7.21 N)."""
    out = tmp_path_factory.mktemp("preset")
    return run_cli(
        "tune-safety", "--policy", "scripted", "--task", "lift", "--grid", "force_limit_n=1:1.5", "--levels", "2",
        "--episodes", "1", "--jobs", "1", "--max-force-n", "1.5", "--force-sensing", "dvrk-calibrated",
        "--out", str(out), "--no-progress",
    )  # fmt: skip


def test_tune_safety_senses_through_the_calibration_file_and_says_so(tuned: dict[str, Any]) -> None:
    """The filter trusts the force to the file's error_bound_with_acceleration_n in every episode, and summary.json
    and both report pages name the file, its bounds and where it was fitted."""
    out = tuned["out"]
    assert "Traceback" not in tuned["result"].stderr, tuned["result"].stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["force_sensing"] == "dvrk-calibrated"
    assert summary["force_sensing_error_n"] == pytest.approx(TRUSTED_N)
    record = summary["force_sensing_calibration"]
    assert record["file"] == str(tuned["calibration"]) and record["fitted_on"] == "PSM1 on sim-dvrk, measured_js"
    assert record["error_bound_with_acceleration_n"] == pytest.approx(TRUSTED_N)
    assert record["error_bound_n"] == pytest.approx(WITHOUT_ACCELERATION_N)
    episodes = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert len(episodes) == 2 and all(e["force_sensing_error_n"] == pytest.approx(TRUSTED_N) for e in episodes)
    for page in ("settings.md", "settings.html"):
        text = " ".join((out / page).read_text().split())
        assert str(tuned["calibration"]) in text and "PSM1 on sim-dvrk, measured_js" in text, page
        assert "4.60 N" in text and "70.99 N" in text, page


def test_tune_safety_warns_about_the_grid_limits_not_the_default(tuned_preset: Any, tuned: dict[str, Any]) -> None:
    """With --grid force_limit_n=1:1.5 the run-start warning names 1 and 1.5 N (and the travel each allows) and the
    sensing's bound (the preset's, or the calibration file's), never the 3 N default the grid replaces."""
    for result, bound in ((tuned_preset, "7.21 N (dvrk-calibrated force sensing)"), (tuned["result"], "4.60 N")):
        stderr = " ".join(result.stderr.split())
        first = stderr[stderr.index("WARNING:") :]
        assert first.startswith(
            "WARNING: 2 of 2 force limits swept (1, 1.5 N) are below the force sensing's error bound " + bound
        )
        assert "mm at 1 N" in first and "mm at 1.5 N" in first
        assert "force limit 3 N" not in stderr
    assert str(tuned["calibration"]) in " ".join(tuned["result"].stderr.split())


def test_nothing_recommended_says_what_would_give_a_recommendation(tuned_preset: Any, tuned: dict[str, Any]) -> None:
    """When every limit within the bound is below the sensing's bound and never succeeded, the verdict suggests a
    grid above that bound, and a calibration (of the robot, or a better one) with a bound below the user's."""
    preset, calibrated = (" ".join(r.stdout.split()) for r in (tuned_preset, tuned["result"]))
    for result, stdout in ((tuned_preset, preset), (tuned["result"], calibrated)):
        assert "Nothing recommended" in stdout and "What would give a recommendation:" in stdout
        assert result.returncode == 1
    assert "--grid force_limit_n=9:18 --max-force-n 18" in preset
    assert "calibrate the force sensing (calibrate-wrench) and sweep with the robot's own file" in preset
    assert "--grid force_limit_n=6:12 --max-force-n 12" in calibrated
    assert "a calibration whose error_bound_with_acceleration_n is below 1.5 N (this file's is 4.60 N)" in calibrated


def test_a_calibration_goes_with_dvrk_calibrated_sensing_only(tmp_path: Path) -> None:
    """--wrench-calibration with --force-sensing ideal or dvrk is refused by name, before any episode runs."""
    calibration = _calibration(tmp_path / "wrench.json")
    for command, sensing in (("tune-safety", "ideal"), ("robustness", "dvrk")):
        sweep = ["--grid", "force_limit_n=1:2"] if command == "tune-safety" else ["--vary", "obs_noise=0:0.001"]
        result = run_cli(
            command, "--policy", "scripted", "--task", "lift", *sweep, "--force-sensing", sensing,
            "--wrench-calibration", str(calibration), "--out", str(tmp_path / command), "--no-progress",
        )  # fmt: skip
        assert result.returncode == 1, result.stdout + result.stderr
        assert f"--force-sensing='{sensing}' is not allowed: expected dvrk-calibrated (or left out)" in result.stderr
        assert not (tmp_path / command / "episodes.jsonl").exists()


def test_robustness_senses_through_the_calibration_file_and_says_so(tmp_path: Path) -> None:
    """robustness --wrench-calibration runs the episodes with the filter trusting the file's bound, and its
    summary.json and report pages name the file, its bounds and where it was fitted."""
    calibration = _calibration(tmp_path / "wrench.json")
    out = tmp_path / "out"
    result = run_cli(
        "robustness", "--policy", "scripted", "--task", "lift", "--trials", "1", "--vary", "obs_noise=0:0.001",
        "--jobs", "1", "--wrench-calibration", str(calibration), "--out", str(out), "--no-progress",
    )  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["force_sensing"] == "dvrk-calibrated"
    assert summary["force_sensing_calibration"]["file"] == str(calibration)
    assert summary["force_sensing_calibration"]["error_bound_with_acceleration_n"] == pytest.approx(TRUSTED_N)
    assert any("error bound 4.60 N" in w and str(calibration) in w for w in summary["warnings"])
    episode = json.loads((out / "episodes.jsonl").read_text().splitlines()[0])
    assert episode["force_sensing_error_n"] == pytest.approx(TRUSTED_N)
    for page in ("report.md", "report.html"):
        text = " ".join((out / page).read_text().split())
        assert str(calibration) in text and "PSM1 on sim-dvrk, measured_js" in text, page
        assert "4.60 N" in text and "70.99 N" in text, page


def test_the_pareto_figure_marks_settings_by_the_recommendation_rule(tmp_path: Path) -> None:
    """A cross is drawn for exactly the settings recommend() would not take, each setting's own force limit is drawn
    on the force axis at its success, and every cross left of the bound line has its limit right of it (or no
    success)."""
    from tissue_retract.cli.tune_safety import _plot

    bound = 1.5
    results = [
        SettingResult({"force_limit_n": 1.0}, 10, 6, 0.9, 0.5, 0, 0),  # recommendable
        SettingResult({"force_limit_n": 3.0}, 10, 10, 0.4, 0.2, 0, 0),  # peak left of the bound, limit right of it
        SettingResult({"force_limit_n": 0.5}, 10, 0, 0.1, 0.05, 0, 0),  # no success
        SettingResult({"force_limit_n": 1.4}, 10, 8, 1.6, 0.8, 0, 0),  # peak right of the bound
    ]
    limits = [r.setting["force_limit_n"] for r in results]
    eligible = [recommend([r], bound) is not None for r in results]
    assert eligible == [True, False, False, False]
    figure = _plot(results, results[:2], results[0], bound, limits, eligible, tmp_path / "pareto.png")
    assert (tmp_path / "pareto.png").stat().st_size > 1000
    axis = figure.axes[0]
    by_label = {c.get_label(): c.get_offsets().tolist() for c in axis.collections}
    crosses = next(v for k, v in by_label.items() if k.startswith("largest peak; not"))
    assert sorted(map(tuple, crosses)) == sorted((r.max_peak_force_n, 100 * r.success_rate) for r in results[1:])
    bars = by_label["its force limit (joined to its peak)"]
    drawn = sorted((lim, 100 * r.success_rate) for r, lim in zip(results, limits, strict=True))
    assert sorted(map(tuple, bars)) == drawn
    lines = [line for line in axis.get_lines() if line.get_label().startswith(f"bound {bound:g} N")]
    assert len(lines) == 1 and list(lines[0].get_xdata()) == [bound, bound]
    for r, limit, ok in zip(results, limits, eligible, strict=True):
        if not ok and r.max_peak_force_n <= bound:
            assert limit > bound or r.successes == 0
