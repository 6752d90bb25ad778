"""The training loop behind ``tissue-retract train``: collect, learn, evaluate, checkpoint, resume.

One episode at a time: the first ``random_steps`` env steps take uniformly random actions, later ones
the agent's exploratory actions; each finished episode goes to the HER buffer and the normalisers, then
``updates_per_episode`` gradient updates run with all their batches sampled at once. Every
``eval_every`` episodes the deterministic actor is scored on a fixed set of evaluation episodes
(success at the final step, as in the paper), logged to TensorBoard and ``eval.csv``, and a resumable
checkpoint is written atomically. Training episodes are seeded from (seed, episode index), so a run
resumed from its checkpoint sees the same episodes it would have seen.

With ``RunSpec.overlap`` the episodes run in a worker process and the same number of updates per episode
is spread over its steps, each running while the worker simulates (:mod:`policies.collect`): both cores
work. Without it (the paper's algorithms as ``reproduce`` runs them) collection and learning alternate.

With a wall-clock budget (``train --budget-s``) the run stops collecting when the next episode and a last
evaluation would no longer fit, evaluates, and ``policy.safetensors`` is the best policy of its
evaluations rather than the last one; the resume checkpoint is always the latest state.
"""

from __future__ import annotations

import csv
import functools
import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch.utils.tensorboard import SummaryWriter
from tqdm import tqdm

from policies.algos import Agent, Dims, make_agent
from policies.budget import PREPARATION_SHARE, Budget
from policies.buffers import Episode, EpisodeBuffer, RewardFn
from policies.checkpoint import (
    check_spaces,
    env_spaces,
    load_agent,
    load_checkpoint,
    save_checkpoint,
)
from policies.collect import Collector, OverlappedCollector, SerialCollector, can_run_in_worker
from policies.config import TrainConfig
from policies.demos import collect_demos, default_attempts, expert_for, load_demos, rollout
from policies.errors import CheckpointError, TrainingDivergedError
from policies.registry import ensure_registered
from psm_control.errors import ConfigurationError

__all__ = ["POLICY_FILE", "RESUME_FILE", "RunSpec", "TrainResult", "ensure_registered", "evaluate", "train"]

RESUME_FILE = "resume.safetensors"
POLICY_FILE = "policy.safetensors"
_EVAL_SEED = 1_000_000_007
_DEMO_SEED = 500_000_003


@dataclass(frozen=True)
class RunSpec:
    """What to train, for how long, and where to write.

    Attributes:
        task_id: Gymnasium id of the goal task.
        seed: Seed of the run (networks, exploration, episodes).
        episodes: Training episodes (0: the demonstrations and pretraining alone, evaluated once when the
            run stops at a target).
        demos: Demonstration episodes (ignored by DDPG).
        out_dir: Directory of checkpoints, TensorBoard logs and ``eval.csv``.
        eval_every: Evaluate and checkpoint every this many episodes (and at the end).
        eval_episodes: Evaluation episodes per evaluation.
        demos_file: Read demonstrations from this ``.npz`` instead of running the expert.
        command: The exact command line, recorded in checkpoints.
        resume: Continue from ``out_dir``'s checkpoint when there is one.
        progress: Show a progress bar.
        tensorboard: Write TensorBoard logs.
        env_wrapper: Wraps the task for training and its evaluations (e.g. what a robot without
            perception observes, ``train --blind``); ``None`` trains on the task as it is.
        observation: Names what the policy observes (``task`` without a wrapper); recorded in the
            checkpoints, and a run resumes only with the same.
        budget_s: Wall-clock budget of the whole run [s] (see the module notes); None: no budget.
        started_s: When the budget started, on ``time.monotonic()`` (the command's start); None: when
            :func:`train` is called.
        overlap: Collect in a worker process, the updates running while the task simulates
            (:mod:`policies.collect`); False collects and then learns, in this process, as the paper's code.
        stop_at_success: End the run at the first evaluation with at least this success rate; its
            policy is ``policy.safetensors``. None: train all ``episodes``.
        preparation_share: Under a budget, the share of it that demonstrations and pretraining may take.
        lag_blind_demos: Demonstrations from the expert moving without knowing the actions still in flight
            (:class:`sim.expert.ScriptedExpert`'s ``lag_blind``).
    """

    task_id: str
    seed: int = 1
    episodes: int = 1000
    demos: int = 100
    out_dir: Path = Path("runs/train")
    eval_every: int = 50
    eval_episodes: int = 50
    demos_file: Path | None = None
    command: str = ""
    resume: bool = True
    progress: bool = True
    tensorboard: bool = True
    env_wrapper: Callable[[gym.Env[Any, Any]], gym.Env[Any, Any]] | None = None
    observation: str = "task"
    budget_s: float | None = None
    started_s: float | None = None
    overlap: bool = False
    stop_at_success: float | None = None
    preparation_share: float = PREPARATION_SHARE
    lag_blind_demos: bool = False

    def __post_init__(self) -> None:
        for name, low in (("seed", 0), ("episodes", 0), ("demos", 0), ("eval_every", 1), ("eval_episodes", 1)):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < low:
                raise ConfigurationError(name, value, f"an integer >= {low}")
        if self.budget_s is not None and not (isinstance(self.budget_s, int | float) and 1.0 <= self.budget_s < 1e7):
            raise ConfigurationError("budget_s", self.budget_s, "a number of seconds from 1 to 1e7")
        target = self.stop_at_success
        if target is not None and (
            isinstance(target, bool) or not (isinstance(target, int | float) and 0 < target <= 1)
        ):
            raise ConfigurationError("stop_at_success", self.stop_at_success, "a success rate in (0, 1]")
        share = self.preparation_share
        if isinstance(share, bool) or not (isinstance(share, int | float) and 0.0 < share <= 1.0):
            raise ConfigurationError("preparation_share", share, "a share of the budget in (0, 1]")


