"""``tissue-retract bench safety``: the force bound against adversarial and shipped policies.

Every policy of :data:`POLICIES` (three adversaries: ``AggressivePull``, ``random`` and ``SignFlipPull``;
the scripted expert; the shipped policy) runs on Tasks I-III, under every force preset, on the flap at
0.3, 1 and 3 times its nominal Young's modulus, ``--episodes`` episodes each on seeds ``--seed`` x 100000
on (not those the filter was developed on). It prints the worst peak force over the limit per policy and
overall against the bound (1.10), and the expert's and shipped policies' success with the filter on and
off (``--no-safety``) at the generic preset. ``--force-sensing`` gives the filter the force a dVRK senses
(:mod:`sim.force_sensing`); the peak is always the true force's, and the environments declare the whole
0.3-3 x E range as the tissue the filter must expect. With an inexact force it also holds the true force
against the force bound's travel bound (:mod:`safety.force_bound`) while that was in force: the largest
ratio says how near the tissue came to its stiffness and held-load bounds (above 1, beyond them). Episodes
on a flap the solver broke while settling (stiff flaps, see docs/simulation.md) end at once as unstable and
are counted, not scored. Exit status 0 when the bound held, 1 when it did not.
"""

from __future__ import annotations

import argparse
import os
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

from sim.strict_json import write_strict_json
from sim.sweep.stopping import pool_worker_start, stop_pool
from tissue_retract.cli._checks import int_in
from tissue_retract.cli._sensing import add_force_sensing_argument

__all__ = ["BOUND", "POLICIES", "STIFFNESS_SCALES", "TASKS", "add_arguments", "run"]

#: The promised bound on peak force over the limit.
BOUND = 1.10
POLICIES = ("sim.pulling:AggressivePull", "random", "sim.pulling:SignFlipPull", "scripted", "pretrained")
TASKS = ("lift", "target", "multisite")
STIFFNESS_SCALES = (0.3, 1.0, 3.0)
#: Policies whose success with the filter on is compared with --no-safety.
_COMPARED = ("scripted", "pretrained")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the safety target."""
    parser.add_argument("--episodes", type=int_in(1, 100), default=3, help="episodes per cell (default 3)")
    parser.add_argument(
        "--seed", type=int_in(0, 20000), default=91, help="seed block: seeds SEED x 100000 on (default 91)"
    )
    parser.add_argument(
        "--jobs", type=int_in(1, 64), default=os.cpu_count() or 1, help="worker processes (default all cores)"
    )
    add_force_sensing_argument(parser)


def _cell_group(
    task: str, preset: str, safety: bool, policies: tuple[str, ...], episodes: int, seed: int, sensing: str
) -> list:
    """Every policy, stiffness and episode of one task and preset, in one environment."""
    import sim.envs
    from policies.resolve import resolve_policy
    from safety.config import SafetyConfig
    from sim.evaluation import run_episode
    from sim.robustness import sweep_ranges
    from sim.tissue import TissueParams

    nominal_kpa = TissueParams().youngs_modulus_kpa
    declared = sweep_ranges([("stiffness", min(STIFFNESS_SCALES), max(STIFFNESS_SCALES), True)])
    env = sim.envs.make(
        task, safety=safety, safety_config=SafetyConfig(tissue=preset), force_sensing=sensing, randomization=declared
    )
    rows = []
    try:
        for policy in policies:
            act, reset = resolve_policy(policy, env)
            for scale in STIFFNESS_SCALES:
                for i in range(episodes):
                    episode_seed = seed * 100000 + i
                    options = {"tissue_youngs_modulus_kpa": nominal_kpa * scale}
                    result = run_episode(env, act, reset, episode_seed, options)
                    rows.append(
                        {
                            "task": task,
                            "preset": preset,
                            "safety": safety,
                            "policy": policy,
                            "stiffness": scale,
                            "seed": episode_seed,
                            "success": result.success,
                            "unstable": result.sim_unstable,
                            "peak_force_n": result.peak_force_n,
                            "peak_measured_force_n": result.peak_measured_force_n,
                            "force_limit_n": result.force_limit_n,
                            "ratio": result.peak_force_n / result.force_limit_n,
                            "force_limit_exceeded": len(result.force_limit_exceeded),
                            "force_over_travel_bound": result.peak_force_over_travel_bound,
                        }
                    )
    finally:
        env.close()
    return rows


def _where(row: dict[str, Any]) -> str:
    return f"{row['task']}, {row['preset']} ({row['force_limit_n']:g} N), {row['stiffness']:g} x E, seed {row['seed']}"


def _worst_over_travel_bound(rows: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The episode whose true force came nearest its travel bound (None: the bound was never in force)."""
    bounded = [r for r in rows if r["force_over_travel_bound"] is not None]
    return max(bounded, key=lambda r: r["force_over_travel_bound"]) if bounded else None


