"""``tissue-retract bench chain``: control-chain tick latency against a naive reference.

Both chains (IK + safety filter + Ruckig + verifier) run the same realistic input in the same process:
a kinematic backend (measured = last command, as the dVRK's KINEMATIC simulation), policy targets of a few
millimetres every 50 ticks that pull a spring-like tissue (stiffness 300 N/m) against the force limit
and into the workspace box. The fast chain keeps its OSQP workspaces and ``update()``s them; the naive
reference rebuilds every QP through ``qpsolvers.solve_qp`` every tick. Pin to one core for stable
numbers: ``taskset -c 0 tissue-retract bench chain``.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the target's options (``--json`` is added by ``bench``)."""
    parser.add_argument("--ticks", type=int, default=10_000, help="ticks per chain (default: 10000, minimum 1000)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the input sequence")


def _run(naive: bool, ticks: int, seed: int) -> np.ndarray:
    from psm_control.commands import CartesianDelta, MeasuredState
    from safety.chain import ControlChain

    chain = ControlChain(naive_qp=naive)
    rng = np.random.default_rng(seed)
    q = chain.model.home()
    t = 0.0
    anchor = chain._command_state.measured_pose()[:3, 3].copy()
    stiffness = 300.0
    measured = MeasuredState(q, np.zeros(6), 0.0, np.zeros(3), t)
    chain.reset(measured)
    pull = np.array([0.0, 0.004, 0.002])
    elapsed = np.empty(ticks)
    for k in range(ticks):
        if k % 50 == 0:
            chain.set_target(CartesianDelta(pull + rng.normal(0.0, 0.002, 3), rng.normal(0.0, 0.05), 0.2), measured)
        start = time.perf_counter_ns()
        out = chain.tick(measured)
        elapsed[k] = time.perf_counter_ns() - start
        t += chain.control_period_s
        tip = chain._verifier_state.model.configuration(out.command.q).measured_pose()[:3, 3] if k % 50 == 0 else None
        anchor_force = -stiffness * (tip - anchor) if tip is not None else measured.force_n
        measured = MeasuredState(out.command.q, out.command.qd, out.command.jaw, anchor_force, t)
    return elapsed / 1000.0


def run(args: argparse.Namespace) -> int:
    """Run both chains and print p50/p99/max [us]."""
    from rich.console import Console
    from rich.table import Table

    ticks = max(int(args.ticks), 1000)
    fast = _run(False, ticks, args.seed)
    naive = _run(True, ticks, args.seed)
    result = {
        "ticks": ticks,
        "p50_us": float(np.percentile(fast, 50)),
        "p99_us": float(np.percentile(fast, 99)),
        "max_us": float(fast.max()),
        "naive_p50_us": float(np.percentile(naive, 50)),
        "naive_p99_us": float(np.percentile(naive, 99)),
        "speedup_p99": float(np.percentile(naive, 99) / np.percentile(fast, 99)),
    }
    table = Table(title=f"control-chain tick latency over {ticks} ticks [us]")
    for column in ("chain", "p50", "p99", "max"):
        table.add_column(column, justify="right" if column != "chain" else "left")
    table.add_row(
        "kept OSQP workspaces", f"{result['p50_us']:.1f}", f"{result['p99_us']:.1f}", f"{result['max_us']:.1f}"
    )
    table.add_row(
        "naive (qpsolvers.solve_qp)",
        f"{result['naive_p50_us']:.1f}",
        f"{result['naive_p99_us']:.1f}",
        f"{naive.max():.1f}",
    )
    console = Console(width=100)
    console.print(table)
    console.print(f"speed-up at p99: {result['speedup_p99']:.2f}x (target: p99 <= 250 us and >= 4x)")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(result, f, indent=2)
    return 0
