"""``tissue-retract robustness``: a policy's success and forces over randomized conditions.

Samples the ``--vary`` ranges (seeded, random or grid), runs every episode through the full safety
chain on a local process pool (or Ray), and writes to ``--out``: ``episodes.jsonl`` (one line per
episode, written as it finishes, so an interrupted sweep resumes), ``summary.json``, PNG plots and
``report.html`` / ``report.md``.

The report and ``summary.json`` (``by_stiffness_fifth``) show where the force limit stops a retraction:
success and the share stopped by the force limit for each fifth of the trials by drawn stiffness
(:mod:`sim.stiffness_fifths`). ``--beside-expert`` also runs the scripted expert on the same trials
(seeds and draws), into ``expert_episodes.jsonl``, and shows its numbers beside the policy's.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

from policies.resolve import POLICY_NAMES
from policies.shipped import policy_file, variant_for
from psm_control import __version__
from psm_control.errors import ConfigurationError
from safety.config import SafetyConfig, load_safety_config
from sim.evaluation import describe_exceedances, describe_stalls
from sim.registration import gym_id
from sim.robustness import parse_vary, sweep_ranges
from sim.stiffness_fifths import by_stiffness_fifth, expert_summary
from sim.strict_json import write_strict_json
from sim.success_interval import describe_success
from sim.sweep import EpisodeStore, Trial, cap_jobs, file_digest, make_trials, prepare_output, run_trials
from tissue_retract.cli._camera import (
    add_perception_argument,
    add_texture_argument,
    check_texture,
    load_perception,
    texture_warning,
)
from tissue_retract.cli._checks import MAX_EPISODES, MAX_TRIALS, check_out_folder, int_in
from tissue_retract.cli._next import command, say_next
from tissue_retract.cli._sensing import (
    SweepSensing,
    add_force_sensing_argument,
    add_wrench_calibration_argument,
    announce,
    sweep_sensing,
)

#: The scripted expert's episodes of the same trials (``--beside-expert``).
EXPERT_EPISODES = "expert_episodes.jsonl"
#: Files a robustness sweep writes into ``--out`` (besides its plots).
OUTPUTS = ("episodes.jsonl", EXPERT_EPISODES, "sweep.json", "summary.json", "report.html", "report.md")
#: The policy a sweep runs beside the user's with ``--beside-expert``.
EXPERT = "scripted"

__all__ = ["add_arguments", "run"]


def add_sweep_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    """Options every sweep command shares: what to run, where, on how many processes."""
    parser.add_argument("--policy", required=True, help=POLICY_NAMES)
    parser.add_argument("--task", required=True, help="task id (lift, target, multisite, expose or a Gymnasium id)")
    parser.add_argument("--seed", type=int_in(0, 2**31 - 1), default=0, help="sweep seed (default 0)")
    parser.add_argument(
        "--backend",
        choices=("local", "ray"),
        default="local",
        help="local process pool (default) or Ray (RAY_ADDRESS or a local cluster)",
    )
    parser.add_argument(
        "--jobs", type=int_in(1, 4096), default=None, help="worker processes (default and at most: all cores)"
    )
    parser.add_argument("--out", type=Path, default=None, help=f"output folder (default runs/{name}-TASK)")
    parser.add_argument("--safety-config", type=Path, default=None, help="SafetyConfig TOML/YAML file")
    add_force_sensing_argument(parser, default=None)
    add_wrench_calibration_argument(parser)
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    parser.add_argument(
        "--fresh", action="store_true", help="delete the episodes of an earlier sweep in --out and start over"
    )
    parser.add_argument(
        "--allow-other-task", action="store_true", help="run a checkpoint trained for another task (same spaces)"
    )


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the subcommand to its parser."""
    add_sweep_arguments(parser, "robustness")
    parser.add_argument(
        "--trials",
        type=int_in(1, MAX_EPISODES),
        default=100,
        help=f"episodes (random mode) or levels per parameter (grid mode); default 100, at most {MAX_EPISODES}",
    )
    parser.add_argument(
        "--vary",
        required=True,
        help="comma-separated NAME=LOW:HIGH (absolute), NAME=LOW:HIGHx (times nominal) or "
        "NAME=VALUE, e.g. youngs_modulus=2:30kpa,obs_noise=0:0.002,latency=0:3 (stiffness=0.3:3x scales "
        "the Young's modulus)",
    )
    parser.add_argument("--mode", choices=("random", "grid"), default="random", help="sampling (default random)")
    parser.add_argument("--no-safety", action="store_true", help="ablation: run without the safety filter")
    parser.add_argument(
        "--beside-expert",
        action="store_true",
        help=f"also run the scripted expert on the same trials (seeds and draws), into {EXPERT_EPISODES}, and "
        "report its success and force-limit stops beside the policy's (nothing more with --policy scripted)",
    )
    add_perception_argument(parser)
    add_texture_argument(parser)


