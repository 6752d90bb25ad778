"""``tissue-retract bench train``: the default recipe's wall time to a policy confirmed on unseen episodes.

For each task and seed it runs ``tissue-retract train --task T --seed S`` (the default recipe, no
``--algo``) as a process of its own, timed from outside: the interpreter's start, the imports, the
demonstrations, training and its evaluations all count. Then it scores the policy that run kept on
``--confirm-episodes`` episodes that neither training nor its evaluations saw. A run whose policy scores
below ``--target`` has not reached it, whatever its time. Per task it prints each run and the median
over the seeds (not reached counts as slower than any time).
"""

from __future__ import annotations

import argparse
import math
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from sim.strict_json import write_strict_json
from tissue_retract.cli._checks import MAX_EPISODES, check_out_folder, float_in, int_in

__all__ = ["add_arguments", "run"]

#: The confirmation episodes' seeds start here: far from training's (seed x 1,000,003 + episode), its
#: evaluations' (1,000,000,007 + i) and the demonstrations' (500,000,003 + 1,000 x seed + i).
CONFIRM_SEED = 3_000_000_019
TASKS = ("lift", "target", "multisite")


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
        default=300.0,
        help="each training run's --budget-s, so that no run goes on for ever (default: 300)",
    )
    parser.add_argument(
        "--out", type=Path, default=Path("runs/bench-train"), help="runs' folders (default: runs/bench-train)"
    )


def run(args: argparse.Namespace) -> int:
    """Train, confirm, print."""
    from sim.envs import gym_id  # the simulation, after the arguments are known good

    tasks = [gym_id(task) for task in args.tasks]
    check_out_folder(args.out, (), ())
    rows: list[dict[str, Any]] = []
    for task in tasks:
        for seed in args.seeds:
            rows.append(_train_and_confirm(task, seed, args))
            row = rows[-1]
            print(
                f"{task} seed {seed}: {row['wall_s']:.1f} s, kept episode {row['policy_episode']}, "
                f"confirmed {100 * row['confirmed_success']:.0f} % on {args.confirm_episodes} unseen episodes"
                + ("" if row["reached"] else f" (below {100 * args.target:g} %: not reached)")
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
        write_strict_json(Path(args.json), {"runs": rows, "summary": summary, "target": args.target})
    return 0


def _train_and_confirm(task: str, seed: int, args: argparse.Namespace) -> dict[str, Any]:
    out = Path(args.out) / task / f"s{seed}"
    out.mkdir(parents=True, exist_ok=True)
    command = [sys.executable, "-m", "tissue_retract", "train", "--task", task, "--seed", str(seed)]
    command += ["--out", str(out), "--fresh", "--no-progress", "--no-tensorboard", "--budget-s", f"{args.budget_s:g}"]
    with (out / "train.log").open("w") as log:
        start = time.perf_counter()
        status = subprocess.run(command, stdout=log, stderr=subprocess.STDOUT, check=False).returncode
        wall_s = time.perf_counter() - start
    success, episode = _confirm(task, out / "policy.safetensors", args.confirm_episodes) if status == 0 else (0.0, 0)
    return {
        "task": task,
        "seed": seed,
        "wall_s": wall_s,
        "exit_status": status,
        "policy_episode": episode,
        "confirmed_success": success,
        "reached": status == 0 and success >= args.target,
        "log": str(out / "train.log"),
    }


def _confirm(task: str, policy: Path, episodes: int) -> tuple[float, int]:
    """Success of the kept policy on unseen episodes, and the training episode it was kept at."""
    from policies.checkpoint import load_checkpoint
    from policies.resolve import resolve_policy
    from sim.envs import make
    from sim.evaluation import run_episode

    env = make(task)
    try:
        act, reset = resolve_policy(str(policy), env)
        results = [run_episode(env, act, reset, CONFIRM_SEED + i) for i in range(episodes)]
    finally:
        env.close()
    kept = int(load_checkpoint(policy).meta["progress"]["episodes"])
    return sum(r.success for r in results) / episodes, kept


def _summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The median over the runs (a run that did not reach the target is slower than any that did)."""
    times = [r["wall_s"] if r["reached"] else math.inf for r in rows]
    return {
        "median_s": statistics.median(times),
        "reached": sum(r["reached"] for r in rows),
        "runs": len(rows),
        "confirmed_success": [r["confirmed_success"] for r in rows],
    }
