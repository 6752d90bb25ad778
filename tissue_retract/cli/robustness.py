"""``tissue-retract robustness``: a policy's success and forces over randomized conditions.

Samples the ``--vary`` ranges (seeded, random or grid), runs every episode through the full safety
chain on a local process pool (or Ray), and writes to ``--out``: ``episodes.jsonl`` (one line per
episode, written as it finishes, so an interrupted sweep resumes), ``summary.json``, PNG plots and
``report.html`` / ``report.md``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from safety.config import SafetyConfig, load_safety_config
from sim.envs import gym_id
from sim.robustness import check_relative_ranges, sweep_parameters
from sim.sweep import EpisodeStore, make_trials, parse_ranges, run_trials
from sim.sweep.report import summarize, write_report
from tissue_retract.workers import ROBUSTNESS_WORKER

__all__ = ["add_arguments", "run"]


def add_sweep_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    """Options every sweep command shares: what to run, where, on how many processes."""
    parser.add_argument("--policy", required=True, help="scripted, random, module:callable or a checkpoint path")
    parser.add_argument("--task", required=True, help="task id (lift, target, multisite, expose or a Gymnasium id)")
    parser.add_argument("--seed", type=int, default=0, help="sweep seed (default 0)")
    parser.add_argument(
        "--backend",
        choices=("local", "ray"),
        default="local",
        help="local process pool (default) or Ray (RAY_ADDRESS or a local cluster)",
    )
    parser.add_argument("--jobs", type=int, default=None, help="worker processes (default: all cores)")
    parser.add_argument("--out", type=Path, default=None, help=f"output folder (default runs/{name}-TASK)")
    parser.add_argument("--safety-config", type=Path, default=None, help="SafetyConfig TOML/YAML file")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the subcommand to its parser."""
    add_sweep_arguments(parser, "robustness")
    parser.add_argument(
        "--trials",
        type=int,
        default=100,
        help="episodes (random mode) or levels per parameter (grid mode); default 100",
    )
    parser.add_argument(
        "--vary",
        required=True,
        help="comma-separated NAME=LOW:HIGH (absolute), NAME=LOW:HIGHx (times nominal) or "
        "NAME=VALUE, e.g. stiffness=0.3:3x,obs_noise=0:0.002,latency=0:3",
    )
    parser.add_argument("--mode", choices=("random", "grid"), default="random", help="sampling (default random)")
    parser.add_argument("--no-safety", action="store_true", help="ablation: run without the safety filter")


def safety_overrides(path: Path | None) -> dict[str, object] | None:
    """The settings of a SafetyConfig file that differ from the defaults (None without a file)."""
    if path is None:
        return None

    defaults = SafetyConfig().to_dict()
    return {k: v for k, v in load_safety_config(path).to_dict().items() if v != defaults[k]}


def run(args: argparse.Namespace) -> int:
    """Run the sweep, write its files, print its summary."""
    task_id = gym_id(args.task)
    ranges = parse_ranges(args.vary, valid_names=sweep_parameters())
    check_relative_ranges(ranges)
    trials = make_trials(ranges, args.trials, mode=args.mode, seed=args.seed)
    out = args.out or Path("runs") / f"robustness-{task_id}"
    out.mkdir(parents=True, exist_ok=True)
    store = EpisodeStore(out / "episodes.jsonl")
    already = len(store.done() & {t.index for t in trials})
    overrides = safety_overrides(args.safety_config)
    kwargs = {
        "policy": args.policy,
        "task": task_id,
        "relative": {r.name: r.relative for r in ranges},
        "safety": not args.no_safety,
        "safety_config": overrides,
    }
    started = time.perf_counter()
    records = run_trials(
        trials,
        ROBUSTNESS_WORKER,
        store=store,
        backend=args.backend,
        jobs=args.jobs,
        worker_kwargs=kwargs,
        show_progress=not args.no_progress,
    )
    elapsed = time.perf_counter() - started
    summary = summarize(records)
    ran = len(records) - already
    summary.update(
        {
            "task": task_id,
            "policy": args.policy,
            "vary": [r.describe() for r in ranges],
            "mode": args.mode,
            "seed": args.seed,
            "backend": args.backend,
            "jobs": args.jobs,
            "episodes_run_now": ran,
            "elapsed_s": elapsed,
            "episodes_per_s": ran / elapsed if ran and elapsed > 0 else None,
            "safety": not args.no_safety,
        }
    )
    (out / "summary.json").write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n")
    config = SafetyConfig.from_mapping(overrides or {})
    context = {
        "policy": args.policy,
        "task": task_id,
        "varied": ", ".join(r.describe() for r in ranges),
        "sampling": f"{args.mode}, {args.trials} trials, seed {args.seed}",
        "safety filter": "on" if not args.no_safety else "OFF (ablation)",
    }
    write_report(
        out,
        records,
        ranges,
        title=f"Robustness of {args.policy} on {task_id}",
        context=context,
        force_limit_n=config.effective_force_limit_n,
        limit_enforced=not args.no_safety,
        command=args.command_line,
    )
    table = Table(title=f"robustness: {args.policy} on {task_id}")
    table.add_column("metric")
    table.add_column("value", justify="right")
    low, high = summary["ci95"]
    table.add_row("episodes (errors)", f"{summary['episodes']} ({summary['errors']})")
    table.add_row("success", f"{100 * summary['success_rate']:.1f} % [{100 * low:.1f}, {100 * high:.1f}]")
    table.add_row(
        "peak force max / p95 [N]",
        f"{summary['peak_force_n']['max'] or 0:.3f} / {summary['peak_force_n']['p95'] or 0:.3f}",
    )
    table.add_row("safety stops / invalid actions", f"{summary['safety_stops']} / {summary['invalid_actions']}")
    table.add_row("failure classes", ", ".join(f"{k} {v}" for k, v in summary["failure_classes"].items()))
    if summary["episodes_per_s"]:
        table.add_row("episodes/s (this run)", f"{summary['episodes_per_s']:.2f}")
    Console(width=110).print(table)
    print(f"report: {out / 'report.html'}")
    return 0 if summary["errors"] == 0 else 1
