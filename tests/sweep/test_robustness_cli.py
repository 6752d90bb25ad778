"""`tissue-retract robustness` end to end on the real simulation, as a user runs it."""

from __future__ import annotations

import itertools
import json
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import run_cli

SWEEP = ("robustness", "--policy", "scripted", "--task", "lift", "--trials", "4", "--jobs", "2", "--no-progress")


def _robustness(out: Path) -> subprocess.CompletedProcess[str]:
    return run_cli(*SWEEP, "--vary", "stiffness=0.5:2x,obs_white_m=0:0.001", "--out", str(out))


#: A sweep's output folder and the command's result.
Sweep = tuple[Path, subprocess.CompletedProcess[str]]

#: The shipped policy's sweep that several tests below read, each for its own property: a calibrated dVRK's
#: policy (its own file), whole-step latency, lengths of fractions of a millimetre, five trials for five fifths
#: of stiffness. Every process of a pretrained sweep loads the policy, so it runs once, on one worker.
BESIDE_EXPERT = (
    "robustness", "--task", "lift", "--trials", "5", "--jobs", "1", "--no-progress", "--force-sensing",
    "dvrk-calibrated", "--vary", "stiffness=0.3:3x,obs_white_m=0:0.001,latency=0:2,obs_noise=0:0.002",
    "--beside-expert",
)  # fmt: skip


@pytest.fixture(scope="module")
def beside_expert(tmp_path_factory: pytest.TempPathFactory) -> Sweep:
    """``--policy pretrained --beside-expert``: the policy's sweep and the scripted expert's on its trials."""
    out = tmp_path_factory.mktemp("beside")
    return out, run_cli(*BESIDE_EXPERT, "--policy", "pretrained", "--out", str(out))


@pytest.fixture(scope="module")
def scripted_same_trials(tmp_path_factory: pytest.TempPathFactory) -> Sweep:
    """The same sweep with ``--policy scripted``, where ``--beside-expert`` does nothing."""
    out = tmp_path_factory.mktemp("scripted")
    return out, run_cli(*BESIDE_EXPERT, "--policy", "scripted", "--out", str(out))


def test_sweep_writes_episodes_report_and_plots_then_resumes(tmp_path: Path) -> None:
    """A sweep writes one JSON line per episode, a summary, a report and non-blank plots; a rerun skips all."""
    import matplotlib.image

    result = _robustness(tmp_path)
    assert result.returncode == 0, result.stderr
    lines = [json.loads(line) for line in (tmp_path / "episodes.jsonl").read_text().splitlines()]
    assert sorted(r["index"] for r in lines) == [0, 1, 2, 3]
    for record in lines:
        assert {"success", "peak_force_n", "failure_class", "params", "options", "seed"} <= record.keys()
        assert 0.5 <= record["params"]["stiffness"] <= 2.0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["episodes"] == 4 and summary["errors"] == 0
    for name in ("success_vs_stiffness.png", "success_vs_obs_white_m.png", "peak_force_histogram.png"):
        pixels = matplotlib.image.imread(tmp_path / name)[..., :3]
        assert pixels.std() > 0.05, name
        assert (np.abs(pixels[..., 0] - pixels[..., 2]) > 0.3).mean() > 0.001, name
    assert "data:image/png;base64" in (tmp_path / "report.html").read_text()
    again = _robustness(tmp_path)
    assert again.returncode == 0, again.stderr
    assert json.loads((tmp_path / "summary.json").read_text())["episodes_run_now"] == 0
    assert len((tmp_path / "episodes.jsonl").read_text().splitlines()) == 4


def test_unknown_parameter_is_refused_with_valid_names(tmp_path: Path) -> None:
    """Varying a parameter the simulation lacks fails before any episode runs, naming the valid ones."""
    result = run_cli(
        "robustness", "--policy", "scripted", "--task", "lift", "--vary", "stifness=1:2", "--out", str(tmp_path)
    )
    assert result.returncode == 1
    assert "stiffness" in result.stderr and "tissue_size_m" in result.stderr
    assert not (tmp_path / "episodes.jsonl").exists()


@pytest.mark.slow
@pytest.mark.xdist_group("ray")  # one local Ray cluster at a time: these run on one worker
def test_simulation_sweep_is_identical_on_local_and_ray(tmp_path: Path) -> None:
    """The same robustness sweep of the real simulation gives identical episode records on both backends."""
    records = {}
    for backend in ("local", "ray"):
        out = tmp_path / backend
        result = run_cli(*SWEEP, "--vary", "stiffness=0.3:3x,latency=0:2", "--backend", backend, "--out", str(out))
        assert result.returncode == 0, result.stderr
        lines = (out / "episodes.jsonl").read_text().splitlines()
        records[backend] = sorted(lines, key=lambda line: json.loads(line)["index"])
    assert len(records["local"]) == 4
    assert records["local"] == records["ray"]


def test_multiplier_of_a_zero_nominal_is_refused(tmp_path: Path) -> None:
    """An x range on a parameter whose nominal value is 0 is refused instead of silently giving 0."""
    result = run_cli(
        "robustness", "--policy", "scripted", "--task", "lift", "--vary", "joint_offset=0.5:2x", "--out", str(tmp_path)
    )
    assert result.returncode == 1
    assert "joint_offset" in result.stderr and "absolute" in result.stderr
    assert not (tmp_path / "episodes.jsonl").exists()