@dataclass
class TrainResult:
    """What a run produced."""

    policy_path: Path
    resume_path: Path
    success_rates: list[tuple[int, float]] = field(default_factory=list)
    env_steps: int = 0
    train_seconds: float = 0.0
    update_seconds: float = 0.0
    learning_steps: int = 0
    learning_seconds: float = 0.0
    learning_cpu_seconds: float = 0.0
    resumed_from: int = 0
    demo_seconds: float = 0.0
    eval_seconds: float = 0.0
    elapsed_s: float = 0.0
    policy_episode: int = 0
    policy_success: float = float("nan")
    stopped_early: bool = False
    demos_used: int = 0
    pretrain_steps: int = 0
    #: (episode, evaluation episodes run) of each evaluation the budget cut short.
    cut_evaluations: list[tuple[int, int]] = field(default_factory=list)

    @property
    def steps_per_second(self) -> float:
        """Env steps per second of training, gradient updates included (evaluation excluded)."""
        return self.env_steps / self.train_seconds if self.train_seconds > 0 else float("nan")

    @property
    def learning_steps_per_second(self) -> float:
        """Env steps per second once gradient updates run (after the random seed steps)."""
        return self.learning_steps / self.learning_seconds if self.learning_seconds > 0 else float("nan")

    @property
    def learning_steps_per_cpu_second(self) -> float:
        """Env steps per second of this process's CPU time once learning: the rate on an idle core."""
        return self.learning_steps / self.learning_cpu_seconds if self.learning_cpu_seconds > 0 else float("nan")

    @property
    def evaluations(self) -> int:
        """Evaluations run."""
        return len(self.success_rates)

    @property
    def final_success(self) -> float:
        """Success rate of the last evaluation."""
        return self.success_rates[-1][1] if self.success_rates else float("nan")


def evaluate(
    agent: Agent, env: gym.Env[Any, Any], episodes: int, out_of_time: Callable[[], bool] | None = None
) -> tuple[float, int]:
    """Success rate of the deterministic actor over fixed evaluation episodes (success at the final step).

    Returns:
        The success rate and the episodes it is over: all ``episodes``, or fewer (at least one) when
        ``out_of_time()`` said so before an episode.
    """
    successes, ran = 0, 0
    for i in range(episodes):
        if ran and out_of_time is not None and out_of_time():
            break
        _, success = rollout(env, lambda o: agent.act(o["observation"], o["desired_goal"]), seed=_EVAL_SEED + i)
        successes += success
        ran += 1
    return successes / ran, ran


#: Demonstrations collected between two looks at the budget (and between this process and the worker).
DEMO_CHUNK = 10
#: Pretraining updates between two looks at the budget.
PRETRAIN_CHUNK = 100


