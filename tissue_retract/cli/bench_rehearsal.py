"""``tissue-retract bench rehearsal``: the shipped policy deployed through ROS beside the same policy in-process.

The rehearsal a user runs before the robot is ``deploy --target dvrk`` against ``sim-dvrk``; it must succeed
as often as the simulation says the policy does. For each task and each way the deploy learns the task
state, this bench starts its own ``sim-dvrk`` on a loopback domain of its own, deploys the shipped policy
through it as a user would (separate processes, real DDS), and evaluates the same policy in-process on the
same seeds with the force the console senses (``--force-sensing dvrk``, as ``sim-dvrk`` serves by default):

- ``topics``: ``sim-dvrk --task T`` and ``deploy --task-topics``, one run of all the episodes (the console
  resets its scene for each). In-process: the true site.
- ``blind``: ``sim-dvrk --task T --blind`` and ``deploy --site X Y Z --goal X Y Z`` with the site and goal it
  printed, one console per episode (a registration is of one scene). In-process: ``--blind
  --registration-error-mm 0``.
- ``camera``: ``sim-dvrk --task T --blind --endoscope`` and ``deploy --perception camera --goal X Y Z
  --camera-site NAME`` with the goal and site it printed, one console per episode (the camera sees the
  site; the jaw, stalled on the held flap, tells the grasp). In-process: ``--perception camera``.

Every episode is scored on the console's ground truth, not on what the deploy estimated: with task topics,
the goal distance the deploy read from them at the episode's end (they are the console's truth); blind and
with the camera, the last line of ``sim-dvrk --truth`` (the deploy ended with the episode). The peak true
force is the largest of ``sim-dvrk --truth`` over the episode's scene. Beside the success and its Wilson
interval it prints the goal distance of each episode, the peak true force, the policy's step period and the
age of the newest ``measured_js`` at each control tick (p50/p99, from the deploy's recording) and the holds.
It exits 1 when a row's ROS success falls below the in-process 95 % interval.

SIGINT, SIGTERM or SIGHUP (even when it inherited SIGINT ignored, as a script's ``&`` job does) stops the
running deploy, then its console, removes the bench's temporary folder, says so in one line and exits with
128 + the signal (130, 143, 129); the consoles and deploys end with the bench even when it is killed
(:class:`sim.sweep.stopping.ChildProcesses`), so none is left serving the domain.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from subprocess import PIPE
from typing import Any

import gymnasium as gym
import numpy as np

from safety.config import load_safety_config
from sim.strict_json import write_strict_json
from sim.success_interval import describe_success, wilson_interval
from sim.sweep.stopping import ChildProcesses
from tissue_retract.cli._checks import float_in, int_in
from tissue_retract.cli._ros import add_bench_domain_argument, bench_domain_id

__all__ = ["MODES", "add_arguments", "run"]

#: How the deploy learns the task state, and what the in-process evaluation does the same with.
MODES = {
    "topics": "task topics / true site",
    "blind": "registered site / --blind",
    "camera": "--perception camera",
}
TASKS = ("lift", "target", "multisite")
#: Force sensing the simulated console serves by default, and so the in-process evaluation's.
SENSING = "dvrk"
#: Longest a deploy process may take per episode before the bench gives up on it [s].
_DEPLOY_S_PER_EPISODE = 120.0
#: Longest wait for sim-dvrk's start-up lines [s].
_STARTUP_S = 120.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the rehearsal target."""
    parser.add_argument("--episodes", type=int_in(1, 1000), default=20, help="episodes per task and mode (default 20)")
    parser.add_argument("--tasks", nargs="+", choices=TASKS, default=list(TASKS), help="tasks (default: all three)")
    parser.add_argument(
        "--modes", nargs="+", choices=tuple(MODES), default=list(MODES), help="task-state sources (default: all)"
    )
    parser.add_argument(
        "--seed", type=int_in(0, 2**31 - 2000), default=7400, help="first episode's seed (default 7400)"
    )
    add_bench_domain_argument(parser)
    parser.add_argument(
        "--safety-config", metavar="FILE", default=None, help="a safety configuration for the deploys (TOML/YAML)"
    )
    parser.add_argument(
        "--policy-budget",
        type=float_in(0.0, 3600.0, open_low=True),
        default=None,
        metavar="SECONDS",
        help="the deploys' longest policy step before the arm is held (default: one policy period, as deploy's)",
    )


