"""``tissue-retract reproduce``: the seed paper's Table 1 and Table 2, trained and evaluated here.

Table 1: DDPG, SQIL, DDPGBC, CoL and DEX on Tasks I-III with 100 demonstrations, seeds 1-3;
Table 2: 25 / 50 / 100 demonstrations on Task III. Every run is one ``train`` in its own process and
folder under ``--runs`` (an interrupted reproduction resumes run by run). Writes the report to ``--out``:
``results.md`` and ``results.html`` (our success, mean over seeds with a 95 % interval, beside the paper's,
per cell and as learning curves) and ``results.json`` (every number, every run's curve, the code it trained
on). The full budget (1,000 episodes per run, as the paper's code) takes hours on a laptop-class CPU;
``--budget`` shortens it.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import TYPE_CHECKING

from policies.config import ALGORITHMS
from policies.config import PAPER_TASKS as TASKS
from psm_control.errors import ConfigurationError, UnknownVariantError
from sim.sweep import BACKENDS
from tissue_retract.cli._checks import MAX_EPISODES, MAX_SEED, check_out_folder, int_in

if TYPE_CHECKING:
    from policies.reproduce import RunOutcome

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the subcommand to its parser."""
    episodes = int_in(1, MAX_EPISODES)
    parser.add_argument("--budget", type=episodes, default=1000, help="training episodes per run (default 1000)")
    parser.add_argument(
        "--jobs", type=int_in(1, 4096), default=None, help="parallel training processes (default: all cores)"
    )
    parser.add_argument(
        "--backend",
        choices=BACKENDS,
        default="local",
        help="local process pool, or Ray (RAY_ADDRESS, else a local cluster on 127.0.0.1; the dist extra)",
    )
    parser.add_argument("--out", type=Path, default=Path("runs/reproduce"), help="the report's folder")
    parser.add_argument("--runs", type=Path, default=None, help="the training runs' folders (default: OUT/runs)")
    parser.add_argument("--tasks", default="I,II,III", help="comma-separated tasks among I, II, III")
    parser.add_argument("--algos", default=",".join(ALGORITHMS), help="comma-separated algorithms")
    parser.add_argument("--seeds", type=int_in(0, MAX_SEED), nargs="+", default=[1, 2, 3], help="seeds (default 1 2 3)")
    parser.add_argument(
        "--demos", type=int_in(1, MAX_EPISODES), default=100, help="demonstrations of Table 1 (default 100)"
    )
    parser.add_argument("--no-ablation", action="store_true", help="skip Table 2's 25 and 50 demonstrations")
    parser.add_argument("--eval-every", type=episodes, default=50, help="episodes between evaluations (default 50)")
    parser.add_argument("--eval-episodes", type=episodes, default=50, help="episodes per evaluation (default 50)")


def run(args: argparse.Namespace) -> int:
    """Plan the runs, train them in parallel, write the tables and curves."""
    tasks = list(dict.fromkeys(t.strip().upper() for t in args.tasks.split(",") if t.strip()))
    for task in tasks:
        if task not in TASKS:
            raise UnknownVariantError("tasks", task, TASKS)
    algos = list(dict.fromkeys(a.strip().lower() for a in args.algos.split(",") if a.strip()))
    for algo in algos:
        if algo not in ALGORITHMS:
            raise UnknownVariantError("algos", algo, ALGORITHMS)
    if not tasks or not algos:
        flag, allowed = ("--tasks", ", ".join(TASKS)) if not tasks else ("--algos", ", ".join(ALGORITHMS))
        raise ConfigurationError(flag, args.tasks if not tasks else args.algos, f"one or more of {allowed}")
    seeds = list(dict.fromkeys(args.seeds))  # one folder per seed: a repeated seed would train it twice at once
    runs_dir = args.runs if args.runs is not None else args.out / "runs"
    for make in (False, True):  # both checked before either is made
        check_out_folder(args.out, (), (), make=make)
        check_out_folder(runs_dir, (), (), field="--runs", make=make)
    from policies.reproduce import plan, reproduce  # torch and matplotlib: only once the arguments are good

    runs = plan(
        runs_dir,
        episodes=args.budget,
        tasks={t: TASKS[t] for t in tasks},
        algos=algos,
        seeds=seeds,
        demos=args.demos,
        ablation_task=None if args.no_ablation else "III",
        eval_every=min(args.eval_every, args.budget),
        eval_episodes=args.eval_episodes,
    )
    jobs = args.jobs or os.cpu_count() or 1
    print(f"reproduce: {len(runs)} runs of {args.budget} episodes on {jobs} processes ({args.backend})")
    print(f"reproduce: runs in {runs_dir}, the report in {args.out}")
    ended = 0

    def report(outcome: RunOutcome) -> None:
        nonlocal ended
        ended += 1
        resumed = f" from episode {outcome.resumed_from}" if outcome.resumed_from else ""
        name, success = outcome.run.out_dir.name, 100 * outcome.success
        took = f"{outcome.wall_seconds:.0f} s{resumed}"
        print(f"reproduce: [{ended}/{len(runs)}] {name}: {success:.0f} % ({took})", flush=True)

    path, _ = reproduce(args.out, runs, jobs=jobs, backend=args.backend, command=args.command_line, on_finished=report)
    print(path.read_text())
    return 0