def _strict(text: str) -> object:
    """Parse JSON as a strict parser does: NaN and Infinity are errors."""

    def refuse(constant: str) -> None:
        raise ValueError(f"non-standard JSON constant {constant}")

    return json.loads(text, parse_constant=refuse)


def test_latency_is_swept_and_binned_in_whole_steps_and_outputs_are_strict_json(beside_expert: Sweep) -> None:
    """latency takes whole policy steps in episodes and report bins; summary/sweep JSON parse strictly; the
    shipped policy's sha256 is recorded for pretrained."""
    import hashlib

    from policies.shipped import shipped_policy_path

    out, result = beside_expert
    assert result.returncode == 0, result.stderr
    records = [_strict(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert all(float(r["params"]["latency"]).is_integer() for r in records)  # type: ignore[index]
    summary = _strict((out / "summary.json").read_text())
    assert isinstance(summary, dict) and "stall_static_load_n" in summary
    sweep = _strict((out / "sweep.json").read_text())
    digest = hashlib.sha256(shipped_policy_path("TissueRetract-Lift-v0", "dvrk-calibrated").read_bytes()).hexdigest()
    assert isinstance(sweep, dict) and sweep["policy_sha256"] == digest
    report = (out / "report.md").read_text()
    labels = {line.split("|")[1].strip() for line in report.splitlines() if "policy steps |" in line}
    assert labels and labels <= {"0 policy steps", "1 policy steps", "2 policy steps"}, report
    assert "success" in result.stdout and "95 % CI" in result.stdout


def test_the_report_reads_as_a_reviewer_needs(beside_expert: Sweep) -> None:
    """The report names the shipped file it ran (path and digest), defines its terms, gives small lengths in
    millimetres and flags bins too thin to read alone."""
    out, result = beside_expert
    assert result.returncode == 0, result.stderr
    report = (out / "report.md").read_text()
    assert "pretrained: policies/pretrained/dvrk-calibrated/TissueRetract-Lift-v0.safetensors (sha256 " in report
    assert "| tissue_damage | an episode in which the force on the tissue exceeded 5 N" in report
    assert " mm | 1 (thin) |" in report or " mm | 2 (thin) |" in report, report
    assert "e-05" not in report and "e-04" not in report
    assert re.search(r"\*\*interventions\*\*: (0$|\d+ \([a-z_]+ \d+)", report, re.MULTILINE), report  # by kind


def _episodes(path: Path) -> list[dict[str, object]]:
    """A sweep's records by trial index, without what depends on the process that ran them."""
    records = [json.loads(line) for line in path.read_text().splitlines()]
    return sorted(
        ({k: v for k, v in r.items() if k not in ("worker_pid", "worker_rss_mb")} for r in records),
        key=lambda r: int(r["index"]),  # type: ignore[call-overload]
    )


def test_beside_expert_shows_the_expert_on_the_same_trials_by_fifth_of_stiffness(
    beside_expert: Sweep, scripted_same_trials: Sweep
) -> None:
    """--beside-expert: the fifths partition the trials, and the expert's episodes, overall success and Wilson
    interval are those of a --policy scripted sweep on the same seeds (where --beside-expert does nothing)."""
    (beside_out, result), (scripted_out, alone) = beside_expert, scripted_same_trials
    assert result.returncode == 0, result.stderr
    assert "scripted expert, same trials" in result.stdout
    assert alone.returncode == 0, alone.stderr
    assert "--beside-expert: the policy is the scripted expert already; no second pass" in alone.stdout
    assert not (scripted_out / "expert_episodes.jsonl").exists()
    expert = _episodes(beside_out / "expert_episodes.jsonl")
    assert expert == _episodes(scripted_out / "episodes.jsonl")
    summary = json.loads((beside_out / "summary.json").read_text())
    scripted = json.loads((scripted_out / "summary.json").read_text())
    assert summary["beside_expert"] is True and scripted["beside_expert"] is False
    assert (summary["expert_success"], summary["expert_ci95"]) == (scripted["success_rate"], scripted["ci95"])
    fifths = summary["by_stiffness_fifth"]
    assert [f["trials"] for f in fifths] == [1] * 5 and all(f["thin"] for f in fifths)
    assert sum(f["expert_trials"] for f in fifths) == 5
    assert [f["expert_success"] for f in fifths] == [f["success"] for f in scripted["by_stiffness_fifth"]]
    peaks = [f["largest_peak_force_n"] for f in scripted["by_stiffness_fifth"]]
    assert [f["expert_largest_peak_force_n"] for f in fifths] == peaks and all(p > 0 for p in peaks)
    assert all(a["stiffness_high_kpa"] <= b["stiffness_low_kpa"] for a, b in itertools.pairwise(fifths))
    assert {f["stiffness_low_kpa"] for f in fifths} == {
        r["options"]["tissue_youngs_modulus_kpa"]  # type: ignore[index]
        for r in _episodes(beside_out / "episodes.jsonl")
    }
    report = (beside_out / "report.md").read_text()
    assert "## Where the force limit stops a retraction, by fifth of the drawn stiffness" in report
    header = (
        "| Young's modulus | trials | success | stopped by the force limit | largest true peak | expert success | "
        "expert stopped by the force limit | expert largest true peak |"
    )
    assert header in report and " kPa | 1 (thin) | " in report, report
    assert "expert success" not in (scripted_out / "report.md").read_text()