def _demonstrations(
    spec: RunSpec,
    env: gym.Env[Any, Any],
    dims: Dims,
    collector: Collector,
    budget: Budget | None = None,
    on_success: Callable[[int], None] | None = None,
    pretraining_s: Callable[[list[Episode]], float] | None = None,
) -> list[Episode]:
    """The run's demonstrations: from its file, or from the task's expert (half of them in the collecting
    worker, if there is one, seeded after every seed the other half may try).

    Under a budget they are collected in chunks of :data:`DEMO_CHUNK` (alternately here and in the worker),
    and collection stops, with fewer than asked, once the rest of the preparation's share of the budget
    (``RunSpec.preparation_share``) is what the pretraining after them needs: ``pretraining_s(episodes)``,
    the pretraining's wall time timed on the first chunk. ``on_success(n)`` reports ``n`` more
    demonstrations collected.
    """
    if spec.demos == 0:
        return []
    if spec.demos_file is not None:
        return load_demos(spec.demos_file, spec.demos, dims=(dims.obs, dims.goal, dims.action))
    seed = _DEMO_SEED + 1000 * spec.seed
    tick = (lambda: on_success(1)) if on_success is not None else None
    worker = collector if isinstance(collector, OverlappedCollector) else None
    if budget is not None and budget.budget_s is not None:
        return _budgeted_demonstrations(spec, env, worker, budget, seed, on_success, pretraining_s)
    expert = expert_for(spec.task_id, lag_blind=spec.lag_blind_demos)
    if worker is None or spec.demos < 2:
        return collect_demos(env, expert, spec.demos, seed=seed, on_success=tick)
    here = spec.demos // 2
    worker.start_demonstrations(spec.demos - here, seed + default_attempts(here), spec.lag_blind_demos)
    episodes = collect_demos(env, expert, here, seed=seed, on_success=tick)
    there = worker.finish_demonstrations()
    if on_success is not None:
        on_success(len(there))
    return episodes + there


def _budgeted_demonstrations(
    spec: RunSpec,
    env: gym.Env[Any, Any],
    worker: OverlappedCollector | None,
    budget: Budget,
    seed: int,
    on_success: Callable[[int], None] | None,
    pretraining_s: Callable[[list[Episode]], float] | None,
) -> list[Episode]:
    """Demonstrations in chunks (chunk k from seed ``seed + k * attempts``), until done or out of time.

    Without room kept for the pretraining, demonstrations that fill the preparation's share leave a policy
    pretrained for a few updates, or none (0 % held out, with 1,620 of 2,000 asked on the camera's MultiSite).
    """
    sizes = [min(DEMO_CHUNK, spec.demos - start) for start in range(0, spec.demos, DEMO_CHUNK)]
    seeds = [seed + k * default_attempts(DEMO_CHUNK) for k in range(len(sizes))]
    tick = (lambda: on_success(1)) if on_success is not None else None
    horizon = int(env.spec.max_episode_steps or 50) if env.spec is not None else 50
    expert = expert_for(spec.task_id, lag_blind=spec.lag_blind_demos)
    episodes: list[Episode] = []
    k = 0
    while k < len(sizes) and budget.demonstrations_fit():
        started = time.monotonic()
        shared = worker is not None and k + 1 < len(sizes)
        if shared and worker is not None:
            worker.start_demonstrations(sizes[k + 1], seeds[k + 1], spec.lag_blind_demos)
        episodes += collect_demos(env, expert, sizes[k], seed=seeds[k], on_success=tick)
        if shared and worker is not None:
            there = worker.finish_demonstrations()
            episodes += there
            if on_success is not None:
                on_success(len(there))
        budget.step_s = (time.monotonic() - started) / (sizes[k] * horizon)
        if k == 0 and pretraining_s is not None and episodes:
            budget.pretraining_s = pretraining_s(episodes)
        k += 2 if shared else 1
    return episodes


def _pretraining_s(dims: Dims, config: TrainConfig, reward_fn: RewardFn, horizon: int, demos: list[Episode]) -> float:
    """What ``config.pretrain_steps`` pretraining updates will take [s]: a second chunk of
    :data:`PRETRAIN_CHUNK` on a throwaway agent over ``demos`` (the first warms up), scaled up. An update's
    cost is its batch's, not the demonstrations' number."""
    agent, buffer = make_agent(dims, config), _demo_buffer(demos, dims, horizon)
    for episode in demos:
        agent.observe_episode(episode.obs, episode.achieved_goal, episode.desired_goal)
    agent.pretrain(buffer, reward_fn, PRETRAIN_CHUNK)
    started = time.monotonic()
    agent.pretrain(buffer, reward_fn, PRETRAIN_CHUNK)
    return (time.monotonic() - started) * config.pretrain_steps / PRETRAIN_CHUNK


