"""Smoke runs of ``tissue-retract train`` for every algorithm and task, and a learning check on the toy task."""

from __future__ import annotations

import csv
import shlex
import subprocess
import sys
import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from policies.algos import Dims, make_agent
from policies.budget import FINISH_RESERVE_S, Budget
from policies.checkpoint import load_checkpoint, load_policy
from policies.collect import SerialCollector
from policies.config import ALGORITHMS, TrainConfig
from policies.recipe import DEFAULT_RECIPE, ROBUST_RECIPE
from policies.toy_env import TOY_TASK_ID
from policies.trainer import RunSpec, _demonstrations, ensure_registered, evaluate, train
from psm_control.errors import ConfigurationError
from tests.forked_cli import run_forked
from tissue_retract.cli import main


def _simulation_tasks() -> list[str]:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import sim  # noqa: F401
    except ImportError:
        return []
    return sorted(k for k in gym.registry if k.startswith("TissueRetract-") and k != TOY_TASK_ID)


TASKS = [TOY_TASK_ID, *_simulation_tasks()]
TINY = ["random_steps=60", "updates_per_episode=3", "batch_size=16", "hidden_sizes=[16,16]", "bc_pretrain_steps=5"]


@pytest.mark.parametrize("task", TASKS)
@pytest.mark.parametrize("algo", ALGORITHMS)
def test_train_smoke(task: str, algo: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """train runs end to end and writes a loadable policy, a resumable checkpoint and the evaluation CSV."""
    args = ["train", "--task", task, "--algo", algo, "--demos", "1", "--episodes", "2", "--seed", "1"]
    args += ["--out", str(tmp_path), "--eval-every", "2", "--eval-episodes", "1", "--no-progress", "--no-tensorboard"]
    for item in TINY:
        args += ["--set", item]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        assert main(args) == 0
        out = capsys.readouterr().out
        assert "env steps/s including gradient updates" in out
        ckpt = load_checkpoint(tmp_path / "policy.safetensors")
        assert ckpt.meta["algo"] == algo and ckpt.meta["task_id"] == task
        assert ckpt.meta["command"].startswith("tissue-retract train") or "--task" in ckpt.meta["command"]
        assert load_checkpoint(tmp_path / "resume.safetensors").meta["kind"] == "training"
        env = gym.make(task)
        obs, _ = env.reset(seed=0)
        action = load_policy(tmp_path / "policy.safetensors", env)(obs)
        assert env.action_space.contains(action)
        env.close()
    rows = list(csv.DictReader((tmp_path / "eval.csv").open()))
    assert [r["episode"] for r in rows] == ["2"]


def test_train_command_line(tmp_path: Path) -> None:
    """The installed command trains, logs to TensorBoard and resumes when run again with more episodes."""
    args = ["train", "--task", TOY_TASK_ID, "--algo", "ddpg", "--out", str(tmp_path), "--eval-every", "1"]
    args += ["--eval-episodes", "1", "--set", "random_steps=50", "--set", "updates_per_episode=2"]
    command = [sys.executable, "-m", "tissue_retract", *args, "--episodes", "1"]
    first = subprocess.run(command, capture_output=True, text=True, timeout=300, check=False)
    assert first.returncode == 0, first.stderr
    assert "throughput:" in first.stdout and list((tmp_path / "tb").iterdir())
    # Run again as a new process would, forked from this one: without importing torch and the simulation again.
    second, bad = run_forked([[*args, "--episodes", "2"], [*args, "--set", "gamma=2"]], parallel=1)
    assert second.returncode == 0, second.stderr
    assert "resumed from episode 1" in second.stdout
    assert bad.returncode == 1 and "gamma=2" in bad.stderr and "[0, 1)" in bad.stderr


def test_ddpg_her_learns_the_toy_reach_task(tmp_path: Path) -> None:
    """DDPG+HER with the paper's defaults reaches >= 90 % success on the toy task within 60 episodes (seed 1)."""
    spec = RunSpec(
        TOY_TASK_ID, seed=1, episodes=60, demos=0, out_dir=tmp_path, eval_every=60, eval_episodes=20,
        progress=False, tensorboard=False,
    )  # fmt: skip
    result = train(spec, TrainConfig(algo="ddpg"))
    assert result.final_success >= 0.9


def test_demonstrations_from_a_file_in_the_simulation_layout(tmp_path: Path) -> None:
    """A demos .npz in the layout of `tissue-retract demo --out` (observation, action, per-step goals) trains."""
    import numpy as np

    from policies.demos import collect_demos, expert_for, load_demos

    env = gym.make(TOY_TASK_ID)
    episodes = collect_demos(env, expert_for(TOY_TASK_ID), 3, seed=0)
    goals = [np.vstack((e.desired_goal, e.desired_goal[-1:])) for e in episodes]
    path = tmp_path / "demos.npz"
    np.savez_compressed(
        path,
        observation=np.stack([e.obs for e in episodes]),
        achieved_goal=np.stack([e.achieved_goal for e in episodes]),
        desired_goal=np.stack(goals),
        action=np.stack([e.action for e in episodes]),
        reward=np.zeros((3, 50), np.float32),
        seed=np.arange(3),
        metadata='{"task": "toy"}',
    )
    loaded = load_demos(path, 2)
    assert len(loaded) == 2
    np.testing.assert_array_equal(loaded[1].desired_goal, episodes[1].desired_goal)
    np.testing.assert_array_equal(loaded[1].action, episodes[1].action)
    args = ["train", "--task", TOY_TASK_ID, "--algo", "ddpgbc", "--demos", "3", "--demos-file", str(path)]
    args += [
        "--episodes",
        "1",
        "--out",
        str(tmp_path / "run"),
        "--eval-episodes",
        "1",
        "--no-progress",
        "--no-tensorboard",
    ]
    for item in TINY:
        args += ["--set", item]
    assert main(args) == 0


def test_train_blind_trains_on_the_registered_task(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """train --blind runs end to end, and its checkpoint records the flags that reproduce it."""
    args = ["train", "--task", "lift", "--algo", "ddpgbc", "--demos", "1", "--episodes", "2", "--blind"]
    args += ["--registration-error-mm", "2.5", "--out", str(tmp_path), "--eval-every", "2", "--eval-episodes", "1"]
    args += ["--no-progress", "--no-tensorboard"]
    for item in TINY:
        args += ["--set", item]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        assert main(args) == 0
    capsys.readouterr()
    command = load_checkpoint(tmp_path / "policy.safetensors").meta["command"]
    assert "--blind" in command and "2.5" in command


def test_train_blind_refuses_a_task_without_a_goal_place(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--blind on a task whose goal is not a place is refused with what is allowed, not a traceback."""
    args = ["train", "--task", TOY_TASK_ID, "--algo", "ddpgbc", "--demos", "1", "--episodes", "1", "--blind"]
    assert main([*args, "--out", str(tmp_path), "--no-progress", "--no-tensorboard"]) == 1
    assert "a task whose goal is a place" in capsys.readouterr().err
    assert not (tmp_path / "policy.safetensors").exists()


def test_a_run_resumes_only_on_what_it_observed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A run trained on the task's observation does not silently continue on the blind one."""
    args = ["train", "--task", "lift", "--algo", "ddpgbc", "--demos", "1", "--out", str(tmp_path)]
    args += ["--eval-every", "1", "--eval-episodes", "1", "--no-progress", "--no-tensorboard"]
    for item in TINY:
        args += ["--set", item]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        assert main([*args, "--episodes", "1"]) == 0
        assert load_checkpoint(tmp_path / "resume.safetensors").meta["observation"] == "task"
        capsys.readouterr()
        assert main([*args, "--episodes", "2", "--blind"]) == 1
    err = capsys.readouterr().err
    assert "different observation" in err and "--fresh" in err


def test_a_budget_ends_with_the_best_evaluated_policy(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--budget-s stops long before --episodes, evaluates the last state, and keeps the best evaluation."""
    args = ["train", "--task", TOY_TASK_ID, "--algo", "ddpgbc", "--demos", "2", "--episodes", "100000"]
    args += ["--budget-s", "6", "--eval-every", "3", "--eval-episodes", "3", "--out", str(tmp_path)]
    args += ["--no-progress", "--no-tensorboard"]
    for item in TINY:
        args += ["--set", item]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "budget 6 s:" in out and "best evaluated policy: episode" in out
    rows = [(int(r["episode"]), float(r["success_rate"])) for r in csv.DictReader((tmp_path / "eval.csv").open())]
    last_episode = rows[-1][0]
    assert last_episode < 100_000
    best_episode = max(rows, key=lambda row: (row[1], row[0]))[0]  # the best; of equals, the latest
    assert load_checkpoint(tmp_path / "policy.safetensors").meta["progress"]["episodes"] == best_episode
    assert load_checkpoint(tmp_path / "resume.safetensors").meta["progress"]["episodes"] == last_episode
    assert f"episode {best_episode}," in out


def test_the_budget_keeps_room_for_the_next_episode_the_last_evaluation_and_the_exit() -> None:
    """Each estimate is the last measured one; before any evaluation, its episodes at twice the step time."""
    now = [0.0]
    budget = Budget(10.0, started_s=0.0, clock=lambda: now[0])
    budget.episode_s, budget.step_s = 0.5, 0.01  # an evaluation of 3 x 50 steps: estimated 3 s
    now[0] = 10.0 - 0.5 - 3.0 - FINISH_RESERVE_S  # the latest time the next episode still fits
    assert budget.fits_episode(3, 50)
    now[0] += 0.01
    assert not budget.fits_episode(3, 50)
    budget.evaluation_s = 1.0  # measured: replaces the estimate
    assert budget.fits_episode(3, 50)
    assert Budget(None, started_s=0.0, clock=lambda: 1e9).fits_episode(3, 50)


def test_an_evaluation_the_budget_cannot_hold_is_cut_short_after_at_least_one_episode() -> None:
    """Out of time: the evaluation stops between episodes and says over how many its success rate is."""
    task = ensure_registered(TOY_TASK_ID)
    env = gym.make(task)
    agent = make_agent(Dims(*_toy_dims(env)), TrainConfig(algo="ddpg"), seed=0)
    try:
        calls = iter([False, False, True])
        success, ran = evaluate(agent, env, 10, out_of_time=lambda: next(calls))
        assert ran == 3 and 0.0 <= success <= 1.0
        assert evaluate(agent, env, 2, out_of_time=lambda: True)[1] == 1
    finally:
        env.close()


def test_demonstrations_stop_when_the_budget_ends_and_progress_is_shown(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Asked for far more demonstrations than a 6 s budget holds, the run collects fewer, says so, and ends."""
    args = ["train", "--task", TOY_TASK_ID, "--demos", "100000", "--budget-s", "6", "--eval-episodes", "3"]
    args += ["--out", str(tmp_path), "--no-tensorboard"]
    assert main(args) == 0
    captured = capsys.readouterr()
    assert "demonstrations:" in captured.err  # the progress bar of the collection
    line = next(line for line in captured.out.splitlines() if line.startswith("demonstrations: "))
    assert int(line.split()[1]) < 100000 and "of 100000 (the budget ended their collection)" in line
    assert "budget 6 s:" in captured.out


@pytest.mark.parametrize(("pretraining_s", "collected"), [(0.0, 40), (999.0, 10)])
def test_demonstrations_leave_the_budget_room_for_the_pretraining_after_them(
    pretraining_s: float, collected: int
) -> None:
    """Timed on the first chunk, a pretraining that needs the rest of the preparation's share stops the
    collection there; one that needs nothing lets it finish."""
    spec = RunSpec(TOY_TASK_ID, seed=2, demos=40)
    env = gym.make(ensure_registered(TOY_TASK_ID))
    budget = Budget(2000.0, started_s=0.0, clock=lambda: 1.0, preparation_share=0.5)
    timed: list[int] = []

    def pretraining(demos: list[Any]) -> float:
        timed.append(len(demos))
        return pretraining_s

    try:
        demos = _demonstrations(spec, env, Dims(*_toy_dims(env)), SerialCollector(env), budget, None, pretraining)
    finally:
        env.close()
    assert len(demos) == collected and timed == [10] and budget.pretraining_s == pretraining_s


def test_a_budget_outside_its_range_is_refused_with_what_is_allowed(capsys: pytest.CaptureFixture[str]) -> None:
    """--budget-s 0 is a usage error naming the range, not a traceback."""
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "--task", TOY_TASK_ID, "--budget-s", "0"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "--budget-s" in err and "Traceback" not in err


def test_without_algo_the_recipe_trains_in_a_worker_and_stops_at_its_target(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """No --algo: the default recipe (CoL from the expert's demonstrations, a collecting worker) stops at the
    first evaluation that reaches its target and keeps that policy; --algo keeps the paper's run."""
    args = ["train", "--task", TOY_TASK_ID, "--episodes", "40", "--eval-every", "2", "--eval-episodes", "5"]
    args += ["--out", str(tmp_path / "recipe"), "--no-progress", "--no-tensorboard"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert f"recipe {DEFAULT_RECIPE.name}: col, {DEFAULT_RECIPE.demos} demonstrations, collecting in a worker" in out
    rows = [
        (int(r["episode"]), float(r["success_rate"])) for r in csv.DictReader((tmp_path / "recipe" / "eval.csv").open())
    ]
    assert rows[0][0] == 0  # first, what the demonstrations alone taught
    assert rows[-1][1] >= DEFAULT_RECIPE.stop_at_success
    assert all(success < DEFAULT_RECIPE.stop_at_success for _, success in rows[:-1])
    stopped = rows[-1][0]
    assert f"stopped at episode {stopped}" in out and stopped < 40
    assert load_checkpoint(tmp_path / "recipe" / "policy.safetensors").meta["progress"]["episodes"] == stopped
    paper = ["train", "--task", TOY_TASK_ID, "--algo", "ddpg", "--episodes", "2", "--eval-every", "1"]
    paper += ["--eval-episodes", "1", "--out", str(tmp_path / "paper"), "--no-progress", "--no-tensorboard"]
    assert main(paper) == 0
    out = capsys.readouterr().out
    assert "recipe fast" not in out and "stopped at" not in out
    assert len(list(csv.DictReader((tmp_path / "paper" / "eval.csv").open()))) == 2


@pytest.mark.parametrize("target", [0.0, 1.5, "all", True])
def test_a_stopping_target_that_is_no_success_rate_is_refused(target: object) -> None:
    with pytest.raises(ConfigurationError, match="a success rate in"):
        RunSpec(TOY_TASK_ID, stop_at_success=target)  # type: ignore[arg-type]


def _toy_dims(env: gym.Env) -> tuple[int, int, int]:  # type: ignore[type-arg]
    spaces = env.observation_space
    return (
        int(spaces["observation"].shape[0]),  # type: ignore[index]
        int(spaces["desired_goal"].shape[0]),  # type: ignore[index]
        int(env.action_space.shape[0]),  # type: ignore[index]
    )


#: The issue's robustness sweep (docs/robustness.md), with disturbances of what the policy sees and commands.
SWEEP_VARY = (
    "stiffness=0.3:3x,size=0.8:1.2x,obs_noise=0:0.002,latency=0:3,friction=0.7:1.3x,"
    "obs_white_m=0:0.001,action_impulse=0:0.3"
)


def test_train_takes_the_sweeps_vary_and_records_it(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The recipe (collecting in a worker) trains over the sweep's full --vary; its checkpoints keep the string."""
    args = ["train", "--task", "lift", "--demos", "2", "--episodes", "2", "--eval-every", "2", "--eval-episodes", "1"]
    args += ["--vary", SWEEP_VARY, "--out", str(tmp_path), "--no-progress", "--no-tensorboard"]
    for item in TINY:
        args += ["--set", item]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        assert main(args) == 0
    assert "collecting in a worker" in capsys.readouterr().out
    for name in ("policy.safetensors", "resume.safetensors"):
        meta = load_checkpoint(tmp_path / name).meta
        command = shlex.split(meta["command"])
        assert command[command.index("--vary") + 1] == SWEEP_VARY
        assert meta["observation"] == f"task, randomized over {SWEEP_VARY}"


def test_train_robust_trains_over_the_sweeps_ranges_by_default(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--robust clones over the sweep's --vary unless told otherwise, scores the clone once and trains no further."""
    args = ["train", "--task", "lift", "--robust", "--demos", "2", "--eval-episodes", "1", "--budget-s", "120"]
    args += ["--out", str(tmp_path), "--no-progress", "--no-tensorboard"]
    for item in TINY:
        args += ["--set", item]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        assert main(args) == 0
    out = capsys.readouterr().out
    assert f"recipe {ROBUST_RECIPE.name}: col, 2 demonstrations" in out
    assert f"every episode drawn over {ROBUST_RECIPE.vary}" in out and "budget 120 s" in out
    meta = load_checkpoint(tmp_path / "policy.safetensors").meta
    assert meta["observation"] == f"task, randomized over {ROBUST_RECIPE.vary}"
    assert "--robust" in shlex.split(meta["command"]) and meta["progress"]["episodes"] == 0
    assert [row["episode"] for row in csv.DictReader((tmp_path / "eval.csv").open())] == ["0"]


def test_train_robust_and_algo_are_refused_together(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--robust is a recipe: with one of the paper's algorithms it is refused before anything is written."""
    args = ["train", "--task", "lift", "--robust", "--algo", "ddpg", "--out", str(tmp_path / "run"), "--no-progress"]
    assert main(args) == 1
    assert "either --robust (a recipe) or --algo" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    "vary",
    [
        "stifness=1:2",
        "latency=0.5:0.7",
        "joint_offset=0.5:2x",
        "obs_white_m=-0.001:0.001",
        "stiffness=3:1x",
        "youngs_modulus=2:30mm",
    ],
)
def test_train_and_robustness_refuse_a_bad_vary_alike(
    vary: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One parser: train and robustness refuse the same --vary with the same message, before writing anything."""
    train_args = ["train", "--task", "lift", "--vary", vary, "--out", str(tmp_path / "train"), "--no-progress"]
    assert main(train_args) == 1
    trained = capsys.readouterr().err
    sweep_args = ["robustness", "--policy", "scripted", "--task", "lift", "--vary", vary]
    assert main([*sweep_args, "--out", str(tmp_path / "sweep"), "--no-progress"]) == 1
    swept = capsys.readouterr().err
    assert trained.startswith("tissue-retract train: error: vary") and swept.startswith("tissue-retract robustness:")
    assert trained.partition(": error: ")[2] == swept.partition(": error: ")[2]
    assert not (tmp_path / "train").exists() and not (tmp_path / "sweep").exists()


#: Where the observation vector holds the site (tip 0:3, orientation 3:7, jaw 7), the lift task's achieved goal.
_SITE = slice(8, 11)


@pytest.mark.parametrize("name", ["obs_noise", "obs_white_m"])
def test_observation_noise_reaches_training_and_demonstrations(name: str) -> None:
    """The expert's demonstration on the training env: with NAME=0 the observed site is the true one at every
    step; with NAME>0 it is not, in the same episode (the same seed: the same actions and true sites)."""
    from policies.demos import collect_demos, expert_for
    from tissue_retract.cli import build_parser
    from tissue_retract.cli.train import task_wrapper

    def demonstration(magnitude: str) -> Any:
        vary = f"obs_noise=0,{name}={magnitude}" if name != "obs_noise" else f"obs_noise={magnitude}"
        wrapper = task_wrapper(build_parser(["train"]).parse_args(["train", "--task", "lift", "--vary", vary]))
        assert wrapper is not None
        env = wrapper(gym.make(ensure_registered("lift")))
        try:
            (episode,) = collect_demos(env, expert_for(ensure_registered("lift")), 1, seed=11)
        finally:
            env.close()
        return episode

    zero, noisy = demonstration("0"), demonstration("0.001:0.002")
    np.testing.assert_array_equal(zero.obs[:, _SITE], zero.achieved_goal)
    np.testing.assert_array_equal(noisy.achieved_goal, zero.achieved_goal)
    np.testing.assert_array_equal(noisy.action, zero.action)
    assert np.all(np.abs(noisy.obs[:, _SITE] - noisy.achieved_goal).max(axis=1) > 0)
