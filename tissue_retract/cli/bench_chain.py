"""``tissue-retract bench chain``: control-chain tick latency against a naive reference.

Both chains (IK + safety filter + Ruckig + verifier) run the same realistic input in the same process:
a kinematic backend (measured = last command, as the dVRK's KINEMATIC simulation), policy targets of a few
millimetres every 50 ms that pull a spring-like tissue (stiffness 300 N/m) against the force limit
and into the workspace box. The fast chain keeps its OSQP workspaces and ``update()``s them; the naive
reference rebuilds every QP through ``qpsolvers.solve_qp`` every tick (the same QPs, the same settings).

Each tick is timed twice: wall clock (``p50_us``, ``p99_us``, ``max_us``: what a control loop sees) and
the process's CPU time (``cpu_*``: the chain's own work, without the time the scheduler gave other
processes). On a shared machine the wall-clock tail is set by preemption, so the JSON also records the
1-minute load average. Pin to one core for stable numbers: ``taskset -c 0 tissue-retract bench chain``.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np
from rich.console import Console
from rich.table import Table

from psm_control.commands import CartesianDelta, MeasuredState
from safety.chain import ControlChain
from safety.config import SafetyConfig

__all__ = ["add_arguments", "run"]

_TARGET_PERIOD_S = 0.05  # a policy step: one new Cartesian target every 50 ms
_FORCE_PERIOD_S = 0.05  # the tissue force is re-measured at the same rate


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the target's options."""
    parser.add_argument("--ticks", type=int, default=10_000, help="ticks per chain (default: 10000, minimum 100)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the input sequence")
    parser.add_argument(
        "--rate", type=float, default=1000.0, help="control rate [Hz] (default: 1000, the loop the target is for)"
    )


def _run(naive: bool, ticks: int, seed: int, rate_hz: float = 1000.0) -> tuple[np.ndarray, np.ndarray, int]:
    """Return wall-clock and CPU time per tick [us] and the number of safety stops."""
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
    return wall / 1000.0, cpu / 1000.0, stops


def run(args: argparse.Namespace) -> int:
    """Run both chains and print p50/p99/max [us]."""
    ticks = max(int(args.ticks), 100)
    fast, fast_cpu, fast_stops = _run(False, ticks, args.seed, args.rate)
    naive, naive_cpu, naive_stops = _run(True, ticks, args.seed, args.rate)
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
    }
    table = Table(title=f"control-chain tick latency over {ticks} ticks at {args.rate:g} Hz [us]")
    for column in ("chain", "p50", "p99", "max", "cpu p50", "cpu p99", "stops"):
        table.add_column(column, justify="right" if column != "chain" else "left")
    for name, wall, cpu, stops in (
        ("kept OSQP workspaces", fast, fast_cpu, fast_stops),
        ("naive (qpsolvers, rebuilt each tick)", naive, naive_cpu, naive_stops),
    ):
        table.add_row(
            name,
            *(f"{v:.1f}" for v in (np.percentile(wall, 50), np.percentile(wall, 99), wall.max())),
            *(f"{v:.1f}" for v in (np.percentile(cpu, 50), np.percentile(cpu, 99))),
            str(stops),
        )
    console = Console(width=110)
    console.print(table)
    console.print(
        f"speed-up at p99: {result['speedup_p99']:.2f}x wall clock, {result['cpu_speedup_p99']:.2f}x CPU time "
        f"(target: p99 <= 250 us and >= 4x); load average {result['load_avg_1min']:.2f}"
    )
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(result, f, indent=2)
    return 0
