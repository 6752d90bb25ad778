"""The Stable-Baselines3 cross-check trains and is scored by our evaluation (a tiny smoke run)."""

from __future__ import annotations

import json
import tempfile
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


def test_smoke_run_trains_for_the_budget_and_returns_a_scored_result(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Two episodes train SB3 for 100 env steps, write the model and return a result within its interval."""
    system_tmp = tmp_path / "system-tmp"
    system_tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(system_tmp))
    monkeypatch.delenv("SB3_LOGDIR", raising=False)
    result = crosscheck_sb3(episodes=2, seed=0, eval_episodes=2, learning_starts=50, gradient_steps=2, out=tmp_path)
    assert not list(system_tmp.glob("SB3-*"))  # no log folder left in the system's temporary directory
    assert set(result) >= KEYS
    assert result["train_episodes"] == 2 and result["env_steps"] <= 100
    assert result["eval_episodes"] == 2 and 0 <= result["successes"] <= 2
    low, high = result["ci95"]
    assert low <= result["success_rate"] <= high
    assert result["settings"]["policy_kwargs"]["net_arch"] == {"pi": [128, 128, 128], "qf": [128, 128, 128]}
    assert (tmp_path / "sb3_ddpg_her.zip").is_file()
    assert json.loads((tmp_path / "result.json").read_text())["successes"] == result["successes"]


def test_normalized_run_learns_its_statistics_from_training_and_saves_them(tmp_path: Path) -> None:
    """With VecNormalize the statistics count every training step and are written beside the model."""
    import pickle

    result = crosscheck_sb3(
        episodes=2, seed=0, eval_episodes=1, learning_starts=50, gradient_steps=2, out=tmp_path, normalize=True
    )
    assert result["settings"]["normalize"] is True
    with (tmp_path / "vecnormalize.pkl").open("rb") as f:
        stats = pickle.load(f)  # written by this test's own run
    assert stats.training is False
    for key in ("observation", "desired_goal", "achieved_goal"):
        # One count per env step (the first reset adds one more); evaluation must not have added any.
        assert 100 <= stats.obs_rms[key].count <= 102
        assert float(stats.obs_rms[key].var.max()) > 0.0


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