def _demo_buffer(demos: list[Episode], dims: Dims, horizon: int) -> EpisodeBuffer:
    """A buffer holding exactly ``demos``."""
    buffer = EpisodeBuffer(len(demos) * horizon, horizon, dims.obs, dims.goal, dims.action)
    for episode in demos:
        buffer.add(episode)
    return buffer


class _Logger:
    """TensorBoard scalars and the evaluation CSV."""

    def __init__(self, out_dir: Path, tensorboard: bool) -> None:
        self.csv_path = out_dir / "eval.csv"
        self.csv_file = self.csv_path.open("a", newline="")
        self.csv = csv.writer(self.csv_file)
        # Also when the file is there but empty: a run stopped before its first evaluation leaves it so.
        if self.csv_file.tell() == 0:
            self.csv.writerow(["episode", "env_steps", "updates", "success_rate", "train_steps_per_s"])
            self.csv_file.flush()
        self.writer: Any = None
        if tensorboard:
            self.writer = SummaryWriter(str(out_dir / "tb"))

    def scalars(self, values: dict[str, float], step: int) -> None:
        if self.writer is not None:
            for key, value in values.items():
                self.writer.add_scalar(key, value, step)

    def evaluation(self, episode: int, env_steps: int, updates: int, success: float, speed: float) -> None:
        self.csv.writerow([episode, env_steps, updates, f"{success:.4f}", f"{speed:.1f}"])
        self.csv_file.flush()
        self.scalars({"eval/success_rate": success, "train/env_steps_per_s": speed}, env_steps)

    def close(self) -> None:
        self.csv_file.close()
        if self.writer is not None:
            self.writer.close()


def train(spec: RunSpec, config: TrainConfig) -> TrainResult:
    """Train ``config.algo`` on ``spec.task_id``; returns where the policy is and how the run went.

    Sets this process's torch to one thread: for networks this small that is fastest, and it keeps
    parallel runs (``policies.reproduce``) from oversubscribing the cores.
    """
    started = spec.started_s if spec.started_s is not None else time.monotonic()
    torch.set_num_threads(1)
    task_id = ensure_registered(spec.task_id)
    if spec.overlap and not can_run_in_worker(spec.env_wrapper):
        raise ConfigurationError("env_wrapper", spec.env_wrapper, "a picklable wrapper to collect in a worker")
    env, eval_env = gym.make(task_id), gym.make(task_id)
    if spec.env_wrapper is not None:
        env, eval_env = spec.env_wrapper(env), spec.env_wrapper(eval_env)
    collector = OverlappedCollector(task_id, spec.env_wrapper) if spec.overlap else SerialCollector(env)
    try:
        budget = Budget(spec.budget_s, started, preparation_share=spec.preparation_share)
        return _train(spec, config, env, eval_env, collector, budget)
    finally:
        collector.close()
        env.close()
        eval_env.close()


