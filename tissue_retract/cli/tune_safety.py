"""``tissue-retract tune-safety``: sweep safety settings, show success against peak force, recommend one.

Every setting of the ``--grid`` runs the same ``--episodes`` seeds through the full chain. The output
folder gets ``episodes.jsonl`` (resumable), ``settings.html`` and ``settings.md`` (every setting, the Pareto
front marked), ``pareto.png`` and ``recommended_safety.yaml``: the most successful setting whose largest
peak force stayed under ``--max-force-n``, loadable with ``--safety-config``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from matplotlib.figure import Figure
from rich.console import Console
from rich.table import Table

from psm_control import __version__
from psm_control.errors import ConfigurationError
from safety.config import SafetyConfig
from sim.envs import gym_id
from sim.sweep import EpisodeStore, cap_jobs, parse_ranges, prepare_output, run_trials
from sim.sweep.page import Page, percent, percent_interval, quantity, unit_of
from sim.tuning import (
    SettingResult,
    pareto_front,
    recommend,
    setting_results,
    tunable_fields,
    tuning_trials,
    write_config,
)
from tissue_retract.cli._checks import MAX_EPISODES, MAX_TRIALS, check_out_folder, float_in, int_in
from tissue_retract.cli.robustness import add_sweep_arguments, safety_overrides, sweep_identity
from tissue_retract.workers import TUNING_WORKER, check_sweep_policy

#: Files tune-safety writes into ``--out``.
OUTPUTS = ("episodes.jsonl", "sweep.json", "summary.json", "settings.md", "pareto.png", "recommended_safety.yaml")

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the subcommand to its parser."""
    add_sweep_arguments(parser, "tune-safety")
    parser.add_argument(
        "--grid",
        required=True,
        help="comma-separated SETTING=LOW:HIGH (or LOW:HIGHx of the default), e.g. force_limit_n=0.5:3,cbf_gamma=0.2:1",
    )
    parser.add_argument("--levels", type=int_in(1, 1000), default=4, help="values per setting, 1-1000 (default 4)")
    parser.add_argument(
        "--episodes", type=int_in(1, MAX_EPISODES), default=20, help="episodes per setting (default 20)"
    )
    parser.add_argument(
        "--max-force-n",
        type=float_in(0.0, 50.0, open_low=True),
        default=None,
        help="peak-force bound for the recommendation [N] (default: the default force limit)",
    )


def _plot(
    results: list[SettingResult], front: list[SettingResult], chosen: SettingResult | None, bound: float, path: Path
) -> None:
    figure = Figure(figsize=(5.5, 3.8), dpi=110)
    axis = figure.subplots()
    axis.scatter(
        [r.max_peak_force_n for r in results],
        [100 * r.success_rate for r in results],
        color="tab:gray",
        label="settings",
    )
    axis.plot(
        [r.max_peak_force_n for r in front],
        [100 * r.success_rate for r in front],
        "o-",
        color="tab:blue",
        label="Pareto front",
    )
    if chosen is not None:
        axis.scatter(
            [chosen.max_peak_force_n],
            [100 * chosen.success_rate],
            s=160,
            facecolors="none",
            edgecolors="tab:green",
            linewidths=2,
            label="recommended",
        )
    axis.axvline(bound, color="red", linestyle="--", label=f"bound {bound:g} N")
    axis.set_xlabel("largest peak retraction force over the episodes [N]")
    axis.set_ylabel("success [%]")
    axis.set_ylim(-5, 105)
    axis.grid(alpha=0.3)
    axis.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path)


