"""``tissue-retract tune-safety``: sweep safety settings, show success against peak force, recommend one.

Every setting of the ``--grid`` runs the same ``--episodes`` seeds through the full chain. The output
folder gets ``episodes.jsonl`` (resumable), ``settings.html`` and ``settings.md`` (every setting, the Pareto
front marked), ``pareto.png`` and ``recommended_safety.yaml``: the most successful setting whose force limit
is at or below ``--max-force-n`` and whose largest observed peak stayed under it, loadable with
``--safety-config``. The report states the recommendation's 95 % CI of success and its episodes, and warns
when it is weak.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from rich.console import Console
from rich.table import Table

from psm_control import __version__
from psm_control.errors import ConfigurationError
from psm_control.outputs import atomic_path
from safety.config import MAX_FORCE_LIMIT_N, SafetyConfig
from sim.registration import gym_id
from sim.strict_json import write_strict_json
from sim.success_interval import describe_success
from sim.sweep import EpisodeStore, cap_jobs, parse_ranges, prepare_output, run_trials
from sim.sweep.page import Page, percent, percent_interval, quantity, unit_of
from sim.tuning import (
    SettingResult,
    pareto_front,
    recommend,
    recommendation_warnings,
    setting_force_limit_n,
    setting_results,
    tunable_fields,
    tuning_trials,
    write_config,
)
from tissue_retract.cli._checks import MAX_EPISODES, MAX_TRIALS, check_out_folder, float_in, int_in
from tissue_retract.cli._next import command, say_next
from tissue_retract.cli._sensing import SweepSensing, announce, sweep_sensing
from tissue_retract.cli.robustness import add_sweep_arguments, calibration_identity, safety_overrides, sweep_identity

if TYPE_CHECKING:
    from matplotlib.figure import Figure

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
        help="force bound for the recommendation [N]: only settings whose force limit is at or below it, and "
        "whose largest observed peak stayed under it, are recommended (default: the default force limit)",
    )


def _plot(
    results: list[SettingResult],
    front: list[SettingResult],
    chosen: SettingResult | None,
    bound: float,
    limits_n: list[float],
    eligible: list[bool],
    path: Path,
) -> Figure:
    """Success against the largest peak, each setting's own force limit beside its peak on the same axis.

    A setting is drawn as a cross when :func:`~sim.tuning.recommend` would not take it (its limit or its
    peak above the bound, or no success), by that rule and no other; its limit is a bar joined to its peak,
    so a setting whose peak is left of the bound and whose limit is right of it shows both.
    """
    from matplotlib.figure import Figure  # only when there is a sweep to plot

    figure = Figure(figsize=(6.0, 4.2), dpi=110)
    axis = figure.subplots()
    colours = ["tab:gray" if ok else "tab:red" for ok in eligible]
    for r, limit, colour in zip(results, limits_n, colours, strict=True):
        y = 100 * r.success_rate
        axis.plot([r.max_peak_force_n, limit], [y, y], color=colour, linewidth=1, alpha=0.5, zorder=1)
    axis.scatter(
        limits_n,
        [100 * r.success_rate for r in results],
        marker="|",
        s=120,
        c=colours,
        zorder=2,
        label="its force limit (joined to its peak)",
    )
    for ok, style, label in (
        (True, {"color": "tab:gray", "marker": "o"}, "largest peak; may be recommended"),
        (
            False,
            {"color": "tab:red", "marker": "x", "s": 60},
            "largest peak; not: limit or peak above the bound, or no success",
        ),
    ):
        shown = [r for r, e in zip(results, eligible, strict=True) if e is ok]
        if shown:
            axis.scatter(
                [r.max_peak_force_n for r in shown],
                [100 * r.success_rate for r in shown],
                zorder=4,
                label=label,
                **style,
            )
    axis.plot(
        [r.max_peak_force_n for r in front],
        [100 * r.success_rate for r in front],
        "-",
        color="tab:blue",
        label="Pareto front (of the peaks)",
        zorder=3,
    )
    if chosen is not None:
        axis.scatter(
            [chosen.max_peak_force_n],
            [100 * chosen.success_rate],
            s=160,
            facecolors="none",
            edgecolors="tab:green",
            linewidths=2,
            zorder=5,
            label="recommended",
        )
    axis.axvline(bound, color="red", linestyle="--", label=f"bound {bound:g} N: limit and peak at or left of it")
    axis.set_xlabel("force [N]: each setting's largest peak over its episodes, and its force limit")
    axis.set_ylabel("success [%]")
    axis.set_ylim(-5, 105)
    axis.grid(alpha=0.3)
    axis.legend(fontsize=7)
    figure.tight_layout()
    with atomic_path(path, "--out") as temporary:
        figure.savefig(temporary)
    return figure


def _grid(low: float, high: float) -> str:
    """A ``--grid`` of force limits from ``low`` to ``high`` [N], as a user would type it."""
    return f"--grid force_limit_n={low:.3g}:{high:.3g}"


def _nothing_recommended(
    results: list[SettingResult],
    bound: float,
    base: dict[str, object],
    sensing: SweepSensing,
    sensing_error_n: float | None,
) -> str:
    """Why no setting qualified, with the numbers, and what grid or setting would give a recommendation."""
    limits = [setting_force_limit_n(r.setting, base) for r in results]
    succeeded = [(limit, r) for r, limit in zip(results, limits, strict=True) if r.successes > 0 and r.errors == 0]
    above = [(limit, r) for limit, r in succeeded if limit > bound + 1e-9]
    evidence = ""
    if above:
        limit, r = min(above, key=lambda pair: pair[0])
        evidence = (
            f"--max-force-n {limit:g}, if the tissue allows that force: the lowest force limit the policy succeeded "
            f"under here is {limit:g} N ({describe_success(r.successes, r.episodes)})"
        )
    if all(limit > bound + 1e-9 for limit in limits):
        todo = [f"sweep force limits at or below it ({_grid(bound / 2, bound)})", *([evidence] if evidence else [])]
        return (
            f"every setting's force limit ({min(limits):g}-{max(limits):g} N) is above the bound {bound:g} N. "
            f"What would give a recommendation: {'; or '.join(todo)}"
        )
    within = [(r, limit) for r, limit in zip(results, limits, strict=True) if limit <= bound + 1e-9]
    if all(r.successes == 0 for r, _ in within):
        low, high = min(lim for _, lim in within), max(lim for _, lim in within)
        why = (
            f"the policy succeeded in no episode under any setting with a force limit <= {bound:g} N "
            f"({len(within)} setting(s), limits {low:.3g}-{high:.3g} N)"
        )
        todo = []
        if sensing_error_n is not None and all(lim <= sensing_error_n for _, lim in within):
            why += (
                f"; every one of those limits is below the force sensing's error bound {sensing_error_n:.2f} N "
                f"({sensing.label}): the filter cannot tell the limit from the measured force and stops each "
                "retraction at the grasp's travel bound"
            )
            if sensing_error_n + 1.0 < MAX_FORCE_LIMIT_N:
                first = math.ceil(sensing_error_n + 1.0)
                last = min(MAX_FORCE_LIMIT_N, 2 * first)
                todo.append(
                    f"force limits above that error bound, where the measured force tells the limit, if the tissue "
                    f"allows them: {_grid(first, last)} --max-force-n {last:g}"
                )
            else:
                why += f". No force limit the safety filter takes ({MAX_FORCE_LIMIT_N:g} N at most) is above it"
            if sensing.calibration is not None:
                todo.append(
                    f"a calibration whose error_bound_with_acceleration_n is below {bound:g} N (this file's is "
                    f"{sensing.error_n:.2f} N): calibrate-wrench again on logs of the poses and speeds the task moves "
                    "at, then --wrench-calibration with the new file"
                )
            else:
                todo.append(
                    f"calibrate the force sensing (calibrate-wrench) and sweep with the robot's own file "
                    f"(--wrench-calibration F.json): limits above its error_bound_with_acceleration_n are told from "
                    f"the measured force, so one below {bound:g} N would give this grid a recommendation"
                )
        elif not evidence:
            todo.append(
                f"higher force limits, if the tissue allows them ({_grid(high, 2 * high)} --max-force-n {2 * high:.3g})"
            )
        if evidence:
            todo.append(evidence)
        return f"{why}. What would give a recommendation: {'; or '.join(todo)}"
    return (
        f"no setting with a force limit <= {bound:g} N kept its largest observed peak force under {bound:g} N. "
        f"What would give a recommendation: force limits a tenth or more below the bound (the true peak stays "
        f"within 1.10 x the limit): {_grid(bound / 2, bound / 1.1)}"
    )


def run(args: argparse.Namespace) -> int:
    """Run the sweep, write the table, plot and recommended configuration."""
    task_id = gym_id(args.task)
    sensing = sweep_sensing(args.force_sensing, args.wrench_calibration)
    args.force_sensing = sensing.name  # the preset, as the policy variant and sweep.json name it
    try:
        ranges = parse_ranges(args.grid, valid_names=tunable_fields())
    except ConfigurationError as e:  # the range grammar is robustness's --vary; here the option is --grid
        raise ConfigurationError(e.field.replace("vary", "--grid", 1), e.value, e.allowed) from None
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
    from tissue_retract.workers import TUNING_WORKER, check_sweep_policy  # the simulation: checks passed

    # One warning, naming the limits the grid runs (not the configuration's, which a force_limit_n grid replaces).
    sensing_note = check_sweep_policy(
        args.policy,
        task_id,
        base,
        allow_other_task=args.allow_other_task,
        force_sensing=args.force_sensing,
        calibrated_error_n=sensing.calibrated_error_n,
        sensing_label=sensing.label,
        force_limits_n=sorted({setting_force_limit_n(t.params, base) for t in trials}),
    )
    announce(sensing_note)
    sensing_error_n = None if args.force_sensing == "ideal" else sensing.error_n
    run_warnings = [sensing_note] if sensing_note else []
    check_out_folder(out, OUTPUTS, (args.policy, args.safety_config, args.wrench_calibration))
    identity = sweep_identity(
        args,
        task_id,
        grid=[r.describe() for r in ranges],
        levels=args.levels,
        episodes=args.episodes,
        safety_config=base,
        force_sensing=args.force_sensing,
        **calibration_identity(sensing),
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
            "force_sensing": args.force_sensing,
            "calibrated_error_n": sensing.calibrated_error_n,
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
    chosen = recommend(results, bound, base)
    names = [r.name for r in ranges]
    page = Page(f"Safety tuning of {args.policy} on {task_id}")
    table = Table(title=f"tune-safety: {args.policy} on {task_id} (bound {bound:g} N)")
    # The limit in force is a column of its own only when the grid does not sweep it (it would repeat it).
    own_limit = "force_limit_n" not in names
    limit_column = ["force limit"] if own_limit else []
    for column in [*names, *limit_column, "success [%]", "95 % CI [%]", "max peak", "Pareto"]:
        table.add_column(column, justify="right")
    rows = []
    for r in results:
        low, high = r.ci95
        limit_n = setting_force_limit_n(r.setting, base)
        mark = ("front" if r in front else "") + (" recommended" if r is chosen else "")
        mark += " limit above bound" if limit_n > bound + 1e-9 else ""
        values = [quantity(r.setting[n], unit_of(n)) for n in names]
        limit = [quantity(limit_n, "N")] if own_limit else []
        rows.append(
            [
                *values,
                *limit,
                percent(r.success_rate),
                percent_interval(low, high),
                quantity(r.max_peak_force_n, "N"),
                quantity(r.mean_peak_force_n, "N"),
                str(r.interventions),
                mark.strip(),
            ]
        )
        table.add_row(
            *values,
            *limit,
            f"{100 * r.success_rate:.0f}",
            f"{100 * low:.0f}-{100 * high:.0f}",
            quantity(r.max_peak_force_n, "N"),
            mark.strip(),
        )
    eligible = [recommend([r], bound, base) is not None for r in results]  # the recommendation's own rule
    _plot(
        results,
        front,
        chosen,
        bound,
        [setting_force_limit_n(r.setting, base) for r in results],
        eligible,
        out / "pareto.png",
    )
    summary: dict[str, object] = {
        "task": task_id,
        "policy": args.policy,
        "grid": args.grid,
        "bound_n": bound,
        "episodes_per_setting": args.episodes,
        "settings": [
            dict(
                r.setting,
                force_limit_in_force_n=setting_force_limit_n(r.setting, base),
                success_rate=r.success_rate,
                success_ci95=list(r.ci95),
                max_peak_force_n=r.max_peak_force_n,
            )
            for r in results
        ],
    }
    summary.update(
        force_sensing=args.force_sensing, force_sensing_error_n=sensing_error_n, **calibration_identity(sensing)
    )
    alert = ["verdict"]
    warnings: list[str] = []
    if chosen is not None:
        low, high = chosen.ci95
        limit_n = setting_force_limit_n(chosen.setting, base)
        confidence = f"success {describe_success(chosen.successes, chosen.episodes)}"
        why = (
            f"force limit {limit_n:g} N <= bound {bound:g} N (the limit is what the filter enforces in every "
            f"episode); the most successful such setting, its largest observed peak {chosen.max_peak_force_n:.3f} N"
        )
        warnings = recommendation_warnings(chosen)
        note = (
            f"Recommended by tissue-retract tune-safety for {args.policy} on {task_id}: {confidence}; {why}."
            + "".join(f"\nWEAK: {w}." for w in warnings)
        )
        write_config(out / "recommended_safety.yaml", chosen.setting, base, note)
        setting = ", ".join(f"{n} = {quantity(chosen.setting[n], unit_of(n))}" for n in names)
        verdict = f"Recommended: {setting} (written to recommended_safety.yaml); {confidence}"
        summary["recommended"] = chosen.setting
        summary["recommendation"] = {
            "setting": chosen.setting,
            "force_limit_n": limit_n,
            "episodes": chosen.episodes,
            "successes": chosen.successes,
            "success_ci95": [low, high],
            "max_peak_force_n": chosen.max_peak_force_n,
            "warnings": warnings,
        }
        alert = ["warnings"] if warnings or run_warnings else []
    else:
        why = _nothing_recommended(results, bound, base, sensing, sensing_error_n)
        verdict = "Nothing recommended (why below)"
    summary["warnings"] = run_warnings + [f"weak recommendation: {w}" for w in warnings]
    card = [
        ("policy", args.policy),
        ("task", task_id),
        ("force sensing", sensing.describe()),
        ("asked", f"grid {args.grid} ({args.levels} levels, {len(results)} settings), force bound {bound:g} N"),
        ("episodes per setting", f"{args.episodes}, seed {args.seed}"),
        ("verdict", verdict),
        ("why", why),
        ("warnings", "; ".join(run_warnings + warnings) or "none"),
        ("package", f"tissue-retract {__version__}"),
    ]
    page.card(card, alert=alert)
    page.heading("Command")
    page.command(args.command_line)
    page.heading("Settings (every setting ran the same episode seeds)")
    page.table(
        [*names, *limit_column, "success", "95 % CI", "max peak force", "mean peak force", "interventions", "Pareto"],
        rows,
    )
    page.figure(
        out / "pareto.png",
        "success against the largest peak force, each setting's force limit a bar joined to its peak; crosses: "
        "not recommendable (limit or peak above the bound, or no success); the Pareto front in blue",
    )
    page.write(out, stem="settings")
    write_strict_json(out / "summary.json", summary, sort_keys=True)
    console = Console(width=110)
    console.print(table)
    console.print(verdict)
    console.print(f"Why: {why}")
    for warning in warnings:
        console.print(f"[bold yellow]WARNING:[/] weak recommendation: {warning}")
    if chosen is None:
        return 1
    config = str(out / "recommended_safety.yaml")
    deploy = ["deploy", "--policy", args.policy, "--target", "sim", "--task", args.task, "--safety-config", config]
    say_next(f"{command(*deploy)} (the recommendation through the whole chain), then the rehearsal against sim-dvrk")
    return 0
