"""``tissue-retract evaluate``: success rate, forces and failure classes of a policy on a task.

POLICY is ``scripted`` (the rule-based expert), ``random``, ``module:callable`` (a callable taking the
observation dict and returning an action) or a checkpoint path (loaded by ``policies.checkpoint``).
Episode seeds are ``S * 100000 + i`` for each ``--seeds`` S and episode i. Every action goes through
the control chain; ``--safety-config FILE`` (TOML/YAML, as ``tissue-retract safety show``) sets its
limits, for example ``force_limit_n``; ``--no-safety`` is the ablation without the filter.

``--blind`` evaluates the policy as a robot with no perception stack runs it (``deploy --site``): its
observation carries a site registered ``--registration-error-mm`` (default 2) from the true one in a random
direction, the episode's goal, a grasp sensed by the jaw stalling on the flap and a site that moves with the
jaws (:class:`hardware_if.registered_env.RegisteredTask`); success is still the true site's distance. The
scripted expert reads the simulation itself, so ``--blind`` is for checkpoints and ``module:callable``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

import sim.envs
from hardware_if.registered_env import RegisteredTask
from policies.resolve import resolve_policy
from psm_control.inputs import check_output_path
from safety.config import load_safety_config
from sim.evaluation import (
    EpisodeResult,
    PolicyError,
    describe_exceedances,
    describe_stalls,
    run_episode,
    summarize,
    timed,
)
from sim.scene_stream import LiveScene, StreamScene
from tissue_retract.cli._blind import add_blind_arguments
from tissue_retract.cli._checks import MAX_EPISODES, MAX_SEED, int_in
from tissue_retract.cli._live import add_live_argument

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the subcommand to its parser."""
    parser.add_argument("--policy", required=True, help="scripted, random, module:callable or a checkpoint path")
    parser.add_argument("--task", default="multisite", help="lift, target, multisite, expose (or 1-3, a Gym id)")
    parser.add_argument("--episodes", type=int_in(1, MAX_EPISODES), default=50, help="episodes per seed (default: 50)")
    parser.add_argument(
        "--seeds", type=int_in(0, MAX_SEED), nargs="+", default=[1, 2, 3], help=f"seeds 0-{MAX_SEED} (default: 1 2 3)"
    )
    parser.add_argument("--no-safety", action="store_true", help="ablation: run without the safety filter")
    parser.add_argument(
        "--safety-config", metavar="FILE", default=None, help="control chain settings (.toml/.yaml), e.g. force_limit_n"
    )
    parser.add_argument("--json", metavar="FILE", default=None, help="write {summary, episodes} as JSON")
    add_blind_arguments(
        parser,
        blind_help="observe a registered site and a jaw-sensed grasp instead of the simulation's truth",
        default_mm=2.0,
        error_help="the registered site's distance from the true one",
    )
    add_live_argument(parser)
    parser.add_argument(
        "--allow-other-task", action="store_true", help="run a checkpoint trained for another task (same spaces)"
    )


def write_json(path: Path, data: Any) -> None:
    """Write JSON atomically: a crash leaves the old file or none, never half a file."""
    fd, temporary = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as handle:
            json.dump(data, handle, indent=2)
        os.replace(temporary, path)
    finally:
        if os.path.exists(temporary):
            os.unlink(temporary)


def run(args: argparse.Namespace) -> int:
    """Evaluate and print a table."""
    output = None
    if args.json:
        output = check_output_path(args.json, "--json", (args.policy, args.safety_config))
    safety_config = None
    if args.safety_config is not None:
        safety_config = load_safety_config(args.safety_config)
    console = Console(width=110)
    if args.no_safety:
        console.print("[bold red]ABLATION: safety filter OFF[/] - commands reach the joints unfiltered")
    env = sim.envs.make(args.task, safety=not args.no_safety, safety_config=safety_config)
    if args.blind:
        env = RegisteredTask(env, registration_error_m=args.registration_error_mm / 1000.0)
    live = None
    if args.live is not None:
        live = LiveScene(port=args.live)
        env = StreamScene(env, [live], realtime=True)
        print(f"live: ws://127.0.0.1:{live.port} (open it in the Foxglove app)", flush=True)
    results: list[EpisodeResult] = []
    failure: PolicyError | None = None
    try:
        policy, reset = resolve_policy(args.policy, env, allow_other_task=args.allow_other_task)
        seeds = [s * 100000 + i for s in args.seeds for i in range(args.episodes)]

        def episodes() -> None:
            nonlocal failure
            for seed in seeds:
                try:
                    results.append(run_episode(env, policy, reset, seed))
                except PolicyError as e:
                    failure = e
                    return

        _, elapsed = timed(episodes)
        controller = env.unwrapped.controller_name
        force_limit_n = env.unwrapped.controller.config.effective_force_limit_n
    finally:
        env.close()
        if live is not None:
            live.close()
    if failure is not None:
        if output is not None:
            write_json(
                output,
                {"policy_error": str(failure), "episodes": [r.to_dict() for r in results]},
            )
        kept = f"; the {len(results)} episodes before it are in {output}" if output is not None else ""
        print(f"tissue-retract evaluate: error: policy error: {failure}{kept}", file=sys.stderr)
        return 1
    summary = summarize(results, elapsed)
    summary.update(
        task=sim.envs.gym_id(args.task),
        policy=args.policy,
        seeds=args.seeds,
        controller=controller,
        safety=not args.no_safety,
        force_limit_n=force_limit_n,
        blind=args.blind,
    )
    if args.blind:
        summary["registration_error_mm"] = args.registration_error_mm
    blind = f", blind: site registered {args.registration_error_mm:g} mm off" if args.blind else ""
    table = Table(title=f"{args.policy} on {summary['task']} ({summary['episodes']} episodes, {controller}{blind})")
    table.add_column("metric")
    table.add_column("value", justify="right")
    table.add_row("success rate", f"{summary['success_rate']:.3f} +- {summary['ci95']:.3f}")
    limit = f" (limit {force_limit_n:g} N{'' if summary['safety'] else ', NOT enforced'})"
    table.add_row("peak force [N]", f"{summary['peak_force_n']:.3f}{limit}")
    table.add_row("mean peak force [N]", f"{summary['mean_peak_force_n']:.3f}")
    table.add_row("force limit exceeded", describe_exceedances(summary))
    table.add_row("force limit stalled retraction", describe_stalls(summary))
    for key in ("grip_losses", "tissue_damage", "sim_unstable", "safety_stops", "invalid_actions", "interventions"):
        table.add_row(key, str(summary[key]))
    table.add_row("joint limit violations", str(summary["joint_limit_violations"]))
    table.add_row("workspace violation [mm]", f"{summary['workspace_violation_mm']:.2f}")
    table.add_row("min insertion margin [mm]", f"{1000 * summary['min_insertion_margin_m']:.1f}")
    for name, count in summary["failure_classes"].items():
        table.add_row(f"failure: {name}", str(count))
    table.add_row("env steps/s", f"{summary['env_steps_per_s']:.0f}")
    console.print(table)
    if output is not None:
        write_json(output, {"summary": summary, "episodes": [r.to_dict() for r in results]})
    return 0
