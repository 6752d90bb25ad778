"""``tissue-retract bench chain``: control-chain tick latency against a naive reference.

Both chains (IK + safety filter + Ruckig + verifier) run the same realistic input in the same process:
a kinematic backend (measured = last command, as the dVRK's KINEMATIC simulation), policy targets of a few
millimetres every 50 ms that pull a spring-like tissue (stiffness 300 N/m) against the force limit
and into the workspace box. The fast chain solves its QPs exactly (a clip, a one-row projection, or the
dual active-set solver DAQP in a workspace it keeps and updates); the naive reference rebuilds every QP
through ``qpsolvers`` every tick and solves it with OSQP (the same QPs).

For each chain the benchmark also prints how the safety filter's ticks were solved (clip, projection,
general solver) and the worst row any tick's answer left violated, in the filter's normalised units
(each row of unit norm, each joint in units of its largest step, the slack of a soft row subtracted):
OSQP stops at its tolerance, an exact solve leaves only rounding.

Each tick is timed twice: wall clock (``p50_us``, ``p99_us``, ``max_us``: what a control loop sees) and
the process's CPU time (``cpu_*``: the chain's own work, without the time the scheduler gave other
processes). On a shared machine the wall-clock tail is set by preemption, so the JSON also records the
1-minute load average. Pin to one core for stable numbers: ``taskset -c 0 tissue-retract bench chain``.
On a machine others are using, ``--repeats N`` runs the fast chain N times on the same input (the chain
is deterministic, so every run computes the same ticks) and also reports each tick's least CPU time over
the runs: what the tick costs when nothing else interfered with it.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from psm_control.commands import CartesianDelta, MeasuredState
from safety.chain import ControlChain
from safety.config import SafetyConfig
from safety.filter import KKT_TOLERANCE, SolvePaths
from sim.strict_json import write_strict_json
from tissue_retract.cli._checks import int_in

__all__ = ["add_arguments", "run"]

_TARGET_PERIOD_S = 0.05  # a policy step: one new Cartesian target every 50 ms
_FORCE_PERIOD_S = 0.05  # the tissue force is re-measured at the same rate


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the target's options."""
    parser.add_argument(
        "--ticks", type=int_in(100, 10_000_000), default=10_000, help="ticks per chain, at least 100 (default: 10000)"
    )
    parser.add_argument("--seed", type=int_in(0, 2**32 - 1), default=0, help="seed of the input sequence")
    parser.add_argument(
        "--rate", type=float, default=1000.0, help="control rate [Hz] (default: 1000, the loop the target is for)"
    )
    parser.add_argument(
        "--repeats",
        type=int_in(1, 1000),
        default=1,
        help="runs of the fast chain on the same input; with more than one, each tick's least CPU time over "
        "them is reported too (default: 1)",
    )


def _run(naive: bool, ticks: int, seed: int, rate_hz: float = 1000.0) -> tuple[np.ndarray, np.ndarray, int, SolvePaths]:
    """Return wall-clock and CPU time per tick [us], the number of safety stops and the filter's solve paths."""
    config = SafetyConfig(control_rate_hz=rate_hz, deadman_timeout_s=max(0.05, 2.0 / rate_hz))
    chain = ControlChain(config, naive_qp=naive)
    rng = np.random.default_rng(seed)
    q = chain.model.home()
    t = 0.0
    anchor = chain.model.configuration(q).measured_pose()[:3, 3].copy()
    stiffness = 300.0
    measured = MeasuredState(q, np.zeros(6), 0.0, np.zeros(3), t)
    chain.reset(measured)
    pull = np.array([0.0, 0.004, 0.002])
    every = max(1, round(_TARGET_PERIOD_S * rate_hz))
    force_every = max(1, round(_FORCE_PERIOD_S * rate_hz))
    wall = np.empty(ticks)
    cpu = np.empty(ticks)
    stops = 0
    clock, cpu_clock = time.perf_counter_ns, time.thread_time_ns
    for k in range(ticks):
        if k % every == 0:
            chain.set_target(CartesianDelta(pull + rng.normal(0.0, 0.002, 3), rng.normal(0.0, 0.05), 0.2), measured)
        start, cpu_start = clock(), cpu_clock()
        out = chain.tick(measured)
        cpu[k] = cpu_clock() - cpu_start
        wall[k] = clock() - start
        stops += out.safety_stop
        t += chain.control_period_s
        force = measured.force_n
        if k % force_every == 0:
            tip = chain.model.configuration(out.command.q).measured_pose()[:3, 3]
            force = -stiffness * (tip - anchor)
        measured = MeasuredState(out.command.q, out.command.qd, out.command.jaw, force, t)
    return wall / 1000.0, cpu / 1000.0, stops, chain.filter.paths


