"""The Stable-Baselines3 cross-check trains and is scored by our evaluation (a tiny smoke run)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from policies.crosscheck import crosscheck_sb3, main
from psm_control.errors import ConfigurationError

pytest.importorskip("stable_baselines3")

KEYS = {
    "successes",
    "eval_episodes",
    "success_rate",
    "ci95",
    "train_episodes",
    "env_steps",
    "train_wall_s",
    "env_steps_per_s",
    "eval_wall_s",
    "failure_classes",
    "seed",
    "eval_seed",
    "settings",
}


def test_smoke_run_trains_for_the_budget_and_returns_a_scored_result(tmp_path: Path) -> None:
    """Two episodes train SB3 for 100 env steps, write the model and return a result within its interval."""
    result = crosscheck_sb3(episodes=2, seed=0, eval_episodes=2, learning_starts=50, gradient_steps=2, out=tmp_path)
    assert set(result) >= KEYS
    assert result["train_episodes"] == 2 and result["env_steps"] <= 100
    assert result["eval_episodes"] == 2 and 0 <= result["successes"] <= 2
    low, high = result["ci95"]
    assert low <= result["success_rate"] <= high
    assert result["settings"]["policy_kwargs"]["net_arch"] == {"pi": [128, 128, 128], "qf": [128, 128, 128]}
    assert (tmp_path / "sb3_ddpg_her.zip").is_file()
    assert json.loads((tmp_path / "result.json").read_text())["successes"] == result["successes"]


def test_a_non_positive_budget_is_refused() -> None:
    """Zero training or evaluation episodes raise a ConfigurationError naming the field."""
    with pytest.raises(ConfigurationError, match="episodes"):
        crosscheck_sb3(episodes=0)
    with pytest.raises(ConfigurationError, match="eval_episodes"):
        crosscheck_sb3(episodes=1, eval_episodes=0)


def test_command_line_prints_the_table(capsys: pytest.CaptureFixture[str]) -> None:
    """``main`` runs a one-episode cross-check and prints success with its Wilson interval."""
    assert main(["--episodes", "1", "--eval-episodes", "1"]) == 0
    out = capsys.readouterr().out
    assert "success (eval)" in out and "95 % Wilson interval" in out
