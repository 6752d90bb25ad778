"""``tissue-retract bench train``: the default recipe's wall time to a policy confirmed on unseen episodes.

For each task and seed it runs ``tissue-retract train --task T --seed S`` (the default recipe, no
``--algo``) as a process of its own, timed from outside: the interpreter's start, the imports, the
demonstrations, training and its evaluations all count. Then it scores the policy that run kept on
``--confirm-episodes`` episodes that neither training nor its evaluations saw. A run whose policy scores
below ``--target`` has not reached it, whatever its time. Per task it prints each run and the median
over the seeds (not reached counts as slower than any time).

With ``--robust`` it times ``train --robust`` (within the recipe's own budget unless ``--budget-s`` is
given) and confirms on the robustness sweep the recipe trains over: ``robustness --policy POLICY
--beside-expert --force-sensing ideal`` with the recipe's ``--vary``, ``--confirm-episodes`` trials from
sweep seed :data:`CONFIRM_SWEEP_SEED` (trials no training or evaluation episode shares). A run reaches the
target when its policy's success is at most ``--below-expert`` under the scripted expert's on the same
trials. The expert's episodes do not depend on the policy, so a task's later seeds resume them from its
first seed's sweep instead of running them again.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from policies.recipe import ROBUST_RECIPE
from sim.registration import gym_id
from sim.strict_json import write_strict_json
from sim.sweep.stopping import ChildProcesses
from tissue_retract.cli._checks import MAX_EPISODES, check_out_folder, float_in, int_in

__all__ = ["add_arguments", "run"]

#: The confirmation episodes' seeds start here: far from training's (seed x 1,000,003 + episode), its
#: evaluations' (1,000,000,007 + i) and the demonstrations' (500,000,003 + 1,000 x seed + i).
CONFIRM_SEED = 3_000_000_019
#: ``--robust``'s confirmation sweep seed: trial i runs seed 1,000,003,000 + i, apart from the same seeds.
CONFIRM_SWEEP_SEED = 1000
TASKS = ("lift", "target", "multisite")
#: The scripted expert's episodes in a ``robustness --beside-expert`` folder.
EXPERT_EPISODES = "expert_episodes.jsonl"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the train target."""
    parser.add_argument("--tasks", nargs="+", default=list(TASKS), help="tasks (default: Tasks I-III)")
    parser.add_argument(
        "--seeds", type=int_in(0, 10_000), nargs="+", default=[1, 2, 3], help="training seeds (default: 1 2 3)"
    )
    parser.add_argument(
        "--confirm-episodes",
        type=int_in(1, MAX_EPISODES),
        default=100,
        help="unseen episodes that confirm a policy (default: 100)",
    )
    parser.add_argument(
        "--target", type=float_in(0.0, 1.0), default=0.95, help="success a policy must confirm (default: 0.95)"
    )
    parser.add_argument(
        "--budget-s",
        type=float_in(10.0, 1e5),
        default=None,
        help="each training run's --budget-s, so that no run goes on for ever (default: 300; with --robust "
        f"the recipe's {ROBUST_RECIPE.budget_s:g})",
    )
    parser.add_argument(
        "--robust",
        action="store_true",
        help="time train --robust and confirm on the robustness sweep it trains over, beside the scripted expert",
    )
    parser.add_argument(
        "--below-expert",
        type=float_in(0.0, 1.0),
        default=0.08,
        help="with --robust: how far under the expert's sweep success a policy may confirm (default: 0.08)",
    )
    parser.add_argument(
        "--out", type=Path, default=Path("runs/bench-train"), help="runs' folders (default: runs/bench-train)"
    )


def run(args: argparse.Namespace) -> int:
    """Train, confirm, print."""
    tasks = [gym_id(task) for task in args.tasks]
    if args.budget_s is None:
        args.budget_s = ROBUST_RECIPE.budget_s if args.robust else 300.0
    check_out_folder(args.out, (), ())
    rows: list[dict[str, Any]] = []
    with ChildProcesses("bench train") as children:
        for task in tasks:
            for seed in args.seeds:
                rows.append(_train_and_confirm(task, seed, args, children))
                row = rows[-1]
                print(
                    f"{task} seed {seed}: {row['wall_s']:.1f} s, kept episode {row['policy_episode']}, "
                    + _confirmed(row, args)
                )
    summary = {task: _summary([r for r in rows if r["task"] == task]) for task in tasks}
    print()
    print(f"{'task':28s} {'median to a confirmed policy':>30s}   runs (s; * not reached)")
    for task, s in summary.items():
        runs = ", ".join(f"{r['wall_s']:.1f}" + ("" if r["reached"] else "*") for r in rows if r["task"] == task)
        median = "not reached" if math.isinf(s["median_s"]) else f"{s['median_s']:.1f} s"
        print(f"{task:28s} {median:>30s}   {runs}")
    if args.json:
        for s in summary.values():  # JSON has no infinity
            s["median_s"] = None if math.isinf(s["median_s"]) else s["median_s"]
        target = {"below_expert": args.below_expert} if args.robust else args.target
        document = {"runs": rows, "summary": summary, "target": target, "robust": args.robust}
        write_strict_json(Path(args.json), document, field="--json")
    return 0


