"""``tissue-retract evaluate``: success rate, forces and failure classes of a policy on a task.

POLICY is ``scripted`` (the rule-based expert), ``random``, ``module:callable`` (a callable taking the
observation dict and returning an action) or a checkpoint path (loaded by ``policies.checkpoint``).
``--episodes N`` is the total: episode k runs on seed ``S * 100000 + k // len(seeds)`` with S the
``k % len(seeds)``-th of ``--seeds`` (with one seed S, episodes ``S * 100000 + 0 .. N - 1``). Progress goes
to stderr as episodes finish; Ctrl-C stops after the running episode and still writes ``--json`` with the
episodes that finished (``"interrupted": true``, exit 130; SIGTERM the same with exit 143). Every action goes through
the control chain; ``--safety-config FILE`` (TOML/YAML, as ``tissue-retract safety show``) sets its
limits, for example ``force_limit_n``; ``--no-safety`` is the ablation without the filter.

``--blind`` evaluates the policy as a robot with no perception stack runs it (``deploy --site``): its
observation carries a site registered ``--registration-error-mm`` (default 2) from the true one in a random
direction, the episode's goal, a grasp sensed by the jaw stalling on the flap and a site that moves with the
jaws (:class:`hardware_if.client.registered_env.RegisteredTask`); success is still the true site's distance. The
scripted expert reads the simulation itself, so ``--blind`` is for checkpoints and ``module:callable``.

``--perception camera[:MODEL]`` is ``--blind`` with the site estimated from the endoscope's stereo images at
each episode's start (:class:`hardware_if.client.perceived_env.PerceivedTask`); the summary gives the estimate's
error to the true site (``site_error_mm``: median, p95, max). ``--texture FILE.png`` puts an image on the
flap.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time

from rich.console import Console
from rich.table import Table
from rich.text import Text

from hardware_if.client.registered_env import RegisteredTask
from policies.resolve import POLICY_NAMES, resolve_policy
from psm_control.errors import ConfigurationError
from psm_control.inputs import check_output_path
from safety.config import load_safety_config
from safety.force_bound import sensing_warning
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
from sim.strict_json import write_strict_json
from sim.success_interval import describe_success
from tissue_retract.cli._blind import add_blind_arguments
from tissue_retract.cli._camera import (
    add_perception_argument,
    add_texture_argument,
    load_perception,
    texture_warning,
    tissue_params,
)
from tissue_retract.cli._checks import MAX_EPISODES, MAX_SEED, int_in
from tissue_retract.cli._live import add_live_argument
from tissue_retract.cli._next import command, say_next
from tissue_retract.cli._sensing import add_force_sensing_argument, announce

__all__ = ["add_arguments", "episode_seeds", "run"]

#: A progress line at least this often while episodes end [s] (and at the first, every 5 % and the last).
PROGRESS_PERIOD_S = 10.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the subcommand to its parser."""
    parser.add_argument("--policy", required=True, help=POLICY_NAMES)
    parser.add_argument("--task", default="multisite", help="lift, target, multisite, expose (or 1-3, a Gym id)")
    parser.add_argument(
        "--episodes",
        type=int_in(1, MAX_EPISODES),
        default=150,
        help="episodes in all, spread over --seeds in turn (default: 150)",
    )
    parser.add_argument(
        "--seeds",
        type=int_in(0, MAX_SEED),
        nargs="+",
        default=[1, 2, 3],
        help=f"seeds 0-{MAX_SEED} the episodes are spread over (default: 1 2 3)",
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
    add_perception_argument(parser)
    add_texture_argument(parser)
    add_live_argument(parser)
    add_force_sensing_argument(parser)
    parser.add_argument(
        "--allow-other-task", action="store_true", help="run a checkpoint trained for another task (same spaces)"
    )


def episode_seeds(seeds: list[int], episodes: int) -> list[int]:
    """The seeds of ``episodes`` episodes in all, taking ``seeds`` in turn (``S * 100000 + round``)."""
    return [seeds[k % len(seeds)] * 100000 + k // len(seeds) for k in range(episodes)]


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
    if args.blind and args.perception is not None:
        raise ConfigurationError("--perception", args.perception, "either --blind or --perception, not both")
    estimator = load_perception(args.perception)
    import sim.envs  # PyBullet: once the arguments and files are checked

    env = sim.envs.make(
        args.task,
        safety=not args.no_safety,
        safety_config=safety_config,
        tissue=tissue_params(args.texture),
        force_sensing=args.force_sensing,
    )
    sensing = sensing_warning(
        env.unwrapped.safety_config,
        f"{args.force_sensing} force sensing",
        calibrated=args.force_sensing == "dvrk-calibrated",
    )
    announce(sensing)
    unseen_texture = texture_warning(estimator, args.texture)
    announce(unseen_texture)
    if args.blind:
        env = RegisteredTask(env, registration_error_m=args.registration_error_mm / 1000.0)
    if estimator is not None:
        from hardware_if.client.perceived_env import PerceivedTask  # PyBullet's endoscope: with --perception

        env = PerceivedTask(env, estimator)
    live = None
    if args.live is not None:
        live = LiveScene(port=args.live)
        env = StreamScene(env, [live], realtime=True)
        print(f"live: ws://127.0.0.1:{live.port} (open it in the Foxglove app)", flush=True)
    results: list[EpisodeResult] = []
    failure: PolicyError | None = None
    interrupted = 0  # the exit status of a stop signal, 0 when none came
    try:
        policy, reset = resolve_policy(args.policy, env, allow_other_task=args.allow_other_task)
        seeds = episode_seeds(args.seeds, args.episodes)
        report_every = max(1, len(seeds) // 20)
        started = last_line_s = time.perf_counter()

        def episodes() -> None:
            # Ctrl-C may land anywhere in the loop, the progress line included: one handler for all of it.
            nonlocal failure, interrupted, last_line_s
            try:
                for seed in seeds:
                    try:
                        results.append(run_episode(env, policy, reset, seed))
                    except PolicyError as e:
                        failure = e
                        return
                    done, now = len(results), time.perf_counter()
                    if done in (1, len(seeds)) or done % report_every == 0 or now - last_line_s >= PROGRESS_PERIOD_S:
                        last_line_s = now
                        successes = sum(r.success for r in results)
                        print(
                            f"evaluate: {done}/{len(seeds)} episodes, {successes} successes, {now - started:.1f} s",
                            file=sys.stderr,
                            flush=True,
                        )
            except KeyboardInterrupt as e:
                interrupted = 128 + int(getattr(e, "signum", signal.SIGINT))  # 130 for Ctrl-C, 143 for SIGTERM

        _, elapsed = timed(episodes)
        controller = env.unwrapped.controller_name
        force_limit_n = env.unwrapped.controller.config.effective_force_limit_n
    finally:
        env.close()
        if live is not None:
            live.close()
    if failure is not None:
        if output is not None:
            write_strict_json(
                output,
                {"policy_error": str(failure), "episodes": [r.to_dict() for r in results]},
                field="--json",
            )
        kept = f"; the {len(results)} episodes before it are in {output}" if output is not None else ""
        print(f"tissue-retract evaluate: error: policy error: {failure}{kept}", file=sys.stderr)
        return 1
    if interrupted and not results:
        print("tissue-retract evaluate: interrupted before the first episode ended", file=sys.stderr)
        return interrupted
    summary = summarize(results, elapsed)
    summary.update(
        task=sim.envs.gym_id(args.task),
        policy=args.policy,
        seeds=args.seeds,
        controller=controller,
        safety=not args.no_safety,
        force_limit_n=force_limit_n,
        blind=args.blind,
        force_sensing=args.force_sensing,
        force_sensing_error_n=env.unwrapped.safety_config.force_sensing_error_n,
        warnings=[warning for warning in (sensing, unseen_texture) if warning],
    )
    if args.blind:
        summary["registration_error_mm"] = args.registration_error_mm
    if args.perception is not None:
        summary.update(perception=args.perception, texture=args.texture)
    blind = f", blind: site registered {args.registration_error_mm:g} mm off" if args.blind else ""
    if args.perception is not None:
        blind = f", perception {args.perception}"
    if interrupted:
        summary["interrupted"] = True
    stopped = f", interrupted after {len(results)} of {len(seeds)}" if interrupted else ""
    table = Table(
        title=f"{args.policy} on {summary['task']} ({summary['episodes']} episodes{stopped}, {controller}{blind})"
    )

    def add_row(metric: str, value: str) -> None:
        table.add_row(Text(metric), Text(value))  # not markup: rich would take "[mm]" for a style tag

    table.add_column("metric")
    table.add_column("value", justify="right")
    add_row("success", describe_success(sum(r.success for r in results), len(results)))
    limit = f" (limit {force_limit_n:g} N{'' if summary['safety'] else ', NOT enforced'})"
    add_row("peak force [N]", f"{summary['peak_force_n']:.3f}{limit}")
    add_row("mean peak force [N]", f"{summary['mean_peak_force_n']:.3f}")
    if args.force_sensing != "ideal":
        add_row(f"peak sensed force [N] ({args.force_sensing})", f"{summary['peak_measured_force_n']:.3f}")
        add_row("force sensing error bound [N]", f"{summary['force_sensing_error_n']:.3f}")
        travel = summary["worst_force_over_travel_bound"]
        add_row("true force / travel bound", "never in force" if travel is None else f"at most {travel:.3f}")
    if "site_error_mm" in summary:
        error = summary["site_error_mm"]
        add_row("site error [mm]", f"median {error['median']:.2f}, p95 {error['p95']:.2f}, max {error['max']:.2f}")
        if "site_estimator" in summary:
            taken = ", ".join(f"{name} {count}" for name, count in summary["site_estimator"].items())
            add_row("site estimator taken (episodes)", taken)
    add_row("force limit exceeded", describe_exceedances(summary))
    add_row("force limit stalled retraction", describe_stalls(summary))
    for key in ("grip_losses", "tissue_damage", "sim_unstable", "safety_stops", "invalid_actions", "interventions"):
        add_row(key, str(summary[key]))
    add_row("joint limit violations", str(summary["joint_limit_violations"]))
    add_row("workspace violation [mm]", f"{summary['workspace_violation_mm']:.2f}")
    add_row("min insertion margin [mm]", f"{1000 * summary['min_insertion_margin_m']:.1f}")
    for name, count in summary["failure_classes"].items():
        add_row(f"failure: {name}", str(count))
    add_row("env steps/s", f"{summary['env_steps_per_s']:.0f}")
    console.print(table)
    if output is not None:
        write_strict_json(output, {"summary": summary, "episodes": [r.to_dict() for r in results]}, field="--json")
    if interrupted:
        kept = f"; the {len(results)} finished episodes are in {output}" if output is not None else ""
        print(f"tissue-retract evaluate: interrupted{kept}", file=sys.stderr)
        return interrupted
    vary = "stiffness=0.3:3x,size=0.8:1.2x"  # the tissue a task's flap stands for (docs/robustness.md)
    sweep = command("robustness", "--policy", args.policy, "--task", args.task, "--trials", "100", "--vary", vary)
    say_next(
        f"{sweep} (success and force over randomized tissue and timing) or tune-safety (the force limit), then "
        "the rehearsal against sim-dvrk (docs/rehearsal-and-reports.md)"
    )
    return 0
