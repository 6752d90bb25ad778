"""Smoke runs of the simulation's commands, as a user would type them.

Each runs the real command line in a child forked from this process (:mod:`tests.forked_cli`), but for what
only a process of its own shows: the exit status of a stop signal, and what PyBullet prints when it is imported.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.forked_cli import run_one


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    """``python -m tissue_retract ARGS``, a fresh interpreter."""
    return subprocess.run(
        [sys.executable, "-m", "tissue_retract", *args], capture_output=True, text=True, timeout=900, check=False
    )


def test_plain_demo_runs_an_expert_episode() -> None:
    """`demo` with no arguments runs one scripted Task III episode and prints a summary."""
    result = run_one("demo")
    assert result.returncode == 0, result.stderr
    assert "TissueRetract-MultiSite-v0: scripted expert succeeded in 1/1" in result.stdout


def test_demo_writes_demonstrations_and_video(tmp_path: Path) -> None:
    """`demo --out --video` writes a .npz of successful episodes with metadata, and a GIF."""
    out, video = tmp_path / "demos.npz", tmp_path / "episode.gif"
    result = run_one("demo", "--task", "lift", "--episodes", "2", "--out", str(out), "--video", str(video))
    assert result.returncode == 0, result.stderr
    data = np.load(out)
    assert data["action"].shape == (2, 50, 5)
    assert data["observation"].shape == (2, 51, 18)
    metadata = json.loads(str(data["metadata"]))
    assert metadata["gym_id"] == "TissueRetract-Lift-v0" and len(metadata["randomization"]) == 2
    assert "package_version" in metadata
    assert video.stat().st_size > 1000


def test_evaluate_writes_the_documented_json(tmp_path: Path) -> None:
    """`evaluate --json --safety-config` writes summary and per-episode keys, safety figures included."""
    path, config = tmp_path / "eval.json", tmp_path / "safety.toml"
    config.write_text("force_limit_n = 1.5\n")
    result = run_one(
        "evaluate", "--policy", "random", "--task", "2", "--episodes", "2", "--seeds", "1", "--json", str(path),
        "--safety-config", str(config),
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    report = json.loads(path.read_text())
    summary = report["summary"]
    for key in ("success_rate", "ci95", "episodes", "peak_force_n", "grip_losses", "tissue_damage", "sim_unstable"):
        assert key in summary
    assert "env_steps_per_s" in summary
    assert summary["force_limit_n"] == 1.5 and summary["safety"] is True
    for key in ("workspace_violation_mm", "min_insertion_margin_m"):
        assert isinstance(summary[key], float) and summary[key] >= 0.0
    for key in ("joint_limit_violations", "safety_stops", "interventions"):
        assert isinstance(summary[key], int)
    assert {"seed", "success", "steps", "peak_force_n", "failure_class"} <= set(report["episodes"][0])


def test_evaluate_episodes_is_the_total_and_progress_is_shown(tmp_path: Path) -> None:
    """`--episodes 4` with the default three seeds runs 4 episodes in all, says so as they end, with a Wilson CI."""
    path = tmp_path / "eval.json"
    result = run_one("evaluate", "--policy", "scripted", "--task", "lift", "--episodes", "4", "--json", str(path))
    assert result.returncode == 0, result.stderr
    report = json.loads(path.read_text())
    assert report["summary"]["episodes"] == 4
    assert [e["seed"] for e in report["episodes"]] == [100000, 200000, 300000, 100001]
    assert "evaluate: 4/4 episodes" in result.stderr
    assert "95 % CI" in result.stdout and "+-" not in result.stdout


@pytest.mark.parametrize(("signum", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_stop_signal_keeps_the_finished_episodes_in_the_json(tmp_path: Path, signum: int, status: int) -> None:
    """Ctrl-C (or SIGTERM) during an evaluation exits 130 (143) and writes --json with the finished episodes,
    even when the evaluation inherited the signal blocked."""
    path = tmp_path / "eval.json"
    command = [sys.executable, "-m", "tissue_retract", "evaluate", "--policy", "scripted", "--task", "lift"]
    process = subprocess.Popen(
        [*command, "--episodes", "1000", "--json", str(path)],
        stderr=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM}),
    )
    assert process.stderr is not None
    for line in process.stderr:  # the first progress line: an episode has finished
        if line.startswith("evaluate: 1/1000 episodes"):
            break
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=300)
    assert process.returncode == status, stderr
    report = json.loads(path.read_text())
    assert report["summary"]["interrupted"] is True and 1 <= len(report["episodes"]) < 1000
    assert "Traceback" not in stderr


@pytest.mark.parametrize("command", ["evaluate", "robustness", "tune-safety", "deploy"])
def test_every_policy_help_names_pretrained(command: str) -> None:
    """Every --policy help line lists pretrained, which the README uses."""
    result = run_one(command, "--help")
    assert result.returncode == 0
    assert "pretrained" in " ".join(result.stdout.split()), result.stdout


@pytest.mark.parametrize(
    "argv",
    [
        ("--help",),
        ("evaluate", "--help"),
        ("evaluate", "--policy", "scripted", "--task", "lift", "--episodes", "1"),
        (
            "robustness",
            "--policy",
            "scripted",
            "--task",
            "lift",
            "--trials",
            "2",
            "--jobs",
            "2",
            "--vary",
            "latency=0:1",
        ),
    ],
)
def test_no_pybullet_build_line_in_the_output(argv: tuple[str, ...], tmp_path: Path) -> None:
    """Neither a command nor its sweep workers print PyBullet's build-time line (it went to stderr)."""
    extra = ("--out", str(tmp_path / "sweep")) if argv[0] == "robustness" else ()
    result = _cli(*argv, *extra)
    assert result.returncode == 0, result.stderr
    assert "pybullet build time" not in result.stdout + result.stderr


