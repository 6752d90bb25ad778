"""``tissue-retract bench env``: environment steps per second with random actions, single process.

State-only observations with the default tissue and the controller in the loop, then the same with an
endoscope render every step. Pin it to one core to compare with the paper's about 30 steps/s:
``taskset -c 0 tissue-retract bench env``.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

from sim.strict_json import write_strict_json
from tissue_retract.cli._checks import MAX_EPISODES, int_in

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the target's options."""
    parser.add_argument("--task", default="multisite", help="task (default: multisite)")
    steps = int_in(1, MAX_EPISODES * 50)
    parser.add_argument("--steps", type=steps, default=1000, help="state-only steps (default: 1000)")
    parser.add_argument("--render-steps", type=steps, default=100, help="steps with rendering (default: 100)")


def _rate(env: object, steps: int, render: bool) -> tuple[float, float, int]:
    env.reset(seed=0)  # type: ignore[attr-defined]
    env.action_space.seed(0)  # type: ignore[attr-defined]
    unstable = 0
    start, cpu = time.perf_counter(), time.process_time()
    for _ in range(steps):
        _, _, terminated, truncated, info = env.step(env.action_space.sample())  # type: ignore[attr-defined]
        unstable += int(info["sim_unstable"])
        if render:
            env.unwrapped.render_frame()  # type: ignore[attr-defined]
        if terminated or truncated:
            env.reset()  # type: ignore[attr-defined]
    return steps / (time.perf_counter() - start), steps / max(time.process_time() - cpu, 1e-9), unstable


def run(args: argparse.Namespace) -> int:
    """Measure and print."""
    from sim.envs import make  # PyBullet: once the arguments are parsed

    env = make(args.task)
    try:
        physics = env.unwrapped.config.physics
        state_rate, state_cpu_rate, unstable = _rate(env, args.steps, render=False)
        render_rate, render_cpu_rate, _ = _rate(env, args.render_steps, render=True)
        controller = env.unwrapped.controller_name
    finally:
        env.close()
    results = {
        "env_steps_per_s": state_rate,
        "render_env_steps_per_s": render_rate,
        "env_steps_per_cpu_s": state_cpu_rate,
        "render_env_steps_per_cpu_s": render_cpu_rate,
        "task": args.task,
        "steps": args.steps,
        "sim_unstable_steps": unstable,
        "substeps": physics.substeps,
        "time_step_s": physics.time_step_s,
        "solver_iterations": physics.solver_iterations,
        "tissue_resolution": env.unwrapped.config.tissue.resolution,
        "control_rate_hz": 1.0 / physics.control_period_s,
        "controller": controller,
        "cpus_allowed": len(os.sched_getaffinity(0)),
        "load_average_1min": os.getloadavg()[0],
    }
    print(
        f"state-only:      {state_rate:8.1f} env steps/s wall, {state_cpu_rate:8.1f} per CPU-second "
        f"({args.steps} steps, resets included)"
    )
    print(
        f"with rendering:  {render_rate:8.1f} env steps/s wall, {render_cpu_rate:8.1f} per CPU-second "
        f"({args.render_steps} steps)"
    )
    print(
        f"settings: {physics.substeps} substeps x {physics.time_step_s:.5f} s, {physics.solver_iterations} solver "
        f"iterations, {results['tissue_resolution']}x{results['tissue_resolution']} flap; {controller}; "
        f"unstable steps: {unstable}; "
        f"cpus allowed {results['cpus_allowed']}, load {results['load_average_1min']:.2f}"
    )
    if args.json:
        write_strict_json(Path(args.json), results, field="--json")
    return 0
