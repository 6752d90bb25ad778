"""Checkpoints: round trip, refusal of non-tensor payloads and of mismatched spaces, resuming."""

from __future__ import annotations

import csv
import json
import pickle
import struct
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from safetensors.torch import save_file

from policies.algos import AGENTS, Dims, make_agent
from policies.checkpoint import env_spaces, load_checkpoint, load_policy, save_checkpoint
from policies.config import TrainConfig
from policies.errors import CheckpointError, SpaceMismatchError
from policies.toy_env import TOY_TASK_ID, ToyReachEnv
from policies.trainer import RunSpec, train

SMALL = {"hidden_sizes": (32, 32), "batch_size": 32, "random_steps": 100, "updates_per_episode": 5}


def _observations(n: int) -> list[dict[str, np.ndarray]]:
    env = ToyReachEnv()
    out = []
    for i in range(n):
        obs, _ = env.reset(seed=i)
        out.append(obs)
    return out


@pytest.mark.parametrize("algo", sorted(AGENTS))
def test_save_load_gives_identical_actions(algo: str, tmp_path: Path) -> None:
    """A saved policy, loaded with load_policy, gives bit-identical deterministic actions."""
    env = gym.make(TOY_TASK_ID)
    agent = make_agent(Dims(4, 3, 5), TrainConfig(algo=algo, hidden_sizes=(32, 32)), seed=3)
    rng = np.random.default_rng(0)
    agent.observe_episode(rng.normal(size=(51, 4)), rng.normal(size=(51, 3)), rng.normal(size=(50, 3)))
    path = save_checkpoint(
        tmp_path / "p.safetensors", agent, task_id=TOY_TASK_ID, spaces=env_spaces(env), command="test", progress={}
    )
    policy = load_policy(path, env)
    for obs in _observations(10):
        expected = agent.act(obs["observation"], obs["desired_goal"])
        np.testing.assert_array_equal(policy(obs), expected)
    meta = load_checkpoint(path).meta
    assert meta["format_version"] == 1 and meta["algo"] == algo and meta["task_id"] == TOY_TASK_ID
    assert meta["spaces"]["observation"] == [4] and meta["command"] == "test"
    assert set(load_checkpoint(path).tensors) == {f"actor.{k}" for k in agent.actor.state_dict()}


