"""Training that goes non-finite stops with an error and keeps the last good checkpoint."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from policies.algos.base import Agent
from policies.checkpoint import load_checkpoint
from policies.config import TrainConfig
from policies.errors import TrainingDivergedError
from policies.toy_env import TOY_TASK_ID
from policies.trainer import POLICY_FILE, RunSpec, train


def test_a_nan_weight_stops_training_and_keeps_the_last_good_policy(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A weight turning NaN in the third episode's updates: TrainingDivergedError, episode 2's policy kept."""
    original = Agent.train
    calls = {"n": 0}

    def poisoned(self: Agent, *args: Any, **kwargs: Any) -> dict[str, float]:
        metrics = original(self, *args, **kwargs)
        calls["n"] += 1
        if calls["n"] == 3:
            with torch.no_grad():
                next(self.actor.parameters()).fill_(float("nan"))
        return metrics

    monkeypatch.setattr(Agent, "train", poisoned)
    spec = RunSpec(
        task_id=TOY_TASK_ID, episodes=4, eval_every=1, eval_episodes=1, out_dir=tmp_path, progress=False,
        tensorboard=False,
    )  # fmt: skip
    config = TrainConfig(algo="ddpg", random_steps=0, updates_per_episode=2, batch_size=8, hidden_sizes=(8,))
    with pytest.raises(TrainingDivergedError, match=r"episode 3.*not finite.*last good policy is kept"):
        train(spec, config)
    kept = load_checkpoint(tmp_path / POLICY_FILE)  # refuses non-finite weights: this one is clean
    assert kept.meta["progress"]["episodes"] == 2
    assert all(np.isfinite(t.numpy()).all() for t in kept.group("actor").values())