class _TrueDistance(gym.Wrapper):
    """Keeps the true goal distance of the last observation (innermost: before any estimate replaces it)."""

    distance_m = float("nan")

    def _keep(self, observation: dict[str, np.ndarray]) -> None:
        self.distance_m = float(np.linalg.norm(observation["achieved_goal"] - observation["desired_goal"]))

    def reset(self, **kwargs: Any) -> Any:
        observation, info = self.env.reset(**kwargs)
        self._keep(observation)
        return observation, info

    def step(self, action: Any) -> Any:
        observation, *rest = self.env.step(action)
        self._keep(observation)
        return (observation, *rest)


def _in_process(task: str, mode: str, seeds: Sequence[int]) -> list[dict[str, Any]]:
    """The shipped policy in-process on ``seeds``, sensing as the console does."""
    import sim.envs
    from hardware_if.client.perceived_env import PerceivedTask
    from hardware_if.client.registered_env import RegisteredTask
    from policies.perception import load_site_estimator
    from policies.resolve import resolve_policy
    from sim.evaluation import run_episode

    truth = _TrueDistance(sim.envs.make(task, force_sensing=SENSING))
    env: Any = truth
    if mode == "blind":
        env = RegisteredTask(env, registration_error_m=0.0)
    elif mode == "camera":
        env = PerceivedTask(env, load_site_estimator(None))
    episodes = []
    try:
        policy, reset = resolve_policy("pretrained", env)
        for seed in seeds:
            result = run_episode(env, policy, reset, seed)
            episodes.append(
                {
                    "seed": seed,
                    "success": bool(result.success),
                    "goal_distance_mm": 1000.0 * truth.distance_m,
                    "peak_true_force_n": float(result.peak_force_n),
                }
            )
    finally:
        env.close()
    return episodes


class _Console:
    """A ``sim-dvrk`` child process on the run's domain, writing its ground truth to a file."""

    def __init__(self, children: ChildProcesses, task: str, seed: int, extra: Sequence[str] = ()) -> None:
        self.children = children
        self.truth = children.folder / f"truth-{seed}.jsonl"
        self.log = (children.folder / f"sim-dvrk-{seed}.log").open("w")
        command = [sys.executable, "-m", "tissue_retract", "sim-dvrk", "--task", task, "--seed", str(seed)]
        command += ["--domain-id", os.environ["ROS_DOMAIN_ID"], "--truth", str(self.truth), *extra]
        self.process = children.start("sim-dvrk", command, stdout=PIPE, stderr=self.log, text=True)

    def printed(self, name: str) -> list[str]:
        """The numbers of the start-up line ``<name>: X Y Z`` (waits for it; sim-dvrk prints it before serving)."""
        for line in self.process.stdout or ():
            if line.startswith(f"{name}: "):
                return line.split()[1:4]
        raise RuntimeError(f"sim-dvrk ended before it printed its {name} (see {self.log.name})")

    def camera_site(self) -> str:
        """The flap's site the episode grasps, from the start-up line ``for a deploy: ... --camera-site NAME``."""
        for line in self.process.stdout or ():
            if line.startswith("for a deploy: "):
                words = line.split()
                return words[words.index("--camera-site") + 1]
        raise RuntimeError(f"sim-dvrk ended before it printed the deploy's arguments (see {self.log.name})")

    def stop(self) -> list[dict[str, Any]]:
        """Stop it (Ctrl-C) and return its ground truth, a line per policy period."""
        self.children.stop(self.process, signal.SIGINT)
        self.log.close()
        if not self.truth.is_file():
            return []
        return [json.loads(line) for line in self.truth.read_text().splitlines() if line.strip()]


def _deploy(
    children: ChildProcesses, task: str, seed: int, episodes: int, record: Path, args: argparse.Namespace, *extra: str
) -> str:
    """Run ``deploy --target dvrk`` of the shipped policy to its end; what it printed."""
    command = [sys.executable, "-m", "tissue_retract", "deploy", "--policy", "pretrained", "--target", "dvrk"]
    command += ["--task", task, "--episodes", str(episodes), "--seed", str(seed), "--record", str(record)]
    command += ["--domain-id", os.environ["ROS_DOMAIN_ID"], "--wait", "60", *extra]
    if args.safety_config is not None:
        command += ["--safety-config", args.safety_config]
    if args.policy_budget is not None:
        command += ["--policy-budget", str(args.policy_budget)]
    done = children.run("deploy", command, timeout_s=60.0 + _DEPLOY_S_PER_EPISODE * episodes)
    return done.stdout + done.stderr