def safety_overrides(path: Path | None) -> dict[str, object] | None:
    """The settings of a SafetyConfig file that differ from the defaults (None without a file)."""
    if path is None:
        return None

    defaults = SafetyConfig().to_dict()
    # Tuples as lists: the overrides go to JSON (sweep.json) and to the workers as they would be read back.
    return {
        k: list(v) if isinstance(v, tuple) else v
        for k, v in load_safety_config(path).to_dict().items()
        if v != defaults[k]
    }


def _shown_path(path: Path) -> str:
    """A policy file's path relative to the installed packages' folder when it is inside it (a shipped one)."""
    root = Path(__file__).resolve().parents[2]
    try:
        return str(Path(path).resolve().relative_to(root))
    except ValueError:
        return str(path)


def _policy_digest(policy: str, task_id: str, variant: str) -> str | None:
    """SHA-256 of the file the policy loads (the shipped one for ``pretrained``); None for code policies."""
    path = policy_file(policy, task_id, variant)
    return file_digest(path) if path is not None else None


def sweep_identity(args: argparse.Namespace, task_id: str, **settings: object) -> dict[str, object]:
    """What decides a sweep's episodes, as recorded in ``sweep.json``."""
    return {
        "policy": args.policy,
        "policy_sha256": _policy_digest(
            args.policy, task_id, variant_for(args.force_sensing, getattr(args, "perception", None) is not None)
        ),
        "task": task_id,
        "seed": args.seed,
        "package_version": __version__,
        **settings,
    }


def calibration_identity(sensing: SweepSensing) -> dict[str, object]:
    """``force_sensing_calibration`` for ``sweep.json`` and ``summary.json`` with a calibration file (nothing
    without one, so a sweep written before the option resumes)."""
    record = sensing.calibration_record()
    return {} if record is None else {"force_sensing_calibration": record}


