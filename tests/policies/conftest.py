"""Fixtures of the learning tests."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import pytest
import torch

from policies.reproduce import Run, RunOutcome, plan, reproduce
from policies.toy_env import TOY_TASK_ID

#: Training settings small enough for a reproduction's run of a few episodes on the toy task to take a fraction
#: of a second.
TINY = {"random_steps": 50, "updates_per_episode": 2, "batch_size": 16, "hidden_sizes": (16,), "bc_pretrain_steps": 5}


@pytest.fixture(autouse=True)
def one_torch_thread() -> Iterator[None]:
    """Run torch on one thread, as training does: small networks are fastest so on a shared CPU."""
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)


class ToyReproduction(NamedTuple):
    """A finished reproduction on the toy task and what :func:`policies.reproduce.reproduce` returned."""

    out_dir: Path
    runs: list[Run]
    results_md: Path
    outcomes: list[RunOutcome]
    ended: list[RunOutcome]  # as ``on_finished`` received them


@pytest.fixture(scope="session")
def toy_reproduction(tmp_path_factory: pytest.TempPathFactory) -> ToyReproduction:
    """DDPG and DDPG+BC, two seeds each, two episodes each, trained in a pool of two processes; its page
    shows the command ``tissue-retract reproduce --budget 2``.

    Read-only: the tests that take it check different things of the same reproduction, which costs two
    spawned workers that each import torch and the simulation.
    """
    out = tmp_path_factory.mktemp("toy-reproduction")
    runs = plan(
        out / "runs", episodes=2, tasks={"toy": TOY_TASK_ID}, algos=("ddpg", "ddpgbc"), seeds=(1, 2), demos=2,
        eval_every=1, eval_episodes=1, overrides=TINY,
    )  # fmt: skip
    ended: list[RunOutcome] = []
    path, outcomes = reproduce(
        out, runs, jobs=2, command="tissue-retract reproduce --budget 2", on_finished=ended.append
    )
    return ToyReproduction(out, runs, path, outcomes, ended)