def run(args: argparse.Namespace) -> int:
    """Run both chains and print p50/p99/max [us]."""
    ticks = args.ticks
    fast, fast_cpu, fast_stops, fast_paths = _run(False, ticks, args.seed, args.rate)
    repeats = args.repeats
    least_cpu = fast_cpu.copy()
    for _ in range(repeats - 1):
        np.minimum(least_cpu, _run(False, ticks, args.seed, args.rate)[1], out=least_cpu)
    naive, naive_cpu, naive_stops, naive_paths = _run(True, ticks, args.seed, args.rate)
    result = {
        "ticks": ticks,
        "control_rate_hz": float(args.rate),
        "p50_us": float(np.percentile(fast, 50)),
        "p99_us": float(np.percentile(fast, 99)),
        "max_us": float(fast.max()),
        "naive_p50_us": float(np.percentile(naive, 50)),
        "naive_p99_us": float(np.percentile(naive, 99)),
        "naive_max_us": float(naive.max()),
        "speedup_p99": float(np.percentile(naive, 99) / np.percentile(fast, 99)),
        "cpu_p50_us": float(np.percentile(fast_cpu, 50)),
        "cpu_p99_us": float(np.percentile(fast_cpu, 99)),
        "naive_cpu_p99_us": float(np.percentile(naive_cpu, 99)),
        "cpu_speedup_p99": float(np.percentile(naive_cpu, 99) / np.percentile(fast_cpu, 99)),
        "safety_stops": fast_stops,
        "naive_safety_stops": naive_stops,
        "load_avg_1min": float(os.getloadavg()[0]),
        "repeats": repeats,
        "least_cpu_p50_us": float(np.percentile(least_cpu, 50)),
        "least_cpu_p99_us": float(np.percentile(least_cpu, 99)),
        "least_cpu_max_us": float(least_cpu.max()),
        "filter_solver": fast_paths.solver_name,
        "filter_ticks_clipped": fast_paths.clipped,
        "filter_ticks_projected": fast_paths.projected,
        "filter_ticks_solver": fast_paths.solver,
        "worst_row_violation": fast_paths.worst_row_violation,
        "ticks_over_tolerance": fast_paths.over_tolerance,
        "naive_filter_solver": naive_paths.solver_name,
        "naive_filter_ticks_solver": naive_paths.solver,
        "naive_worst_row_violation": naive_paths.worst_row_violation,
        "naive_ticks_over_tolerance": naive_paths.over_tolerance,
    }
    table = Table(title=f"control-chain tick latency over {ticks} ticks at {args.rate:g} Hz [us]")
    for column in ("chain", "p50", "p99", "max", "cpu p50", "cpu p99", "stops"):
        table.add_column(column, justify="right" if column != "chain" else "left")
    for name, wall, cpu, stops in (
        ("exact solves, kept DAQP workspace", fast, fast_cpu, fast_stops),
        ("naive (qpsolvers + OSQP, rebuilt each tick)", naive, naive_cpu, naive_stops),
    ):
        table.add_row(
            name,
            *(f"{v:.1f}" for v in (np.percentile(wall, 50), np.percentile(wall, 99), wall.max())),
            *(f"{v:.1f}" for v in (np.percentile(cpu, 50), np.percentile(cpu, 99))),
            str(stops),
        )
    if repeats > 1:
        table.add_row(
            f"exact solves, each tick's least CPU time of {repeats} runs",
            "",
            "",
            "",
            f"{result['least_cpu_p50_us']:.1f}",
            f"{result['least_cpu_p99_us']:.1f}",
            "",
        )
    paths = Table(title="safety filter: how each tick was solved, and the worst row left violated")
    for column in ("chain", "clip only", "one-row projection", "general solver", "worst row violation", "ticks > 1e-9"):
        paths.add_column(column, justify="right" if column != "chain" else "left")
    for name, solve in (("exact solves", fast_paths), ("naive", naive_paths)):
        paths.add_row(
            name,
            str(solve.clipped),
            str(solve.projected),
            f"{solve.solver} ({solve.solver_name})",
            f"{solve.worst_row_violation:.2g}",
            str(solve.over_tolerance),
        )
    console = Console(width=120)
    console.print(table)
    console.print(paths)
    console.print(
        f"speed-up at p99: {result['speedup_p99']:.2f}x wall clock, {result['cpu_speedup_p99']:.2f}x CPU time "
        f"(target: p99 <= 250 us and >= 4x); load average {result['load_avg_1min']:.2f}"
    )
    for name, solve in (("exact solves", fast_paths), ("naive", naive_paths)):
        console.print(
            f"{name}: worst row violation {solve.worst_row_violation:.2g}, {solve.over_tolerance} of {solve.ticks} "
            f"ticks above {KKT_TOLERANCE:g} (target: none); {solve.solver} ticks went to {solve.solver_name}"
        )
    if args.json:
        write_strict_json(Path(args.json), result, field="--json")
    return 0
