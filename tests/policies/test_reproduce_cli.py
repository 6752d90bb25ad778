"""`tissue-retract reproduce` runs as a user types it, at a tiny budget."""

from __future__ import annotations

from pathlib import Path

from tests.conftest import run_cli


def test_reproduce_writes_tables_beside_the_paper(tmp_path: Path) -> None:
    """A one-run reproduction writes results.md with the paper's number beside ours, and the curves."""
    result = run_cli(
        "reproduce",
        "--budget",
        "2",
        "--tasks",
        "I",
        "--algos",
        "ddpg",
        "--seeds",
        "1",
        "--demos",
        "2",
        "--no-ablation",
        "--eval-episodes",
        "2",
        "--jobs",
        "1",
        "--out",
        str(tmp_path),
    )
    assert result.returncode == 0, result.stderr
    text = (tmp_path / "results.md").read_text()
    assert "83 +- 0.7" in text  # the paper's DDPG on Task I, beside ours
    assert (tmp_path / "curves.png").stat().st_size > 1000


def test_unknown_algorithm_is_refused() -> None:
    """An algorithm outside the five is refused with the valid names."""
    result = run_cli("reproduce", "--algos", "ppo")
    assert result.returncode == 1
    assert "ddpgbc" in result.stderr