def run(args: argparse.Namespace) -> int:
    """Run the matrix, print the tables, return 0 when the bound held."""
    from safety.config import FORCE_PRESETS

    groups: list[tuple[str, str, bool, tuple[str, ...]]] = [
        (t, p, True, POLICIES) for t in TASKS for p in FORCE_PRESETS
    ]
    groups += [(t, "generic", False, _COMPARED) for t in TASKS]
    rows: list[dict[str, Any]] = []
    with ProcessPoolExecutor(max_workers=min(args.jobs, len(groups)), initializer=pool_worker_start) as pool:
        futures = [pool.submit(_cell_group, *g, args.episodes, args.seed, args.force_sensing) for g in groups]
        try:
            for future in futures:
                rows += future.result()
        except KeyboardInterrupt:  # a stop signal: the workers end now (they leave stopping to this process)
            stop_pool(pool)
            raise
    filtered = [r for r in rows if r["safety"] and not r["unstable"]]
    console = Console(width=150)
    table = Table(
        title=f"force bound: true peak / limit over {len(filtered)} episodes with the filter on (bound {BOUND}), "
        f"{args.force_sensing} force sensing"
    )
    travel_column = "true force / travel bound"
    for column in ("policy", "episodes", "unstable", "exceedances", "worst peak / limit", "where", travel_column):
        table.add_column(column, justify="left" if column in ("policy", "where") else "right")
    for policy in POLICIES:
        mine = [r for r in filtered if r["policy"] == policy]
        unstable = sum(r["unstable"] for r in rows if r["safety"] and r["policy"] == policy)
        worst = max(mine, key=lambda r: r["ratio"])
        travel = _worst_over_travel_bound(mine)
        table.add_row(
            policy,
            str(len(mine)),
            str(unstable),
            str(sum(r["force_limit_exceeded"] for r in mine)),
            f"{worst['ratio']:.3f}",
            _where(worst) + f": {worst['peak_force_n']:.3f} N",
            "-" if travel is None else f"{travel['force_over_travel_bound']:.3f}",
        )
    console.print(table)
    success = Table(title="success at the generic preset, filter on / --no-safety (episodes on a broken flap left out)")
    for column in ("policy", *TASKS, "all"):
        success.add_column(column, justify="left" if column == "policy" else "right")
    for policy in _COMPARED:
        cells = []
        for task in (*TASKS, None):
            pair = []
            for safety in (True, False):
                mine = [
                    r
                    for r in rows
                    if r["policy"] == policy
                    and r["preset"] == "generic"
                    and r["safety"] is safety
                    and not r["unstable"]
                    and (task is None or r["task"] == task)
                ]
                pair.append(100.0 * sum(r["success"] for r in mine) / len(mine))
            cells.append(f"{pair[0]:.0f} / {pair[1]:.0f} %")
        success.add_row(policy, *cells)
    console.print(success)
    overall = max(filtered, key=lambda r: r["ratio"])
    held = overall["ratio"] <= BOUND
    print(f"worst peak / limit {overall['ratio']:.3f}: the bound {BOUND} {'held' if held else 'did NOT hold'}")
    travel = _worst_over_travel_bound(filtered)
    if travel is not None:
        ratio = travel["force_over_travel_bound"]
        verdict = "the tissue bounds held" if ratio <= 1.0 else "the tissue was stiffer or heavier than its bounds"
        print(f"worst true force / travel bound {ratio:.3f} ({travel['policy']}, {_where(travel)}): {verdict}")
    if args.json:
        document = {
            "bound": BOUND,
            "force_sensing": args.force_sensing,
            "worst_peak_over_limit": overall["ratio"],
            "worst_force_over_travel_bound": None if travel is None else travel["force_over_travel_bound"],
            "episodes": rows,
        }
        write_strict_json(Path(args.json), document, indent=1, field="--json")
    return 0 if held else 1
