"""Episodes collected in a worker process are the episodes collected here, and learning runs during them."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from policies.algos import Dims
from policies.collect import OverlappedCollector, SerialCollector, can_run_in_worker
from policies.config import TrainConfig
from policies.demos import collect_demos, expert_for
from policies.toy_env import TOY_TASK_ID
from policies.trainer import RunSpec, _demonstrations, ensure_registered, train
from psm_control.errors import ConfigurationError


def _actions(seed: int, size: int) -> Callable[[dict[str, np.ndarray]], np.ndarray]:
    rng = np.random.default_rng(seed)
    return lambda obs: rng.uniform(-1.0, 1.0, size).astype(np.float32)


def test_the_worker_collects_the_same_episode_and_learns_at_every_step() -> None:
    task = ensure_registered(TOY_TASK_ID)
    env = gym.make(task)
    serial, overlapped = SerialCollector(env), OverlappedCollector(task)
    size = int(np.prod(env.action_space.shape))
    try:
        calls: list[int] = []
        here = serial.episode(7, _actions(1, size), lambda step: None)
        there = overlapped.episode(7, _actions(1, size), calls.append)
        second = overlapped.episode(8, _actions(2, size), lambda step: None)
    finally:
        overlapped.close()
        env.close()
    for name in here._fields:
        np.testing.assert_array_equal(getattr(here, name), getattr(there, name), err_msg=name)
    assert calls == list(range(-1, len(there.action)))  # the reset, then every step
    assert not np.array_equal(second.obs[0], there.obs[0])  # a new episode, from its own seed


def test_the_worker_collects_the_demonstrations_this_process_would() -> None:
    """Demonstrations asked of the worker are the expert's episodes from the same seeds, as here."""
    task = ensure_registered(TOY_TASK_ID)
    env = gym.make(task)
    overlapped = OverlappedCollector(task)
    try:
        overlapped.start_demonstrations(3, seed=11)
        there = overlapped.finish_demonstrations()
        here = collect_demos(env, expert_for(task), 3, seed=11)
    finally:
        overlapped.close()
        env.close()
    assert len(there) == len(here) == 3
    for a, b in zip(here, there, strict=True):
        for name in a._fields:
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_a_run_with_a_worker_splits_its_demonstrations_over_distinct_episodes() -> None:
    """Half the demonstrations come from this process, the rest from the worker, none of them twice."""
    spec = RunSpec(TOY_TASK_ID, seed=4, demos=5, overlap=True)
    task = ensure_registered(TOY_TASK_ID)
    env = gym.make(task)
    overlapped = OverlappedCollector(task)
    try:
        dims = Dims(4, 3, 5)
        demos = _demonstrations(spec, env, dims, overlapped)
        serial = _demonstrations(spec, env, dims, SerialCollector(env))
    finally:
        overlapped.close()
        env.close()
    assert len(demos) == len(serial) == 5
    for a, b in zip(demos[:2], serial[:2], strict=True):  # this process's half: the serial run's first two
        np.testing.assert_array_equal(a.obs, b.obs)
    starts = {tuple(episode.obs[0]) for episode in demos}
    assert len(starts) == 5


def test_an_overlapped_run_trains_and_keeps_a_policy(tmp_path: Path) -> None:
    spec = RunSpec(
        TOY_TASK_ID, seed=2, episodes=4, demos=2, out_dir=tmp_path, eval_every=2, eval_episodes=2,
        progress=False, tensorboard=False, overlap=True,
    )  # fmt: skip
    result = train(spec, TrainConfig(algo="ddpgbc", random_steps=20, updates_per_episode=10))
    assert result.policy_path.exists() and len(result.success_rates) == 2
    assert result.env_steps > 20 and result.update_seconds >= 0.0


def test_a_wrapper_that_cannot_reach_a_worker_is_refused_before_anything_runs(tmp_path: Path) -> None:
    assert can_run_in_worker(None) and not can_run_in_worker(lambda env: env)
    spec = RunSpec(TOY_TASK_ID, out_dir=tmp_path, overlap=True, env_wrapper=lambda env: env)
    with pytest.raises(ConfigurationError, match="picklable"):
        train(spec, TrainConfig())
    assert not any(tmp_path.iterdir())


_CHILD = """
import sys
from policies.collect import OverlappedCollector
from policies.toy_env import TOY_TASK_ID
from policies.trainer import ensure_registered

collector = OverlappedCollector(ensure_registered(TOY_TASK_ID))
collector.episode(1, lambda obs: [0.0] * 5, lambda step: None)
print("collected", flush=True)
sys.stdin.read()  # until killed
"""


@pytest.mark.skipif(sys.platform != "linux", reason="SIGKILL")
def test_a_killed_parent_leaves_its_worker_to_end_without_a_traceback() -> None:
    """SIGKILL of the learner: its collecting worker ends by itself and prints no traceback."""
    child = subprocess.Popen(
        [sys.executable, "-c", _CHILD], stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        assert child.stdout is not None and child.stdout.readline() == "collected\n"
        child.kill()
        child.wait(timeout=60)
        # The worker inherited stderr: its end of file means the worker has ended too.
        _, err = child.communicate(timeout=120)
    finally:
        child.kill()
    assert "Traceback" not in err and "BrokenPipeError" not in err, err


def test_the_worker_collects_lag_blind_demonstrations_when_asked() -> None:
    """Asked for lag-blind demonstrations, the worker runs the lag-blind expert: its episodes are this
    process's lag-blind ones, and not the lag-aware expert's (Task III at its nominal 0-1 steps of latency)."""
    task = ensure_registered("multisite")
    env = gym.make(task)
    overlapped = OverlappedCollector(task)
    try:
        overlapped.start_demonstrations(1, seed=21, lag_blind=True)
        (there,) = overlapped.finish_demonstrations()
        (here,) = collect_demos(env, expert_for(task, lag_blind=True), 1, seed=21)
        (aware,) = collect_demos(env, expert_for(task), 1, seed=21)
    finally:
        overlapped.close()
        env.close()
    np.testing.assert_array_equal(here.action, there.action)
    assert not np.array_equal(here.action[: len(aware.action)], aware.action[: len(here.action)])