def _episodes_from_truth(truth: list[dict[str, Any]], seeds: Sequence[int], threshold_m: float) -> list[dict[str, Any]]:
    """Per seed: the goal distance at the last line of its scene, its peak true force."""
    episodes: list[dict[str, Any]] = []
    for seed in seeds:
        lines = [line for line in truth if line.get("seed") == seed]
        if not lines:
            episodes.append({"seed": seed, "success": False, "goal_distance_mm": None, "peak_true_force_n": None})
            continue
        distance = float(lines[-1]["distance_m"])
        episodes.append(
            {
                "seed": seed,
                "success": distance <= threshold_m,
                "goal_distance_mm": 1000.0 * distance,
                "peak_true_force_n": max(float(line["force_n"]) for line in lines),
            }
        )
    return episodes


def _episode_ends(record: Path) -> dict[int, dict[str, Any]]:
    """The deploy's ``episode_end`` events by seed (success and goal distance as the deploy judged them)."""
    from hardware_if.recording.recorder import read_recording

    if not record.is_file():
        return {}
    return {
        int(payload["seed"]): payload
        for topic, _t, payload in read_recording(record).messages
        if topic == "/deploy/event" and payload.get("kind") == "episode_end"
    }


def _timing(record: Path) -> dict[str, list[Any]]:
    """The policy step periods and the ``measured_js`` ages at each control tick of a deploy's recording [s]."""
    from hardware_if.recording.recorder import read_recording

    steps: list[float] = []
    ages: list[float] = []
    holds: list[Any] = []
    if not record.is_file():
        return {"step_period_s": steps, "measured_age_s": ages, "holds": holds}
    last_action: tuple[int, float] | None = None
    for topic, t, payload in read_recording(record).messages:
        if topic == "/deploy/action":
            episode = int(payload["episode"])
            if last_action is not None and last_action[0] == episode:
                steps.append(t - last_action[1])
            last_action = (episode, t)
        elif topic == "/deploy/measured" and payload.get("stamp_s") is not None:
            ages.append(t - float(payload["stamp_s"]))
        elif topic == "/deploy/event" and payload.get("kind") == "hold":
            holds.append(str(payload.get("text", "")))  # the hold event says why in its text
    return {"step_period_s": steps, "measured_age_s": ages, "holds": holds}


def _ros(
    task: str, mode: str, seeds: Sequence[int], children: ChildProcesses, args: argparse.Namespace
) -> dict[str, Any]:
    """The shipped policy deployed through ROS against sim-dvrk on ``seeds``, scored on the console's truth.

    A stop signal or an error leaves the console and the deploy running to ``children``, which stops the
    deploy before its console.
    """
    import sim.envs

    folder = children.folder
    threshold_m = sim.envs.make(task).unwrapped.config.success_threshold_m
    timing: dict[str, list[Any]] = {"step_period_s": [], "measured_age_s": [], "holds": []}
    episodes: list[dict[str, Any]] = []
    outputs: list[str] = []

    def deployed(record: Path, output: str) -> None:
        outputs.append(output)
        for key, values in _timing(record).items():
            timing[key].extend(values)

    if mode == "topics":
        console = _Console(children, task, seeds[0])
        record = folder / f"{task}-{mode}.mcap"
        output = _deploy(children, task, seeds[0], len(seeds), record, args, "--task-topics")
        truth = console.stop()
        deployed(record, output)
        ends = _episode_ends(record)  # the task topics at each episode's end: the console's truth then
        for episode in _episodes_from_truth(truth, seeds, threshold_m):
            end = ends.get(episode["seed"])
            distance = None if end is None or end.get("goal_distance_m") is None else float(end["goal_distance_m"])
            episode["success"] = distance is not None and distance <= threshold_m
            episode["goal_distance_mm"] = None if distance is None else 1000.0 * distance
            episodes.append(episode)
    else:
        for seed in seeds:
            # A camera sees the site but not the grasp: the jaw tells it, as a real one stalled on tissue (--blind).
            extra = ["--blind"] if mode == "blind" else ["--blind", "--endoscope"]
            console = _Console(children, task, seed, extra)
            record = folder / f"{task}-{mode}-{seed}.mcap"
            # The goal is the scene's, given as the in-process episode is given it (PerceivedTask and
            # RegisteredTask take the episode's goal); only the site is registered or seen.
            site, goal = console.printed("site"), console.printed("goal")
            if mode == "blind":
                output = _deploy(children, task, seed, 1, record, args, "--site", *site, "--goal", *goal)
            else:
                named = ("--camera-site", console.camera_site())  # MultiSite grasps another site each episode
                output = _deploy(
                    children, task, seed, 1, record, args, "--perception", "camera", "--goal", *goal, *named
                )
            truth = console.stop()
            deployed(record, output)
            episodes += _episodes_from_truth(truth, [seed], threshold_m)
    return {"episodes": episodes, **timing, "output_tail": [o.strip().splitlines()[-3:] for o in outputs if o.strip()]}