def test_evaluate_rejects_unknown_policy_and_task() -> None:
    """Unknown tasks and unloadable policies fail with a message naming what is allowed."""
    result = run_one("evaluate", "--policy", "random", "--task", "nope", "--episodes", "1")
    assert result.returncode == 1 and "multisite" in result.stderr
    result = run_one("evaluate", "--policy", "missing_module:fn", "--task", "lift", "--episodes", "1")
    assert result.returncode == 1 and "module:callable" in result.stderr


def test_bench_env_reports_rates(tmp_path: Path) -> None:
    """`bench env --json` reports state-only and rendering steps/s."""
    path = tmp_path / "bench.json"
    result = run_one("bench", "env", "--steps", "60", "--render-steps", "5", "--json", str(path))
    assert result.returncode == 0, result.stderr
    numbers = json.loads(path.read_text())
    assert numbers["env_steps_per_s"] > 0 and numbers["render_env_steps_per_s"] > 0


@pytest.mark.slow
def test_bench_train_times_the_recipe_and_confirms_on_unseen_episodes(tmp_path: Path) -> None:
    """`bench train`: a recipe run per seed, timed from outside, its kept policy scored on unseen episodes."""
    path = tmp_path / "train.json"
    args = ("--tasks", "lift", "--seeds", "4", "--confirm-episodes", "1", "--budget-s", "10")
    result = run_one("bench", "train", *args, "--out", str(tmp_path / "runs"), "--json", str(path), timeout_s=900)
    assert result.returncode == 0, result.stderr
    (run,) = json.loads(path.read_text())["runs"]
    log = Path(run["log"]).read_text()
    assert run["exit_status"] == 0 and "recipe fast" in log, log
    assert f"kept episode {run['policy_episode']}, confirmed {100 * run['confirmed_success']:.0f} %" in result.stdout
    assert run["wall_s"] > 0 and run["reached"] == (run["confirmed_success"] >= 0.95)
    assert "TissueRetract-Lift-v0" in result.stdout.splitlines()[-1]


@pytest.mark.slow
def test_bench_train_robust_confirms_beside_the_expert_on_the_sweep(tmp_path: Path) -> None:
    """`bench train --robust`: train --robust per seed, confirmed on the sweep beside the expert, whose episodes
    the second seed resumes from the first's instead of running them again."""
    path = tmp_path / "train.json"
    args = ("--robust", "--tasks", "lift", "--seeds", "4", "5", "--confirm-episodes", "1", "--budget-s", "10")
    result = run_one("bench", "train", *args, "--out", str(tmp_path / "runs"), "--json", str(path), timeout_s=900)
    assert result.returncode == 0, result.stderr
    runs = json.loads(path.read_text())["runs"]
    for run in runs:
        assert run["exit_status"] == 0 and "recipe robust" in Path(run["log"]).read_text()
        assert run["reached"] == (run["confirmed_success"] >= run["expert_success"] - 0.08)
        line = f"confirmed {100 * run['confirmed_success']:.1f} % on 1 sweep trials, the expert"
        assert line in result.stdout
    task = tmp_path / "runs" / "TissueRetract-Lift-v0"
    first, second = (task / f"s{seed}" / "sweep" / "expert_episodes.jsonl" for seed in (4, 5))
    assert first.read_text() == second.read_text()
    assert "--seed 1000" in (task / "s5" / "sweep" / "report.md").read_text()


def test_tissue_test_prints_and_writes_both_tests(tmp_path: Path) -> None:
    """`tissue-test` measures tension within 10 % of E t W eps and writes both tests with their curves."""
    out = tmp_path / "material.json"
    # The coarsest lattice (4 nodes a side, a third of the default's CPU): its 1/(n - 1) share of E t / k is the
    # largest; tests/sim/test_material.py measures the default lattice over E, t and W.
    argv = ("tissue-test", "--tissue", "liver", "--size-mm", "60", "--resolution", "4", "--json", str(out))
    result = run_one(*argv)
    assert result.returncode == 0, result.stderr
    assert "uniaxial tension to 10 %" in result.stdout and "picture-frame shear to 10 %" in result.stdout
    document = json.loads(out.read_text())
    assert document["material"]["youngs_modulus_kpa"] == 5.4 and document["material"]["preset"] == "liver"
    uniaxial = document["uniaxial"]
    assert uniaxial["expected_force_n"] == pytest.approx(5.4e3 * 5e-3 * 0.06 * 0.10)
    assert abs(uniaxial["force_n"] / uniaxial["expected_force_n"] - 1.0) < 0.10
    assert len(uniaxial["curve"]) == 10 and set(document["shear"]) >= {"force_n", "strain", "expected_force_n"}


def test_tissue_test_refuses_an_unknown_preset() -> None:
    """An unknown preset exits 1 with the preset names, and no traceback."""
    result = run_one("tissue-test", "--tissue", "kidney")
    assert result.returncode == 1
    assert "liver" in result.stderr and "small-bowel" in result.stderr and "Traceback" not in result.stderr