def _confirmed(row: dict[str, Any], args: argparse.Namespace) -> str:
    """What the confirmation showed, and whether it reached the target."""
    success = 100 * row["confirmed_success"]
    if not args.robust:
        return f"confirmed {success:.0f} % on {args.confirm_episodes} unseen episodes" + (
            "" if row["reached"] else f" (below {100 * args.target:g} %: not reached)"
        )
    expert = 100 * row["expert_success"]
    return f"confirmed {success:.1f} % on {args.confirm_episodes} sweep trials, the expert {expert:.1f} %" + (
        "" if row["reached"] else f" (more than {100 * args.below_expert:g} points below it: not reached)"
    )


def _train_and_confirm(task: str, seed: int, args: argparse.Namespace, children: ChildProcesses) -> dict[str, Any]:
    out = Path(args.out) / task / f"s{seed}"
    out.mkdir(parents=True, exist_ok=True)
    shutil.rmtree(out / "sweep", ignore_errors=True)  # an earlier bench's confirmation, of another policy
    command = [sys.executable, "-m", "tissue_retract", "train", "--task", task, "--seed", str(seed)]
    command += ["--robust"] if args.robust else []
    command += ["--out", str(out), "--fresh", "--no-progress", "--no-tensorboard", "--budget-s", f"{args.budget_s:g}"]
    with (out / "train.log").open("w") as log:
        start = time.perf_counter()
        status = children.run("train", command, stdout=log, stderr=subprocess.STDOUT).returncode
        wall_s = time.perf_counter() - start
    row: dict[str, Any] = {"task": task, "seed": seed, "wall_s": wall_s, "exit_status": status}
    policy = out / "policy.safetensors"
    if args.robust:
        success, expert = _confirm_on_sweep(task, seed, args, children) if status == 0 else (0.0, math.nan)
        row["expert_success"] = expert
        reached = success >= expert - args.below_expert
    else:
        success = _confirm(task, policy, args.confirm_episodes) if status == 0 else 0.0
        reached = success >= args.target
    row["policy_episode"] = _kept_episode(policy) if status == 0 else 0
    row["confirmed_success"] = success
    row["reached"] = status == 0 and reached
    row["log"] = str(out / "train.log")
    return row


def _confirm_on_sweep(task: str, seed: int, args: argparse.Namespace, children: ChildProcesses) -> tuple[float, float]:
    """The kept policy's and the scripted expert's success on the robustness sweep the recipe trains over."""
    task_folder = Path(args.out) / task
    out = task_folder / f"s{seed}" / "sweep"
    out.mkdir(parents=True, exist_ok=True)
    first = task_folder / f"s{args.seeds[0]}" / "sweep" / EXPERT_EPISODES
    if seed != args.seeds[0] and first.is_file():
        shutil.copyfile(first, out / EXPERT_EPISODES)  # the same trials: resumed, not run again
    policy = task_folder / f"s{seed}" / "policy.safetensors"
    command = [sys.executable, "-m", "tissue_retract", "robustness", "--policy", str(policy), "--task", task]
    command += ["--trials", str(args.confirm_episodes), "--seed", str(CONFIRM_SWEEP_SEED)]
    command += ["--vary", str(ROBUST_RECIPE.vary), "--force-sensing", "ideal", "--beside-expert", "--no-progress"]
    command += ["--out", str(out)]
    with (out.parent / "sweep.log").open("w") as log:
        children.run("robustness", command, stdout=log, stderr=subprocess.STDOUT)
    summary = json.loads((out / "summary.json").read_text())  # written even when some episodes failed
    return float(summary["success_rate"]), float(summary["expert_success"])


def _kept_episode(policy: Path) -> int:
    """The training episode the run kept its policy at."""
    from policies.checkpoint import load_checkpoint

    return int(load_checkpoint(policy).meta["progress"]["episodes"])


def _confirm(task: str, policy: Path, episodes: int) -> float:
    """Success of the kept policy on unseen episodes."""
    from policies.resolve import resolve_policy
    from sim.envs import make
    from sim.evaluation import run_episode

    env = make(task)
    try:
        act, reset = resolve_policy(str(policy), env)
        results = [run_episode(env, act, reset, CONFIRM_SEED + i) for i in range(episodes)]
    finally:
        env.close()
    return sum(r.success for r in results) / episodes


def _summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The median over the runs (a run that did not reach the target is slower than any that did)."""
    times = [r["wall_s"] if r["reached"] else math.inf for r in rows]
    return {
        "median_s": statistics.median(times),
        "reached": sum(r["reached"] for r in rows),
        "runs": len(rows),
        "confirmed_success": [r["confirmed_success"] for r in rows],
    }
