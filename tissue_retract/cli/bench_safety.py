"""``tissue-retract bench safety``: the retraction-force bound over adversaries, tasks, presets and tissue.

Every policy (the adversaries ``aggressive`` = :class:`sim.pulling.AggressivePull`, ``random`` and
``signflip`` = :class:`sim.pulling.SignFlipPull`, and the shipped ``scripted`` expert and ``pretrained``
policies) runs on every task x every force preset x tissue stiffness 0.3x / 1x / 3x (the sampled spring
stiffness times the factor), with the safety filter on. It prints the worst peak/limit ratio (peak: the
largest force read at any control tick) per preset and per policy, the ``force_limit_exceeded`` events,
and, on a separate sample at the ``generic`` preset and 1x stiffness, the success of ``scripted`` and
``pretrained`` with the filter on against ``--no-safety``. ``pretrained`` is left out on tasks that ship
no policy (Expose).

Episode seeds are ``seed * 100000 + i``; each (task, preset, stiffness) cell gets its own ``i`` range, so
no two cells share an episode. ``--jobs N`` runs the cells in N processes.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

__all__ = ["POLICIES", "STIFFNESS_FACTORS", "add_arguments", "run"]

#: Bench policy name -> what ``policies.resolve.resolve_policy`` takes.
POLICIES: dict[str, str] = {
    "aggressive": "sim.pulling:AggressivePull",
    "random": "random",
    "signflip": "sim.pulling:SignFlipPull",
    "scripted": "scripted",
    "pretrained": "pretrained",
}
#: Tissue stiffness factors applied to the sampled spring stiffness.
STIFFNESS_FACTORS = (0.3, 1.0, 3.0)
_SHIPPED = ("scripted", "pretrained")
_STIFFNESS = "tissue_stiffness_n_per_m"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the target's options."""
    from safety.config import FORCE_PRESETS
    from sim.envs import TASKS

    parser.add_argument("--episodes", type=int, default=1, help="episodes per policy and cell (default: 1)")
    parser.add_argument(
        "--success-episodes",
        type=int,
        default=20,
        help="episodes per task for the filter-on vs --no-safety success comparison (default: 20; 0 skips it)",
    )
    parser.add_argument("--seed", type=int, default=51, help="seed block (default: 51)")
    parser.add_argument("--jobs", type=int, default=1, help="worker processes (default: 1)")
    parser.add_argument("--tasks", nargs="+", default=list(TASKS), help="tasks (default: all)")
    parser.add_argument("--presets", nargs="+", default=list(FORCE_PRESETS), help="force presets (default: all)")
    parser.add_argument("--policies", nargs="+", default=list(POLICIES), choices=list(POLICIES), help="policies")


def _cell(job: dict[str, Any]) -> list[dict[str, Any]]:
    """Run one (task, preset, safety) job over its policies and stiffness factors; one row per episode."""
    import numpy as np

    from policies.resolve import resolve_policy
    from psm_control.errors import UnknownVariantError
    from safety.config import SafetyConfig
    from sim.envs import make
    from sim.evaluation import run_episode

    env = make(job["task"], safety=job["safety"], safety_config=SafetyConfig(tissue=job["preset"]))
    rows = []
    try:
        low, high = env.unwrapped.randomizer.ranges[_STIFFNESS]
        for policy_name in job["policies"]:
            try:
                policy, reset = resolve_policy(POLICIES[policy_name], env)
            except UnknownVariantError:  # no shipped policy for this task (Expose)
                continue
            if policy_name == "random":
                env.action_space.seed(job["first_seed"])
            for k, factor in enumerate(job["factors"]):
                for i in range(job["episodes"]):
                    seed = job["first_seed"] + k * job["episodes"] + i
                    stiffness = factor * float(np.random.default_rng(seed).uniform(low, high))
                    result = run_episode(env, policy, reset, seed, options={_STIFFNESS: stiffness})
                    rows.append(
                        {
                            "task": job["task"],
                            "preset": job["preset"],
                            "safety": job["safety"],
                            "policy": policy_name,
                            "stiffness_factor": factor,
                            "seed": seed,
                            "success": result.success,
                            "peak_force_n": result.peak_force_n,
                            "force_limit_n": result.force_limit_n,
                            "ratio": result.peak_force_n / result.force_limit_n,
                            "force_limit_exceeded": result.force_limit_exceeded,
                            "max_force_excess_n": result.max_force_excess_n,
                            "safety_stops": result.safety_stops,
                        }
                    )
    finally:
        env.close()
    return rows


