"""``tissue-retract train``: train a policy on a task, by the default recipe or one of the paper's algorithms.

Without ``--algo`` the default recipe runs (:mod:`policies.recipe`: fast, both cores, early stopping);
``--robust`` runs it over the robustness sweep's ranges within a 10-minute budget; ``--algo`` picks
DDPG+HER, SQIL, DDPGBC, CoL or DEX, trained as the paper does.

Writes to ``--out``: ``policy.safetensors`` (the deterministic actor, for ``evaluate`` and ``deploy``),
``resume.safetensors`` (everything needed to continue: running the same command again resumes from
it), ``eval.csv`` (success rate per evaluation) and TensorBoard logs in ``tb/``. With ``--algo`` the
defaults are the seed paper's; ``--set FIELD=VALUE`` overrides any field of
:class:`policies.config.TrainConfig`.

``--blind`` (Tasks I-III) trains on what a robot without perception observes (``evaluate --blind``,
``deploy --site``): a site registered up to ``--registration-error-mm`` from the true one, a jaw-sensed
grasp and the estimated site, rewarded by the simulation's true distance to the goal (see
:mod:`hardware_if.client.registered_env`). Demonstrations and the evaluations in ``eval.csv`` see the same.

``--vary`` takes what ``robustness --vary`` takes, parsed by the same function
(:func:`sim.robustness.parse_vary`): every episode, the expert's demonstrations and the evaluations
included, draws its tissue, observation noise and latency from the ranges (:mod:`sim.randomization`), and
the magnitudes of the observation and action disturbances as a sweep's trial has them
(:mod:`sim.drawn_disturbances`), all from the episode's seed.
"""

from __future__ import annotations

import argparse
import atexit
import dataclasses
import functools
import json
import os
import shlex
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

import gymnasium as gym

from hardware_if.client.registered_env import RegisteredTask
from policies.budget import PREPARATION_SHARE
from policies.config import TrainConfig
from policies.recipe import DEFAULT_RECIPE, ROBUST_RECIPE, Recipe
from policies.registry import ensure_registered
from psm_control.errors import ConfigurationError
from sim.drawn_disturbances import DrawnDisturbanceWrapper
from sim.robustness import TrainingRanges, parse_vary, training_ranges
from tissue_retract.cli._blind import add_blind_arguments
from tissue_retract.cli._camera import add_perception_argument, load_perception
from tissue_retract.cli._checks import MAX_EPISODES, MAX_SEED, check_out_folder, float_in, int_in
from tissue_retract.cli._next import command as tissue_retract_command
from tissue_retract.cli._next import say_next
from tissue_retract.cli._sensing import add_force_sensing_argument

__all__ = ["add_arguments", "parse_overrides", "run", "task_wrapper"]

ALGOS = ("ddpg", "sqil", "ddpgbc", "col", "dex")


@dataclasses.dataclass(frozen=True)
class _PaperRun:
    """How the paper's algorithms run with ``--algo`` (the seed paper's numbers)."""

    demos: int = 100
    episodes: int = 1000
    eval_every: int = 50
    eval_episodes: int = 50


