"""The sweep engine: sampling, resumption, retries after worker deaths, local vs Ray, reports."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from psm_control.errors import ConfigurationError, UnknownVariantError
from sim.robustness import episode_options, parameter_units, sweep_parameters
from sim.sweep import EpisodeStore, make_trials, parse_ranges, run_trials, wilson_interval
from sim.sweep.report import write_report

WORKER = "tests.sweep.workers:toy_episode"


def _strip(records: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if k != "pid"} for r in records]


def test_parse_ranges_grammar() -> None:
    """Absolute, relative (x) and fixed ranges parse; relative ranges sample within their bounds."""
    ranges = parse_ranges("stiffness=0.3:3x, obs_noise=0:0.002,latency=2")
    assert [(r.name, r.low, r.high, r.relative) for r in ranges] == [
        ("stiffness", 0.3, 3.0, True),
        ("obs_noise", 0.0, 0.002, False),
        ("latency", 2.0, 2.0, False),
    ]
    trials = make_trials(ranges, 200, seed=3)
    values = np.array([t.params["stiffness"] for t in trials])
    assert values.min() >= 0.3 and values.max() <= 3.0
    assert np.mean(values < 1.0) == pytest.approx(np.log(1 / 0.3) / np.log(10), abs=0.1)  # log-uniform


@pytest.mark.parametrize("text", ["stiffness", "stiffness=a:b", "stiffness=3:1", "stiffness=0:2x", "a=1,a=2", ""])
def test_bad_ranges_are_refused(text: str) -> None:
    """Malformed, inverted, non-positive relative, duplicate or empty ranges raise ConfigurationError."""
    with pytest.raises(ConfigurationError):
        parse_ranges(text)


def test_a_modulus_range_in_kpa() -> None:
    """youngs_modulus=2:30kpa is the absolute range 2-30 kPa; another unit is refused, naming kPa."""
    units = parameter_units()
    (modulus,) = parse_ranges("youngs_modulus=2:30kpa", valid_names=sweep_parameters(), units=units)
    assert (modulus.low, modulus.high, modulus.relative) == (2.0, 30.0, False)
    assert episode_options({"youngs_modulus": 12.0}, {"youngs_modulus": False}) == {"tissue_youngs_modulus_kpa": 12.0}
    assert episode_options({"stiffness": 2.0}, {"stiffness": True}) == {"tissue_youngs_modulus_kpa": 20.0}
    with pytest.raises(ConfigurationError, match="kpa"):
        parse_ranges("youngs_modulus=2:30mm", units=units)
    with pytest.raises(ConfigurationError, match="without a unit"):
        parse_ranges("size=0.07:0.09kpa", units=units)


def test_unknown_parameter_lists_valid_ones() -> None:
    """A parameter the simulation does not know is refused with the valid names."""
    with pytest.raises(UnknownVariantError, match="stiffness"):
        parse_ranges("stifness=1:2", valid_names=("stiffness", "size"))


def test_trials_depend_only_on_seed_and_index() -> None:
    """The same sweep seed gives the same trials; a grid holds every combination of levels."""
    ranges = parse_ranges("stiffness=0.5:2x,size=0.8:1.2")
    assert make_trials(ranges, 10, seed=7) == make_trials(ranges, 10, seed=7)
    assert make_trials(ranges, 10, seed=7) != make_trials(ranges, 10, seed=8)
    grid = make_trials(ranges, 3, mode="grid")
    assert len(grid) == 9
    assert {round(t.params["size"], 6) for t in grid} == {0.8, 1.0, 1.2}


def test_wilson_interval_bounds() -> None:
    """The 95 % interval contains the estimate, stays in [0, 1], and narrows with more episodes."""
    for k, n in [(0, 10), (10, 10), (5, 10), (50, 100)]:
        low, high = wilson_interval(k, n)
        assert 0.0 <= low <= k / n <= high <= 1.0
    assert np.diff(wilson_interval(50, 100)) < np.diff(wilson_interval(5, 10))


def test_resumed_sweep_skips_finished_trials(tmp_path: Path) -> None:
    """A sweep resumed after an interruption runs only the trials not yet written."""
    trials = make_trials(parse_ranges("stiffness=0.5:2x"), 12, seed=1)
    store = EpisodeStore(tmp_path / "episodes.jsonl")
    first = run_trials(trials[:5], WORKER, store=store, jobs=2, show_progress=False)
    pids_before = {r["index"]: r["pid"] for r in first}
    with (tmp_path / "episodes.jsonl").open("a") as handle:
        handle.write('{"index": 99, "tor')  # a write torn by the interruption
    resumed = EpisodeStore(tmp_path / "episodes.jsonl")
    assert resumed.done() == set(range(5))
    records = run_trials(trials, WORKER, store=resumed, jobs=2, show_progress=False)
    assert [r["index"] for r in records] == list(range(12))
    assert all(r["pid"] == pids_before[r["index"]] for r in records[:5])  # not re-run
    lines = (tmp_path / "episodes.jsonl").read_text().splitlines()
    assert len(lines) == 12 and all(json.loads(line) for line in lines)


def test_killed_worker_loses_no_trial(tmp_path: Path) -> None:
    """Trials whose worker process is SIGKILLed are retried; every trial ends with a real result."""
    trials = make_trials(parse_ranges("stiffness=0.5:2x"), 16, seed=2)
    store = EpisodeStore(tmp_path / "episodes.jsonl")
    kwargs = {"kill_marker_dir": str(tmp_path), "kill_indices": (3, 9)}
    records = run_trials(trials, WORKER, store=store, jobs=2, worker_kwargs=kwargs, show_progress=False)
    assert [r["index"] for r in records] == list(range(16))
    assert not [r for r in records if "error" in r]
    assert (tmp_path / "killed-3").exists() and (tmp_path / "killed-9").exists()
    clean = run_trials(trials, WORKER, store=EpisodeStore(tmp_path / "clean.jsonl"), jobs=1, show_progress=False)
    assert _strip(records) == _strip(clean)


def test_trial_that_always_crashes_is_recorded_not_lost(tmp_path: Path) -> None:
    """A trial whose worker dies on every attempt is written as an error after max_attempts."""
    trials = make_trials(parse_ranges("stiffness=1"), 3)
    store = EpisodeStore(tmp_path / "episodes.jsonl")
    records = run_trials(trials, "tests.sweep.workers:failing_episode", store=store, jobs=1, show_progress=False)
    assert len(records) == 3
    assert all("RuntimeError: broken trial" in r["error"] for r in records)


@pytest.mark.slow
@pytest.mark.xdist_group("ray")  # one local Ray cluster at a time: these run on one worker
def test_local_and_ray_backends_agree(tmp_path: Path) -> None:
    """The same sweep gives identical per-episode results on the local pool and a local Ray cluster."""
    trials = make_trials(parse_ranges("stiffness=0.3:3x,size=0.8:1.2"), 10, seed=5)
    local = run_trials(trials, WORKER, store=EpisodeStore(tmp_path / "local.jsonl"), jobs=2, show_progress=False)
    ray_records = run_trials(
        trials, WORKER, store=EpisodeStore(tmp_path / "ray.jsonl"), backend="ray", jobs=2, show_progress=False
    )
    assert _strip(local) == _strip(ray_records)


def test_report_plots_have_content(tmp_path: Path) -> None:
    """The report and its plots are written, and the plots are not blank images."""
    import matplotlib.image

    ranges = parse_ranges("stiffness=0.3:3x")
    records = run_trials(
        make_trials(ranges, 40, seed=4), WORKER, store=EpisodeStore(tmp_path / "e.jsonl"), jobs=2, show_progress=False
    )
    files = write_report(tmp_path, records, ranges, title="toy", context={"policy": "toy"}, force_limit_n=2.0)
    for key in ("forces_png", "success_stiffness_png"):
        pixels = matplotlib.image.imread(files[key])[..., :3]
        assert pixels.std() > 0.05  # not a blank canvas
        coloured = np.abs(pixels[..., 0] - pixels[..., 2]) > 0.3  # blue markers or orange bars
        assert coloured.mean() > 0.002
    page = files["report_html"].read_text()
    assert "data:image/png;base64," in page and "Success and peak force against stiffness" in page