def _jobs(args: argparse.Namespace) -> list[dict[str, Any]]:
    base = args.seed * 100000
    jobs = []
    block = max(args.episodes * len(STIFFNESS_FACTORS), args.success_episodes)
    for n, (task, preset) in enumerate(itertools.product(args.tasks, args.presets)):
        jobs.append(
            {
                "task": task,
                "preset": preset,
                "safety": True,
                "policies": args.policies,
                "factors": STIFFNESS_FACTORS,
                "episodes": args.episodes,
                "first_seed": base + n * block,
            }
        )
    if args.success_episodes > 0:
        shipped = [p for p in args.policies if p in _SHIPPED]
        offset = len(jobs) * block
        for n, task in enumerate(args.tasks):
            for safety in (True, False):
                jobs.append(
                    {
                        "task": task,
                        "preset": "generic",
                        "safety": safety,
                        "policies": shipped,
                        "factors": (1.0,),
                        "episodes": args.success_episodes,
                        "first_seed": base + offset + n * block,
                        "comparison": True,
                    }
                )
    return jobs


def _run_job(job: dict[str, Any]) -> list[dict[str, Any]]:
    try:
        rows = _cell(job)
    except Exception as e:  # the project's errors do not pickle back from a worker process: say it here
        raise RuntimeError(f"{job['task']}, {job['preset']}, safety={job['safety']}: {type(e).__name__}: {e}") from None
    for row in rows:
        row["comparison"] = bool(job.get("comparison", False))
    return rows


def run(args: argparse.Namespace) -> int:
    """Run the matrix and print the worst ratios and the success comparison."""
    from psm_control.errors import ConfigurationError

    for name in ("episodes", "jobs"):
        if getattr(args, name) < 1:
            raise ConfigurationError(f"--{name}", getattr(args, name), "at least 1")
    if args.success_episodes < 0:
        raise ConfigurationError("--success-episodes", args.success_episodes, "0 or more")
    jobs = _jobs(args)
    start = time.perf_counter()
    if args.jobs == 1:
        chunks = [_run_job(job) for job in jobs]
    else:
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            chunks = list(pool.map(_run_job, jobs))
    elapsed = time.perf_counter() - start
    rows = [row for chunk in chunks for row in chunk]
    matrix = [r for r in rows if not r["comparison"]]
    results = _summarise(matrix, [r for r in rows if r["comparison"]])
    results.update(elapsed_s=elapsed, episodes=len(rows), seed=args.seed, jobs=args.jobs)
    _print(results, args)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"summary": results, "episodes": rows}, f, indent=2)
    return 0


def _worst(rows: list[dict[str, Any]]) -> dict[str, Any]:
    worst = max(rows, key=lambda r: r["ratio"])
    return {
        "ratio": worst["ratio"],
        "peak_force_n": worst["peak_force_n"],
        "where": f"{worst['policy']} on {worst['task']}, {worst['preset']}, {worst['stiffness_factor']:g}x, "
        f"seed {worst['seed']}",
        "episodes": len(rows),
        "force_limit_exceeded": sum(r["force_limit_exceeded"] for r in rows),
    }


def _summarise(matrix: list[dict[str, Any]], comparison: list[dict[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    if matrix:
        out["worst"] = _worst(matrix)
        for key in ("preset", "policy", "task", "stiffness_factor"):
            values = sorted({r[key] for r in matrix}, key=str)
            out[f"by_{key}"] = {str(v): _worst([r for r in matrix if r[key] == v]) for v in values}
    success: dict[str, dict[str, float]] = {}
    for policy in sorted({r["policy"] for r in comparison}):
        entry = {}
        for safety, label in ((True, "filter_on"), (False, "no_safety")):
            chosen = [r["success"] for r in comparison if r["policy"] == policy and r["safety"] == safety]
            entry[label] = sum(chosen) / len(chosen) if chosen else math.nan
            entry[f"{label}_episodes"] = len(chosen)
        entry["difference_points"] = 100 * (entry["filter_on"] - entry["no_safety"])
        success[policy] = entry
    out["success_generic"] = success
    return out


def _print(results: dict[str, Any], args: argparse.Namespace) -> None:
    if "worst" in results:
        worst = results["worst"]
        print(
            f"worst peak/limit {worst['ratio']:.3f} ({worst['peak_force_n']:.3f} N; {worst['where']}) over "
            f"{worst['episodes']} episodes; force_limit_exceeded events: {worst['force_limit_exceeded']}"
        )
        for key in ("preset", "policy", "stiffness_factor", "task"):
            print(f"by {key}:")
            for name, entry in results[f"by_{key}"].items():
                print(
                    f"  {name:>16}: worst {entry['ratio']:.3f} ({entry['where']}), "
                    f"exceeded {entry['force_limit_exceeded']} in {entry['episodes']} episodes"
                )
    for policy, entry in results["success_generic"].items():
        print(
            f"success at generic, 1x: {policy:>10} filter on {100 * entry['filter_on']:.1f} % "
            f"({entry['filter_on_episodes']} episodes), --no-safety {100 * entry['no_safety']:.1f} % "
            f"({entry['no_safety_episodes']}); difference {entry['difference_points']:+.1f} points"
        )
    print(f"{results['episodes']} episodes in {results['elapsed_s']:.0f} s with {args.jobs} job(s)")