def run(args: argparse.Namespace) -> int:
    """Run the sweep, write the table, plot and recommended configuration."""
    task_id = gym_id(args.task)
    ranges = parse_ranges(args.grid, valid_names=tunable_fields())
    count = args.levels ** len(ranges) * args.episodes
    if count > MAX_TRIALS:
        raise ConfigurationError(
            "--grid/--levels/--episodes",
            f"{len(ranges)} settings x {args.levels} levels x {args.episodes} episodes",
            f"at most {MAX_TRIALS} episodes in all (levels^settings x episodes = {count})",
        )
    jobs = cap_jobs(args.jobs)
    base = safety_overrides(args.safety_config) or {}
    bound = (
        args.max_force_n if args.max_force_n is not None else SafetyConfig.from_mapping(base).effective_force_limit_n
    )
    trials = tuning_trials(ranges, args.levels, args.episodes, seed=args.seed)
    out = args.out or Path("runs") / f"tune-safety-{task_id}"
    check_sweep_policy(args.policy, task_id, base, allow_other_task=args.allow_other_task)
    check_out_folder(out, OUTPUTS, (args.policy, args.safety_config))
    identity = sweep_identity(
        args,
        task_id,
        grid=[r.describe() for r in ranges],
        levels=args.levels,
        episodes=args.episodes,
        safety_config=base,
    )
    prepare_output(out, identity, fresh=args.fresh)
    records = run_trials(
        trials,
        TUNING_WORKER,
        store=EpisodeStore(out / "episodes.jsonl"),
        backend=args.backend,
        jobs=jobs,
        show_progress=not args.no_progress,
        worker_kwargs={
            "policy": args.policy,
            "task": task_id,
            "base_config": base,
            "allow_other_task": args.allow_other_task,
        },
    )
    failed = [r for r in records if "error" in r]
    if failed:
        print(
            f"tissue-retract tune-safety: error: {len(failed)} of {len(records)} episodes failed; first error: "
            f"{failed[0]['error']} (the others are kept in {out / 'episodes.jsonl'})",
            file=sys.stderr,
        )
        return 1
    results = setting_results(records, args.episodes)
    front = pareto_front(results)
    chosen = recommend(results, bound)
    names = [r.name for r in ranges]
    page = Page(f"Safety tuning of {args.policy} on {task_id}")
    table = Table(title=f"tune-safety: {args.policy} on {task_id} (bound {bound:g} N)")
    for column in [*names, "success %", "max peak N", "Pareto"]:
        table.add_column(column, justify="right")
    rows = []
    for r in results:
        low, high = r.ci95
        mark = ("front" if r in front else "") + (" recommended" if r is chosen else "")
        values = [quantity(r.setting[n], unit_of(n)) for n in names]
        rows.append(
            [
                *values,
                percent(r.success_rate),
                percent_interval(low, high),
                quantity(r.max_peak_force_n, "N"),
                quantity(r.mean_peak_force_n, "N"),
                str(r.interventions),
                mark.strip(),
            ]
        )
        table.add_row(*values, f"{100 * r.success_rate:.0f}", f"{r.max_peak_force_n:.3f}", mark)
    _plot(results, front, chosen, bound, out / "pareto.png")
    summary: dict[str, object] = {
        "task": task_id,
        "policy": args.policy,
        "grid": args.grid,
        "bound_n": bound,
        "settings": [
            dict(r.setting, success_rate=r.success_rate, max_peak_force_n=r.max_peak_force_n) for r in results
        ],
    }
    if chosen is not None:
        note = (
            f"Recommended by tissue-retract tune-safety for {args.policy} on {task_id}: success "
            f"{100 * chosen.success_rate:.0f} % over {chosen.episodes} episodes, largest peak force "
            f"{chosen.max_peak_force_n:.3f} N <= {bound:g} N."
        )
        write_config(out / "recommended_safety.yaml", chosen.setting, base, note)
        setting = ", ".join(f"{n} = {quantity(chosen.setting[n], unit_of(n))}" for n in names)
        verdict = f"Recommended: {setting} (written to recommended_safety.yaml)"
        summary["recommended"] = chosen.setting
    else:
        verdict = f"No setting kept the largest peak force under {bound:g} N; nothing recommended."
    page.card(
        [
            ("policy", args.policy),
            ("task", task_id),
            ("grid", f"{args.grid} ({args.levels} levels, {len(results)} settings)"),
            ("episodes per setting", f"{args.episodes}, seed {args.seed}"),
            ("peak-force bound", quantity(bound, "N")),
            ("verdict", verdict),
            ("package", f"tissue-retract {__version__}"),
        ],
        alert=[] if chosen is not None else ["verdict"],
    )
    page.heading("Command")
    page.command(args.command_line)
    page.heading("Settings (every setting ran the same episode seeds)")
    page.table([*names, "success", "95 % CI", "max peak force", "mean peak force", "interventions", "Pareto"], rows)
    page.figure(out / "pareto.png", "success against the largest peak force; the Pareto front in blue")
    page.write(out, stem="settings")
    (out / "summary.json").write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n")
    console = Console(width=110)
    console.print(table)
    console.print(verdict)
    return 0 if chosen is not None else 1