class _Trap:
    """Unpickling this would create a file: proof that code ran."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self) -> tuple[object, tuple[str, str]]:
        return (Path.write_text, (str(self.marker), "code ran"))


def test_pickle_payload_is_refused_without_running_it(tmp_path: Path) -> None:
    """A pickle or torch.save file is refused, and nothing in it is executed."""
    marker = tmp_path / "marker"
    for name, write in (
        ("evil.safetensors", lambda p: p.write_bytes(pickle.dumps({"actor": _Trap(marker)}))),
        ("evil.pt", lambda p: torch.save({"actor": _Trap(marker)}, p)),
    ):
        path = tmp_path / name
        write(path)
        with pytest.raises(CheckpointError, match="not a safetensors file"):
            load_policy(path, gym.make(TOY_TASK_ID))
    assert not marker.exists()


def test_malformed_and_foreign_files_are_refused(tmp_path: Path) -> None:
    """Truncated files, safetensors without our metadata, and unknown versions are refused with a reason."""
    env = gym.make(TOY_TASK_ID)
    short = tmp_path / "short.safetensors"
    short.write_bytes(b"\x01\x02")
    foreign = tmp_path / "foreign.safetensors"
    save_file({"w": torch.zeros(2)}, str(foreign))
    future = tmp_path / "future.safetensors"
    meta = {"format": "tissue-retract-checkpoint", "format_version": 99, "algo": "ddpg"}
    save_file({"w": torch.zeros(2)}, str(future), metadata={"tissue_retract": json.dumps(meta)})
    header = json.dumps(
        {"__metadata__": {"tissue_retract": "{}"}, "w": {"dtype": "F32", "shape": [4], "data_offsets": [0, 16]}}
    )
    lying = tmp_path / "lying.safetensors"
    lying.write_bytes(struct.pack("<Q", len(header)) + header.encode() + b"\x00" * 4)
    for path, reason in ((short, "too short"), (foreign, "metadata"), (future, "version 99"), (lying, "format")):
        with pytest.raises(CheckpointError, match=reason):
            load_policy(path, env)
    with pytest.raises(CheckpointError, match="no such file"):
        load_policy(tmp_path / "missing.safetensors", env)


class _WiderToy(ToyReachEnv):
    def __init__(self) -> None:
        super().__init__()
        self.action_space = gym.spaces.Box(-1.0, 1.0, (4,), dtype=np.float32)


def test_space_mismatch_is_refused_with_a_clear_message(tmp_path: Path) -> None:
    """A checkpoint is refused by an env whose action (or observation) space differs, naming both."""
    env = gym.make(TOY_TASK_ID)
    agent = make_agent(Dims(4, 3, 5), TrainConfig(hidden_sizes=(8,)), seed=0)
    path = save_checkpoint(
        tmp_path / "p.safetensors", agent, task_id=TOY_TASK_ID, spaces=env_spaces(env), command="", progress={}
    )
    with pytest.raises(SpaceMismatchError) as info:
        load_policy(path, _WiderToy())
    assert info.value.key == "action" and "(5,)" in str(info.value) and "(4,)" in str(info.value)
    spaces = env_spaces(env)
    spaces["observation"] = [18]
    other = save_checkpoint(tmp_path / "o.safetensors", agent, task_id="x", spaces=spaces, command="", progress={})
    with pytest.raises(SpaceMismatchError, match="observation space"):
        load_policy(other, env)


@pytest.mark.parametrize("algo", ["ddpgbc", "sqil"])
def test_interrupted_run_resumes_to_the_same_result(algo: str, tmp_path: Path) -> None:
    """Training 2 episodes, then resuming to 4, ends with the same weights as 4 episodes in one go."""
    config = TrainConfig(algo=algo, **SMALL)  # type: ignore[arg-type]

    def run(out: Path, episodes: int) -> Path:
        spec = RunSpec(
            TOY_TASK_ID, seed=2, episodes=episodes, demos=2, out_dir=out, eval_every=2, eval_episodes=2,
            progress=False, tensorboard=False,
        )  # fmt: skip
        return train(spec, config).resume_path

    once = run(tmp_path / "once", 4)
    run(tmp_path / "split", 2)
    split = run(tmp_path / "split", 4)
    a, b = load_checkpoint(once), load_checkpoint(split)
    assert a.meta["progress"] == b.meta["progress"]
    for key in a.tensors:
        if key.startswith(("actor.", "critic.", "optim.")):
            assert torch.equal(a.tensors[key], b.tensors[key]), key
    rows = (tmp_path / "split" / "eval.csv").read_text().splitlines()
    assert [r.split(",")[0] for r in rows] == ["episode", "2", "4"]


def test_a_run_stopped_before_its_first_evaluation_still_gets_a_csv_header(tmp_path: Path) -> None:
    """Stopped before anything was flushed, a run leaves an empty eval.csv; the rerun must head it."""
    (tmp_path / "eval.csv").touch()
    spec = RunSpec(
        TOY_TASK_ID, seed=1, episodes=2, demos=0, out_dir=tmp_path, eval_every=2, eval_episodes=1,
        progress=False, tensorboard=False,
    )  # fmt: skip
    train(spec, TrainConfig(**SMALL))  # type: ignore[arg-type]
    rows = list(csv.DictReader((tmp_path / "eval.csv").open()))
    assert [row["episode"] for row in rows] == ["2"]


def test_resume_refuses_a_different_run(tmp_path: Path) -> None:
    """Resuming into a directory written with another config or seed is refused, naming the difference."""
    spec = RunSpec(
        TOY_TASK_ID, seed=1, episodes=1, demos=0, out_dir=tmp_path, eval_episodes=1, progress=False, tensorboard=False
    )
    train(spec, TrainConfig(**SMALL))  # type: ignore[arg-type]
    with pytest.raises(CheckpointError, match="different config"):
        train(spec, TrainConfig(**{**SMALL, "tau": 0.01}))  # type: ignore[arg-type]