def _percentiles_ms(values: Sequence[float]) -> str:
    """``p50/p99/max`` in milliseconds."""
    if not values:
        return "-"
    p50, p99, top = np.percentile(np.asarray(values, dtype=float), [50, 99, 100])
    return f"{1000 * p50:.0f}/{1000 * p99:.0f}/{1000 * top:.0f}"


def _successes(episodes: Sequence[dict[str, Any]]) -> int:
    return sum(bool(e["success"]) for e in episodes)


def _distances(episodes: Sequence[dict[str, Any]]) -> str:
    return " ".join("-" if e["goal_distance_mm"] is None else f"{e['goal_distance_mm']:.1f}" for e in episodes)


def _peak(episodes: Sequence[dict[str, Any]]) -> float:
    peaks = [e["peak_true_force_n"] for e in episodes if e["peak_true_force_n"] is not None]
    return max(peaks) if peaks else float("nan")


def run(args: argparse.Namespace) -> int:
    """Deploy through ROS and evaluate in-process per task and mode; print both; 1 when ROS falls short."""
    if args.safety_config is not None:  # refused here, before sim-dvrk starts, not by each deploy it starts
        load_safety_config(args.safety_config)
    domain_id = bench_domain_id(args)
    seeds = [args.seed + k for k in range(args.episodes)]
    rows = []
    short = []
    print(
        f"bench rehearsal: {args.episodes} episode(s) per row, seeds {seeds[0]}-{seeds[-1]}, "
        f"ROS_DOMAIN_ID={domain_id} (loopback), force sensing {SENSING}",
        flush=True,
    )
    with ChildProcesses("bench rehearsal", folder_prefix="rehearsal-") as children:
        for task in args.tasks:
            for mode in args.modes:
                ros = _ros(task, mode, seeds, children, args)
                local = _in_process(task, mode, seeds)
                ros_k, local_k = _successes(ros["episodes"]), _successes(local)
                low, _high = wilson_interval(local_k, len(local))
                below = ros_k / len(seeds) < low
                agree = sum(a["success"] == b["success"] for a, b in zip(ros["episodes"], local, strict=True))
                row = {
                    "task": task,
                    "mode": mode,
                    "ros": ros,
                    "in_process": {"episodes": local},
                    "ros_successes": ros_k,
                    "in_process_successes": local_k,
                    "in_process_interval": [low, _high],
                    "episodes_agreeing": agree,
                    "ros_below_in_process_interval": below,
                }
                rows.append(row)
                if below:
                    short.append(f"{task}/{mode}")
                print(f"\n{task} / {MODES[mode]}", flush=True)
                print(f"  ROS        success {describe_success(ros_k, len(seeds))}", flush=True)
                print(f"  in-process success {describe_success(local_k, len(local))}", flush=True)
                print(f"  episodes agreeing on success: {agree} of {len(seeds)}")
                print(f"  ROS goal distance [mm]:        {_distances(ros['episodes'])}")
                print(f"  in-process goal distance [mm]: {_distances(local)}")
                print(f"  peak true force [N]: ROS {_peak(ros['episodes']):.3f}, in-process {_peak(local):.3f}")
                print(
                    f"  ROS policy step period p50/p99/max [ms]: {_percentiles_ms(ros['step_period_s'])}; "
                    f"measured_js age at each tick p50/p99/max [ms]: {_percentiles_ms(ros['measured_age_s'])}"
                )
                print(f"  holds: {len(ros['holds'])}{': ' + '; '.join(ros['holds']) if ros['holds'] else ''}")
    verdict = (
        f"ROS success below the in-process 95 % interval: {', '.join(short)}"
        if short
        else "ROS success within or above the in-process 95 % interval in every row"
    )
    print(f"\n{verdict}")
    if args.json:
        write_strict_json(
            Path(args.json),
            {
                "benchmark": "rehearsal: deploy --target dvrk against sim-dvrk beside the same policy in-process",
                "machine": {"cpus": os.cpu_count(), "python": sys.version.split()[0]},
                "seeds": seeds,
                "force_sensing": SENSING,
                "rows": rows,
                "ok": not short,
            },
        )
    return 1 if short else 0