def run(args: argparse.Namespace) -> int:
    """Run the sweep, write its files, print its summary."""
    task_id = gym_id(args.task)
    sensing = sweep_sensing(args.force_sensing, args.wrench_calibration)
    args.force_sensing = sensing.name  # the preset, as the policy variant and sweep.json name it
    ranges = parse_vary(args.vary)
    count = args.trials ** len(ranges) if args.mode == "grid" else args.trials
    if count > MAX_TRIALS:
        raise ConfigurationError(
            "--trials",
            args.trials,
            f"at most {MAX_TRIALS} trials in all ({args.trials}^{len(ranges)} = {count} in grid mode)",
        )
    jobs = cap_jobs(args.jobs)
    overrides = safety_overrides(args.safety_config)
    out = args.out or Path("runs") / f"robustness-{task_id}"
    declared = sweep_ranges((r.name, r.low, r.high, r.relative) for r in ranges)
    from tissue_retract.workers import ROBUSTNESS_WORKER, check_sweep_policy  # the simulation: checks passed

    warning = check_sweep_policy(
        args.policy,
        task_id,
        overrides,
        allow_other_task=args.allow_other_task,
        force_sensing=args.force_sensing,
        tissue_ranges=declared,
        calibrated_error_n=sensing.calibrated_error_n,
        sensing_label=sensing.label,
    )
    announce(warning)
    texture = check_texture(args.texture) if args.texture is not None else None
    # Refused here, before any worker starts, if it is not a model.
    announce(texture_warning(load_perception(args.perception), texture))
    check_out_folder(out, OUTPUTS, (args.policy, args.safety_config, args.wrench_calibration))
    trials = make_trials(ranges, args.trials, mode=args.mode, seed=args.seed)
    kwargs = {
        "policy": args.policy,
        "task": task_id,
        "relative": {r.name: r.relative for r in ranges},
        "safety": not args.no_safety,
        "safety_config": overrides,
        "allow_other_task": args.allow_other_task,
        "force_sensing": args.force_sensing,
        "tissue_ranges": {k: list(v) for k, v in declared.items()},
        "perception": args.perception,
        "texture": texture,
        "calibrated_error_n": sensing.calibrated_error_n,
    }
    identity = sweep_identity(
        args,
        task_id,
        vary=[r.describe() for r in ranges],
        mode=args.mode,
        episodes=args.trials,
        safety=not args.no_safety,
        safety_config=overrides,
        force_sensing=args.force_sensing,
        perception=args.perception,
        texture=texture,
        **calibration_identity(sensing),
    )
    if args.fresh:
        (out / EXPERT_EPISODES).unlink(missing_ok=True)
    prepare_output(out, identity, fresh=args.fresh)
    store = EpisodeStore(out / "episodes.jsonl")
    already = len(store.done() & {t.index for t in trials})
    started = time.perf_counter()
    records = run_trials(
        trials,
        ROBUSTNESS_WORKER,
        store=store,
        backend=args.backend,
        jobs=jobs,
        worker_kwargs=kwargs,
        show_progress=not args.no_progress,
    )
    elapsed = time.perf_counter() - started
    expert_records = _beside_expert(args, trials, kwargs, out, jobs)
    from sim.sweep.report import summarize, write_report  # matplotlib: for the report only

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
            "jobs": jobs,
            "episodes_run_now": ran,
            "elapsed_s": elapsed,
            "episodes_per_s": ran / elapsed if ran and elapsed > 0 else None,
            "safety": not args.no_safety,
            "force_sensing": args.force_sensing,
            **calibration_identity(sensing),
            "warnings": [warning] if warning else [],
            "beside_expert": expert_records is not None,
            "by_stiffness_fifth": [f.to_dict() for f in by_stiffness_fifth(records, expert_records)],
            **(expert_summary(expert_records) if expert_records is not None else {}),
        }
    )
    write_strict_json(out / "summary.json", summary, sort_keys=True)
    config = SafetyConfig.from_mapping(overrides or {})
    variant = variant_for(args.force_sensing, getattr(args, "perception", None) is not None)
    policy_path = policy_file(args.policy, task_id, variant)
    policy = args.policy
    if policy_path is not None:  # the file it ran, by path and digest, not only the name given
        policy = f"{args.policy}: {_shown_path(policy_path)} (sha256 {str(file_digest(policy_path))[:12]})"
    context = {
        "policy": policy,
        "task": task_id,
        "varied": ", ".join(r.describe() for r in ranges),
        "sampling": f"{args.mode}, {args.trials} trials, seed {args.seed}",
        "safety filter": "on" if not args.no_safety else "OFF (ablation)",
        "force sensing": sensing.describe() if sensing.calibration is not None else args.force_sensing,
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
        expert_records=expert_records,
        warnings=summary["warnings"],
    )
    table = Table(title=f"robustness: {args.policy} on {task_id}")
    table.add_column("metric")
    table.add_column("value", justify="right")
    finished = [r for r in records if "error" not in r]
    table.add_row("episodes (errors)", f"{summary['episodes']} ({summary['errors']})")
    table.add_row("success", describe_success(sum(1 for r in finished if r.get("success")), len(finished)))
    if expert_records is not None:
        beside = [r for r in expert_records if "error" not in r]
        table.add_row(
            "scripted expert, same trials", describe_success(sum(1 for r in beside if r.get("success")), len(beside))
        )
    table.add_row(
        "peak force max / p95 [N]",
        f"{summary['peak_force_n']['max'] or 0:.3f} / {summary['peak_force_n']['p95'] or 0:.3f}",
    )
    table.add_row("safety stops / invalid actions", f"{summary['safety_stops']} / {summary['invalid_actions']}")
    table.add_row("force limit exceeded", describe_exceedances(summary))
    table.add_row("force limit stalled retraction", describe_stalls(summary))
    table.add_row("failure classes", ", ".join(f"{k} {v}" for k, v in summary["failure_classes"].items()))
    if summary["episodes_per_s"]:
        table.add_row("episodes/s (this run)", f"{summary['episodes_per_s']:.2f}")
    Console(width=110).print(table)
    print(f"report: {out / 'report.html'}")
    status = 0
    for whose, kept, file in (("", records, "episodes.jsonl"), (" of the expert", expert_records, EXPERT_EPISODES)):
        failed = [r for r in kept or () if "error" in r]
        if failed:
            print(
                f"tissue-retract robustness: error: {len(failed)} of {len(kept or ())} episodes{whose} failed; "
                f"first: {failed[0]['error']} (the others are kept in {out / file})",
                file=sys.stderr,
            )
            status = 1
    if status == 0:
        tune = command("tune-safety", "--policy", args.policy, "--task", args.task, "--grid", "force_limit_n=0.5:3")
        say_next(f"{tune} (the force limit to deploy with), then the rehearsal (docs/rehearsal-and-reports.md)")
    return status


def _beside_expert(
    args: argparse.Namespace, trials: list[Trial], kwargs: dict[str, Any], out: Path, jobs: int
) -> list[dict[str, Any]] | None:
    """With ``--beside-expert``, the scripted expert's episodes of the same trials (None without it, or when the
    policy is the expert already)."""
    if not args.beside_expert:
        return None
    if args.policy == EXPERT:
        print(f"--beside-expert: the policy is the {EXPERT} expert already; no second pass")
        return None
    from tissue_retract.workers import ROBUSTNESS_WORKER  # the simulation: as in run

    return run_trials(
        trials,
        ROBUSTNESS_WORKER,
        store=EpisodeStore(out / EXPERT_EPISODES),
        backend=args.backend,
        jobs=jobs,
        worker_kwargs={**kwargs, "policy": EXPERT, "allow_other_task": False},
        show_progress=not args.no_progress,
    )