def _train(
    spec: RunSpec,
    config: TrainConfig,
    env: gym.Env[Any, Any],
    eval_env: gym.Env[Any, Any],
    collector: Collector,
    budget: Budget,
) -> TrainResult:
    spaces = env_spaces(env)
    dims = Dims(
        int(np.prod(spaces["observation"])),
        int(np.prod(spaces["desired_goal"])),
        int(np.prod(spaces["action"]["shape"])),
    )
    horizon = int(env.spec.max_episode_steps or 50) if env.spec is not None else 50
    reward_fn: RewardFn = env.unwrapped.compute_reward  # type: ignore[attr-defined]
    out = Path(spec.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    resume_path, policy_path = out / RESUME_FILE, out / POLICY_FILE

    buffer = EpisodeBuffer(config.buffer_size, horizon, dims.obs, dims.goal, dims.action)
    demo_start = time.monotonic()
    demos: list[Episode] = []
    if config.uses_demos:
        demo_bar = tqdm(total=spec.demos, desc="demonstrations", unit="ep") if spec.progress and spec.demos else None
        try:
            timed = (
                functools.partial(_pretraining_s, dims, config, reward_fn, horizon) if config.pretrain_steps else None
            )
            demos = _demonstrations(spec, env, dims, collector, budget, demo_bar.update if demo_bar else None, timed)
        finally:
            if demo_bar is not None:
                demo_bar.close()
    demo_buffer = _demo_buffer(demos, dims, horizon) if demos else None

    start_episode, env_steps, pretrained = 0, 0, 0
    if spec.resume and resume_path.exists():
        agent, start_episode, env_steps = _resume(resume_path, spec, config, env, buffer)
    else:
        agent = make_agent(dims, config, spec.seed)
        for episode in demos:
            agent.observe_episode(episode.obs, episode.achieved_goal, episode.desired_goal)
        while demo_buffer is not None and pretrained < config.pretrain_steps:
            if not budget.preparing_fits():
                break
            steps = min(PRETRAIN_CHUNK, config.pretrain_steps - pretrained)
            agent.pretrain(demo_buffer, reward_fn, steps)
            pretrained += steps

    result = TrainResult(policy_path, resume_path, resumed_from=start_episode)
    result.demos_used, result.pretrain_steps = len(demos), pretrained
    result.demo_seconds = time.monotonic() - demo_start
    logger = _Logger(out, spec.tensorboard)
    bar = None
    if spec.progress:
        bar = tqdm(total=spec.episodes, initial=start_episode, desc=f"{config.algo} {spec.task_id}", unit="ep")

    def checkpoint(episode: int, policy: bool = True) -> None:
        progress = {"episodes": episode, "env_steps": env_steps, "updates": agent.updates}
        common: dict[str, Any] = {
            "task_id": spec.task_id,
            "spaces": spaces,
            "command": spec.command,
            "observation": spec.observation,
        }
        save_checkpoint(
            resume_path, agent, progress=progress, training=True, arrays=_prefixed("replay", buffer.state()),
            rng={"agent": agent.rng.bit_generator.state, "seed": spec.seed}, **common,
        )  # fmt: skip
        if policy:
            save_checkpoint(policy_path, agent, progress=progress, **common)

    metrics: dict[str, float] = {}

    def evaluation(episode: int) -> None:
        """Score the actor, log it, checkpoint; under a budget the policy file keeps the best evaluation."""
        start = time.monotonic()
        success, ran = evaluate(agent, eval_env, spec.eval_episodes, budget.out_of_time)
        if ran < spec.eval_episodes:
            result.cut_evaluations.append((episode, ran))
        result.success_rates.append((episode, success))
        logger.evaluation(episode, env_steps, agent.updates, success, result.steps_per_second)
        logger.scalars({f"train/{k}": v for k, v in metrics.items()}, env_steps)
        keeps_best = budget.budget_s is not None or spec.stop_at_success is not None
        best = not keeps_best or not success < result.policy_success  # the first one: NaN
        checkpoint(episode, policy=best)
        if best:
            result.policy_episode, result.policy_success = episode, success
        budget.evaluation_s = time.monotonic() - start
        result.eval_seconds += budget.evaluation_s
        if bar is not None:
            speed = result.steps_per_second
            bar.set_postfix(success=f"{success:.2f}", **({"steps_s": f"{speed:.0f}"} if np.isfinite(speed) else {}))

    def act_from(first_step: int) -> Callable[[dict[str, np.ndarray]], np.ndarray]:
        """The episode's actions: uniformly random for the first ``random_steps`` of the run, then explored."""
        steps = itertools.count(first_step)

        def act(obs: dict[str, np.ndarray]) -> np.ndarray:
            if next(steps) < config.random_steps:
                return agent.rng.uniform(-1.0, 1.0, dims.action).astype(np.float32)
            return agent.explore(obs["observation"], obs["desired_goal"])

        return act

    def learn_from(first_step: int) -> Callable[[int], None]:
        """Updates while the episode simulates (overlapped collection): ``updates_per_episode`` spread over
        its steps, from the buffer as it was when the episode started. Serial collection learns after."""

        def learn(step: int) -> None:
            nonlocal metrics
            if not spec.overlap or step < 0 or first_step + step < config.random_steps:
                return
            count = (step + 1) * config.updates_per_episode // horizon - step * config.updates_per_episode // horizon
            if count > 0:
                start = time.perf_counter()
                metrics = agent.train(buffer, demo_buffer, reward_fn, count) or metrics
                result.update_seconds += time.perf_counter() - start

        return learn

    def reached(episode: int) -> bool:
        """Evaluate; True when the evaluation reaches ``stop_at_success`` (early stopping)."""
        evaluation(episode)
        cut = bool(result.cut_evaluations) and result.cut_evaluations[-1][0] == episode  # too few episodes to tell
        result.stopped_early = (
            spec.stop_at_success is not None and not cut and result.success_rates[-1][1] >= spec.stop_at_success
        )
        return result.stopped_early

    done = start_episode
    try:
        if spec.stop_at_success is not None and start_episode == 0 and demos:
            reached(0)  # what the demonstrations alone taught: enough already?
        for episode_index in range(start_episode, spec.episodes):
            if result.stopped_early or not budget.fits_episode(spec.eval_episodes, horizon):
                break
            t0, c0 = time.perf_counter(), time.process_time()
            seed = spec.seed * 1_000_003 + episode_index
            episode = collector.episode(seed, act_from(env_steps), learn_from(env_steps))
            env_steps += len(episode.action)
            buffer.add(episode)
            agent.observe_episode(episode.obs, episode.achieved_goal, episode.desired_goal)
            t1 = time.perf_counter()
            learning = env_steps >= config.random_steps
            if learning and not spec.overlap:
                metrics = agent.train(buffer, demo_buffer, reward_fn, config.updates_per_episode)
            if learning:
                _check_finite(agent, metrics, episode_index + 1, policy_path)
            t2 = time.perf_counter()
            if learning:
                result.learning_steps += len(episode.action)
                result.learning_seconds += t2 - t0
                result.learning_cpu_seconds += time.process_time() - c0
            result.train_seconds += t2 - t0
            result.update_seconds += t2 - t1
            result.env_steps += len(episode.action)
            budget.episode_s, budget.step_s = t2 - t0, (t1 - t0) / len(episode.action)
            done = episode_index + 1
            if bar is not None:
                bar.update(1)
            if (done % spec.eval_every == 0 or done == spec.episodes) and reached(done):
                break
        collector.close()  # no more training episodes: its worker's exit is not left for the end of the budget
        if start_episode >= spec.episodes:
            checkpoint(start_episode)
        elif (
            not result.stopped_early
            and budget.budget_s is not None
            and (not result.success_rates or result.success_rates[-1][0] != done)
        ):
            evaluation(done)  # the budget ended the run between two evaluations
    finally:
        if bar is not None:
            bar.close()
        logger.close()
    result.elapsed_s = budget.elapsed()
    return result


def _check_finite(agent: Agent, metrics: dict[str, float], episode: int, policy_path: Path) -> None:
    """Stop before a non-finite loss or weight reaches a checkpoint: the last good one stays as it is."""
    bad = next((f"loss {k}={v}" for k, v in metrics.items() if not np.isfinite(v)), None)
    if bad is None:
        for name, module in agent.modules().items():
            for key, value in module.state_dict().items():
                if value.is_floating_point() and not bool(torch.isfinite(value).all()):
                    bad = f"weight {name}.{key}"
                    break
            if bad is not None:
                break
    if bad is not None:
        kept = f"the last good policy is kept in {policy_path}" if policy_path.exists() else "no checkpoint was written"
        raise TrainingDivergedError(episode, bad, kept)


def _prefixed(prefix: str, arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {f"{prefix}.{k}": v for k, v in arrays.items()}


def _resume(
    path: Path, spec: RunSpec, config: TrainConfig, env: gym.Env[Any, Any], buffer: EpisodeBuffer
) -> tuple[Agent, int, int]:
    ckpt = load_checkpoint(path)
    meta = ckpt.meta
    if meta.get("kind") != "training":
        raise CheckpointError(path, "is not a training checkpoint and cannot be resumed")
    check_spaces(path, meta.get("spaces", {}), env)
    saved_seed = meta.get("rng", {}).get("seed")
    for name, saved, wanted in (
        ("task", meta.get("task_id"), spec.task_id),
        ("seed", saved_seed, spec.seed),
        ("config", meta.get("config"), config.to_dict()),
        ("observation", meta.get("observation", "task"), spec.observation),
    ):
        if saved != wanted:
            raise CheckpointError(
                path,
                f"was written by a run with a different {name} ({saved!r}, now {wanted!r}); "
                "pass --fresh to start over or choose another --out",
            )
    agent = load_agent(ckpt, spec.seed)
    agent.rng.bit_generator.state = meta["rng"]["agent"]
    torch.set_rng_state(ckpt.tensors["rng.torch"])
    buffer.load_state({k: v.numpy() for k, v in ckpt.group("replay").items()})
    progress = meta.get("progress", {})
    return agent, int(progress.get("episodes", 0)), int(progress.get("env_steps", 0))