_PAPER_RUN = _PaperRun()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the subcommand to its parser."""
    parser.add_argument(
        "--task",
        required=True,
        help="Gymnasium id (TissueRetract-Lift-v0, TissueRetract-ToyReach-v0, ...) or a short name (lift, III)",
    )
    parser.add_argument(
        "--algo",
        choices=ALGOS,
        default=None,
        help=f"one of the paper's algorithms, trained as the paper does (default: the {DEFAULT_RECIPE.name!r} "
        f"recipe: {DEFAULT_RECIPE.config.algo} from {DEFAULT_RECIPE.demos} demonstrations, collecting in a worker "
        f"process, stopping at {100 * DEFAULT_RECIPE.stop_at_success:g} %% held-out success)",
    )
    for flag, low, what, note in (
        ("--demos", 0, "demonstration episodes", "; unused by ddpg"),
        ("--episodes", 1, "most training episodes", "; the recipe usually stops early"),
        ("--eval-every", 1, "evaluate and checkpoint every N episodes", ""),
        ("--eval-episodes", 1, "held-out episodes per evaluation", ""),
    ):
        name = flag[2:].replace("-", "_")
        parser.add_argument(
            flag,
            type=int_in(low, MAX_EPISODES),
            default=None,
            help=f"{what} (default: {getattr(DEFAULT_RECIPE, name)} for the recipe, "
            f"{getattr(_PAPER_RUN, name)} with --algo{note})",
        )
    parser.add_argument(
        "--robust",
        action="store_true",
        help=f"the {ROBUST_RECIPE.name!r} recipe: cloned from {ROBUST_RECIPE.demos} demonstrations over the "
        f"robustness sweep's ranges (default --vary {ROBUST_RECIPE.vary}) and scored on "
        f"{ROBUST_RECIPE.eval_episodes} randomized held-out episodes, within a {ROBUST_RECIPE.budget_s:g} s "
        "budget (default --budget-s); --episodes N trains on after the cloning; not with --algo",
    )
    parser.add_argument("--demos-file", type=Path, default=None, help="read demonstrations from this .npz")
    parser.add_argument("--seed", type=int_in(0, MAX_SEED), default=1, help=f"seed 0-{MAX_SEED} (default: 1)")
    parser.add_argument(
        "--out", type=Path, default=None, help="output directory (default: runs/TASK/ALGO-sSEED, RECIPE-sSEED)"
    )
    parser.add_argument(
        "--set", action="append", default=[], metavar="FIELD=VALUE", help="override a TrainConfig field (JSON value)"
    )
    add_blind_arguments(
        parser,
        blind_help="observe a registered site and a jaw-sensed grasp, rewarded by the true distance",
        default_mm=3.0,
        error_help="the largest registration error drawn per episode",
    )
    add_perception_argument(parser)
    parser.add_argument(
        "--budget-s",
        type=float_in(1.0, 1e7),
        default=None,
        help="wall-clock budget of the whole command [s]: stop in time for a last evaluation and keep the "
        "best evaluated policy as policy.safetensors (default: none; train all --episodes)",
    )
    parser.add_argument("--fresh", action="store_true", help="ignore an existing checkpoint in --out and start over")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--no-tensorboard", action="store_true", help="no TensorBoard logs")
    add_force_sensing_argument(parser)
    parser.add_argument(
        "--vary",
        default=None,
        help="train over these ranges, as robustness's --vary takes them (NAME=LOW:HIGH, NAME=LOW:HIGHx times "
        "nominal, NAME=VALUE; the same names): each episode draws its tissue, noise, latency and "
        "disturbances from them, the demonstrations' and evaluations' too, e.g. "
        "stiffness=0.3:3x,obs_noise=0:0.002,latency=0:3 (with --robust, --vary '' keeps the task's own ranges)",
    )


def parse_overrides(items: list[str]) -> dict[str, object]:
    """``FIELD=VALUE`` pairs as a dict; values are JSON (``64``, ``[64,64]``, ``false``) or plain strings."""
    out: dict[str, object] = {}
    for item in items:
        name, sep, raw = item.partition("=")
        if not sep or not name:
            raise ConfigurationError("--set", item, "FIELD=VALUE")
        try:
            value: object = json.loads(raw)
        except json.JSONDecodeError:
            value = raw
        out[name.strip().replace("-", "_")] = tuple(value) if isinstance(value, list) else value
    return out


def run(args: argparse.Namespace) -> int:
    """Train, print where the policy is, its last success rate and the throughput."""
    overrides = parse_overrides(args.set)
    known = {f.name for f in dataclasses.fields(TrainConfig)}
    for name in overrides:
        if name not in known or name == "algo":
            raise ConfigurationError(
                "--set", name, "a TrainConfig field other than algo: " + ", ".join(sorted(known - {"algo"}))
            )
    recipe = _recipe(args)
    if recipe is not None:
        config = dataclasses.replace(recipe.config, **overrides)  # type: ignore[arg-type]
    else:
        config = TrainConfig(algo=args.algo, **overrides)  # type: ignore[arg-type]
    defaults = _PAPER_RUN if recipe is None else recipe
    for name in ("demos", "episodes", "eval_every", "eval_episodes"):
        if getattr(args, name) is None:
            setattr(args, name, getattr(defaults, name))
    if recipe is not None and args.vary is None:
        args.vary = recipe.vary
    if recipe is not None and args.budget_s is None:
        args.budget_s = recipe.budget_s
    args.task = ensure_registered(args.task)
    run_name = args.algo if recipe is None else recipe.name
    out = args.out if args.out is not None else Path("runs") / args.task / f"{run_name}-s{args.seed}"
    wrapper = task_wrapper(args)  # a bad --vary is refused before anything is written
    from policies.trainer import POLICY_FILE, RESUME_FILE, RunSpec, train  # torch: once the arguments are good

    check_out_folder(out, (POLICY_FILE, RESUME_FILE, "eval.csv"), (args.demos_file,))
    command = shlex.join(["tissue-retract", *sys.argv[1:]]) if sys.argv[1:2] == ["train"] else _rebuild(args)
    spec = RunSpec(
        task_id=args.task,
        seed=args.seed,
        episodes=args.episodes,
        demos=args.demos,
        out_dir=out,
        eval_every=args.eval_every,
        eval_episodes=args.eval_episodes,
        demos_file=args.demos_file,
        command=command,
        resume=not args.fresh,
        progress=not args.no_progress,
        tensorboard=not args.no_tensorboard,
        env_wrapper=wrapper,
        observation=_observation(args),
        budget_s=args.budget_s,
        started_s=_command_started_s() if sys.argv[1:2] == ["train"] else None,  # else: called in-process
        overlap=recipe is not None and recipe.overlap,
        stop_at_success=None if recipe is None else recipe.stop_at_success,
        preparation_share=recipe.preparation_share if recipe is not None else PREPARATION_SHARE,
        lag_blind_demos=recipe is not None and recipe.lag_blind_demos,
    )
    if recipe is not None:
        print(
            f"recipe {recipe.name}: {config.algo}, {args.demos} demonstrations, "
            f"{'collecting in a worker process, ' if spec.overlap else ''}"
            f"stopping at {100 * recipe.stop_at_success:g} % on {args.eval_episodes} held-out episodes "
            f"(evaluated every {args.eval_every})" + (f"; every episode drawn over {args.vary}" if args.vary else "")
        )
    result = train(spec, config)
    if result.resumed_from:
        print(f"resumed from episode {result.resumed_from}")
    for episode, success in result.success_rates:
        print(f"episode {episode:6d}: success {100 * success:5.1f} %")
    if result.stopped_early:
        print(f"stopped at episode {result.policy_episode}: held-out success reached the recipe's target")
    demos_in_use = bool(result.demos_used) and config.uses_demos
    if args.demos and result.demos_used < args.demos and args.demos_file is None and config.uses_demos:
        print(f"demonstrations: {result.demos_used} of {args.demos} (the budget ended their collection)")
    if demos_in_use and result.pretrain_steps < config.pretrain_steps and not result.resumed_from:
        print(f"pretraining: {result.pretrain_steps} of {config.pretrain_steps} updates (the budget ended it)")
    for episode, ran in result.cut_evaluations:
        print(f"evaluation at episode {episode}: {ran} of {args.eval_episodes} episodes (the budget cut it short)")
    if args.budget_s is not None:
        over = result.elapsed_s - args.budget_s
        print(
            f"budget {args.budget_s:g} s: {result.elapsed_s:.1f} s used (demonstrations {result.demo_seconds:.1f} s, "
            f"training {result.train_seconds:.1f} s, {result.evaluations} evaluation(s) {result.eval_seconds:.1f} s)"
            + (f"; OVER by {over:.1f} s" if over > 0 else "")
        )
        print(
            f"best evaluated policy: episode {result.policy_episode}, success {100 * result.policy_success:.1f} % "
            f"on {dict(result.cut_evaluations).get(result.policy_episode, args.eval_episodes)} held-out episodes"
        )
    print(f"policy: {result.policy_path}")
    print(f"resume checkpoint: {result.resume_path}")
    if result.env_steps:
        update_share = result.update_seconds / result.train_seconds if result.train_seconds else 0.0
        print(
            f"throughput: {result.steps_per_second:.1f} env steps/s including gradient updates "
            f"({result.env_steps} steps in {result.train_seconds:.1f} s; updates {100 * update_share:.0f} % of it)"
        )
    if result.learning_steps:
        print(
            f"throughput once learning: {result.learning_steps_per_second:.1f} env steps/s "
            f"({result.learning_steps} steps after the random seed steps, evaluation excluded; "
            f"{result.learning_steps_per_cpu_second:.1f} per CPU-second of this process)"
        )
    sensing = ["--force-sensing", args.force_sensing] if args.force_sensing not in (None, "ideal") else []
    evaluate = ["evaluate", "--policy", str(result.policy_path), "--task", args.task, "--episodes", "100", *sensing]
    say_next(f"{tissue_retract_command(*evaluate)} (the policy on episodes it never saw)")
    if args.budget_s is not None and sys.argv[1:2] == ["train"]:
        _end_process_now(0)
    return 0


def _recipe(args: argparse.Namespace) -> Recipe | None:
    """The recipe the arguments ask for (None: one of the paper's algorithms, ``--algo``)."""
    if getattr(args, "robust", False):
        if args.algo is not None:
            raise ConfigurationError("--robust", args.algo, "either --robust (a recipe) or --algo, not both")
        return ROBUST_RECIPE
    return DEFAULT_RECIPE if args.algo is None else None


def task_wrapper(args: argparse.Namespace) -> Callable[[gym.Env[Any, Any]], gym.Env[Any, Any]] | None:
    """What the policy trains on (``train``'s parsed arguments): the force as ``--force-sensing`` senses it
    over ``--vary``'s ranges, the task as a robot without perception (``--blind``) or with the endoscope
    (``--perception``) sees it, and ``--vary``'s disturbances on what it sees and commands."""
    if args.blind and args.perception is not None:
        raise ConfigurationError("--perception", args.perception, "either --blind or --perception, not both")
    seen: Callable[[gym.Env[Any, Any]], gym.Env[Any, Any]] | None = None
    if args.perception is not None:
        load_perception(args.perception)  # refused here if it is not a model file
        from hardware_if.client.perceived_env import camera_task  # PyBullet's endoscope: only with --perception

        seen = functools.partial(camera_task, model=args.perception.partition(":")[2] or None, for_training=True)
    elif args.blind:
        registration_error_m = args.registration_error_mm / 1000.0
        seen = functools.partial(RegisteredTask, registration_error_m=registration_error_m, for_training=True)
    ranges = training_ranges(parse_vary(args.vary)) if args.vary else TrainingRanges({}, frozenset(), ())
    if args.force_sensing == "ideal" and not ranges.randomization and not ranges.disturbances:
        return seen
    return functools.partial(_sensed_task, args.force_sensing, ranges, seen)


def _observation(args: argparse.Namespace) -> str:
    """What the policy observes, for the checkpoint's metadata."""
    if args.perception is not None:
        seen = f"perception {args.perception}"
    else:
        seen = f"blind, registration error up to {args.registration_error_mm:g} mm" if args.blind else "task"
    sensed = "" if args.force_sensing == "ideal" else f", {args.force_sensing} force sensing"
    return seen + sensed + (f", randomized over {args.vary}" if args.vary else "")


def _sensed_task(
    sensing: str,
    ranges: TrainingRanges,
    seen: Callable[[gym.Env[Any, Any]], gym.Env[Any, Any]] | None,
    env: gym.Env[Any, Any],
) -> gym.Env[Any, Any]:
    """The task with its ranges and force sensing set, as ``seen`` observes it, disturbed as a sweep's trial
    is (outermost, as the sweep wraps it; it pickles)."""
    if ranges.randomization:
        env.unwrapped.use_randomization(ranges.randomization, ranges.log_uniform)  # type: ignore[attr-defined]
    env.unwrapped.use_force_sensing(sensing)  # type: ignore[attr-defined]
    observed = env if seen is None else seen(env)
    return DrawnDisturbanceWrapper(observed, ranges.disturbances) if ranges.disturbances else observed


def _rebuild(args: argparse.Namespace) -> str:
    parts = ["tissue-retract", "train", "--task", args.task]
    if args.algo is not None:
        parts += ["--algo", args.algo]
    if getattr(args, "robust", False):
        parts += ["--robust"]
    parts += ["--demos", str(args.demos)]
    parts += ["--seed", str(args.seed), "--episodes", str(args.episodes)]
    if args.out is not None:
        parts += ["--out", str(args.out)]
    for item in args.set:
        parts += ["--set", item]
    if args.blind:
        parts += ["--blind", "--registration-error-mm", f"{args.registration_error_mm:g}"]
    if args.force_sensing != "ideal":
        parts += ["--force-sensing", args.force_sensing]
    if args.vary or (args.vary == "" and getattr(args, "robust", False)):
        parts += ["--vary", args.vary]  # an empty --vary is what keeps --robust on the task's own ranges
    if args.perception is not None:
        parts += ["--perception", args.perception]
    if args.budget_s is not None:
        parts += ["--budget-s", f"{args.budget_s:g}"]
    return shlex.join(parts)


def _end_process_now(code: int) -> NoReturn:
    """End the process without tearing its modules down, once everything is written and printed.

    The exit handlers run (temporary folders are removed) and the output is flushed; what is skipped is
    the interpreter's teardown of torch, Numba and PyBullet, which took 3 s on the loaded 2-core machine
    (0.1 s without it), outside any budget.
    """
    sys.stdout.flush()
    sys.stderr.flush()
    atexit._run_exitfuncs()
    os._exit(code)


def _command_started_s() -> float:
    """When this process started, on the ``time.monotonic()`` clock (Linux's ``/proc``); elsewhere: now.

    ``--budget-s`` covers the whole command, the interpreter's start and the imports included.
    """
    try:
        after_name = Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()
        started_ticks = int(after_name[19])  # field 22 of proc(5), the start time after boot [clock ticks]
        age_s = time.clock_gettime(time.CLOCK_BOOTTIME) - started_ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, AttributeError):
        return time.monotonic()
    return time.monotonic() - max(age_s, 0.0)
