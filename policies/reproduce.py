"""The paper's evaluation protocol: Table 1 and Table 2, run as parallel processes on this machine or on Ray.

Table 1 trains each algorithm on Tasks I-III (``TissueRetract-Lift-v0``, ``-Target-v0``,
``-MultiSite-v0``) with 100 demonstrations and seeds 1, 2, 3; Table 2 varies the demonstrations
(25 / 50 / 100) on Task III. Each run is one ``train`` in its own process, in its own directory, so an
interrupted reproduction resumes run by run. The outcome is written as markdown tables with our
success rate (mean over seeds, 95 % t-interval) beside the paper's, and learning curves as PNG.
"""

from __future__ import annotations

import csv
import functools
import json
import math
import multiprocessing
import subprocess
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from policies.config import ALGORITHMS, TrainConfig
from policies.errors import ReproductionError
from policies.trainer import RunSpec, train
from psm_control import __version__
from psm_control.errors import UnknownVariantError
from sim.strict_json import write_strict_json
from sim.sweep import BACKENDS
from sim.sweep.cluster import ray_cluster
from sim.sweep.page import Page, percent
from sim.sweep.stopping import stop_pool

__all__ = [
    "OUTCOME_FILE",
    "PAPER_TABLE1",
    "PAPER_TABLE2",
    "TASKS",
    "Run",
    "RunOutcome",
    "plan",
    "plot_curves",
    "reproduce",
    "run_all",
    "table_blocks",
]

#: Task label -> Gymnasium id, as in the paper.
TASKS = {"I": "TissueRetract-Lift-v0", "II": "TissueRetract-Target-v0", "III": "TissueRetract-MultiSite-v0"}

#: The paper's Table 1: success % (mean, 95 % CI) with 100 demonstrations, by task and algorithm.
PAPER_TABLE1: dict[str, dict[str, tuple[float, float]]] = {
    "I": {"ddpg": (83, 0.7), "sqil": (4, 7), "col": (94, 6), "ddpgbc": (95, 3), "dex": (66, 32)},
    "II": {"ddpg": (85, 11), "sqil": (1, 1), "col": (86, 9), "ddpgbc": (86, 5), "dex": (82, 12)},
    "III": {"ddpg": (80, 6), "sqil": (6, 4), "col": (76, 4), "ddpgbc": (65, 5), "dex": (58, 8)},
}

#: The paper's Table 2: success % on Task III by number of demonstrations.
PAPER_TABLE2: dict[str, dict[int, float]] = {
    "sqil": {25: 5, 50: 5, 100: 6},
    "col": {25: 50, 50: 60, 100: 76},
    "ddpgbc": {25: 62, 50: 62, 100: 65},
    "dex": {25: 34, 50: 58, 100: 58},
}


@dataclass(frozen=True)
class Run:
    """One training run of the protocol."""

    task: str
    task_id: str
    algo: str
    seed: int
    demos: int
    episodes: int
    eval_every: int
    eval_episodes: int
    out_dir: Path
    overrides: tuple[tuple[str, Any], ...] = ()


@dataclass
class RunOutcome:
    """What a run produced: its final success and its learning curve."""

    run: Run
    success: float
    curve: list[tuple[int, float]] = field(default_factory=list)
    wall_seconds: float = 0.0
    steps_per_second: float = float("nan")
    resumed_from: int = 0


def plan(
    out_dir: Path,
    *,
    episodes: int = 1000,
    tasks: Mapping[str, str] = TASKS,
    algos: Sequence[str] = ALGORITHMS,
    seeds: Sequence[int] = (1, 2, 3),
    demos: int = 100,
    ablation_task: str | None = "III",
    ablation_demos: Sequence[int] = (25, 50),
    eval_every: int = 50,
    eval_episodes: int = 50,
    overrides: Mapping[str, Any] | None = None,
) -> list[Run]:
    """The runs of Table 1 and of Table 2's extra demonstration counts (100 demos are shared with Table 1)."""
    extra = tuple(sorted((overrides or {}).items()))
    runs = []
    grid: list[tuple[str, str, int]] = [(task, algo, demos) for task in tasks for algo in algos]
    if ablation_task is not None and ablation_task in tasks:
        grid += [(ablation_task, algo, n) for algo in algos if algo in PAPER_TABLE2 for n in ablation_demos]
    for task, algo, n_demos in grid:
        for seed in seeds:
            run_dir = out_dir / "runs" / f"{task}-{algo}-d{n_demos}-s{seed}"
            runs.append(
                Run(task, tasks[task], algo, seed, n_demos, episodes, eval_every, eval_episodes, run_dir, extra)
            )
    return runs


#: Written in a run's folder when it finishes: what it scored, how long it took, on which code.
OUTCOME_FILE = "outcome.json"


def _execute(run: Run) -> RunOutcome:
    """Train one run (in a worker process); returns its outcome. A finished run is read, not retrained."""
    finished = _read_outcome(run)
    if finished is not None:
        return finished
    start = time.perf_counter()
    config = TrainConfig(algo=run.algo, **dict(run.overrides))
    spec = RunSpec(
        run.task_id, seed=run.seed, episodes=run.episodes, demos=run.demos if run.algo != "ddpg" else 0,
        out_dir=run.out_dir, eval_every=run.eval_every, eval_episodes=run.eval_episodes,
        command=f"tissue-retract train --task {run.task_id} --algo {run.algo} --demos {run.demos} "
        f"--seed {run.seed} --episodes {run.episodes} --out {run.out_dir}",
        progress=False, tensorboard=False,
    )  # fmt: skip
    result = train(spec, config)
    curve = _read_curve(run.out_dir / "eval.csv")
    success = curve[-1][1] if curve else result.final_success
    outcome = RunOutcome(
        run, success, curve, time.perf_counter() - start, result.learning_steps_per_second, result.resumed_from
    )
    record = {
        "episodes": run.episodes,
        "success": success,
        "curve": curve,
        "wall_seconds": outcome.wall_seconds,
        "steps_per_second": outcome.steps_per_second,
        "resumed_from": outcome.resumed_from,
        "commit": _commit(),
        "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
    write_strict_json(run.out_dir / OUTCOME_FILE, record, indent=1)
    return outcome


def _read_outcome(run: Run) -> RunOutcome | None:
    path = run.out_dir / OUTCOME_FILE
    if not path.exists():
        return None
    record = json.loads(path.read_text())
    if record.get("episodes") != run.episodes:
        return None
    curve = [(int(e), float(s)) for e, s in record["curve"]]
    return RunOutcome(
        run, float(record["success"]), curve, float(record["wall_seconds"]), float(record["steps_per_second"]),
        int(record.get("resumed_from", 0)),
    )  # fmt: skip


def _commit() -> str:
    """The git commit of the code that ran, or "" outside a checkout."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=Path(__file__).parent,
            capture_output=True,
            text=True,
            timeout=10,
        )
    except (OSError, subprocess.SubprocessError):
        return ""
    return out.stdout.strip() if out.returncode == 0 else ""


def _read_curve(path: Path) -> list[tuple[int, float]]:
    if not path.exists():
        return []
    with path.open() as f:
        return [(int(row["episode"]), float(row["success_rate"])) for row in csv.DictReader(f)]


def run_all(runs: Iterable[Run], jobs: int = 1, backend: str = "local") -> list[RunOutcome]:
    """Train every run, ``jobs`` processes at a time (each process uses one torch thread).

    Args:
        runs: The runs; a finished run (its ``outcome.json``) is read, not retrained.
        jobs: Parallel runs on the local pool, or CPUs of a local Ray cluster started here.
        backend: ``"local"`` (a process pool) or ``"ray"`` (``RAY_ADDRESS`` or a local cluster on
            127.0.0.1). On a cluster of several machines the output folder must be on storage they share.

    Raises:
        UnknownVariantError: Unknown backend.
        ReproductionError: After every run has ended, naming the runs that failed.
    """
    if backend not in BACKENDS:
        raise UnknownVariantError("backend", backend, BACKENDS)
    runs = list(runs)
    outcomes: list[RunOutcome] = []
    failures: list[tuple[str, str]] = []

    def collect(run: Run, result: Callable[[], RunOutcome]) -> None:
        # One failed run must not cost the others: hours of training may be under way beside it.
        try:
            outcomes.append(result())
        except Exception as e:
            failures.append((run.out_dir.name, f"{type(e).__name__}: {e}"))

    if backend == "ray":
        with ray_cluster(jobs) as ray:
            # One CPU per run, as on the local pool; a failed run is reported, not retried.
            remote = ray.remote(num_cpus=1, max_retries=0)(_execute)
            refs = [remote.remote(run) for run in runs]
            for run, ref in zip(runs, refs, strict=True):
                collect(run, functools.partial(ray.get, ref))
    elif jobs <= 1:
        for run in runs:
            collect(run, functools.partial(_execute, run))
    else:
        with ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
            futures = [pool.submit(_execute, run) for run in runs]
            try:
                for run, future in zip(runs, futures, strict=True):
                    collect(run, future.result)
            except KeyboardInterrupt:  # finished runs are on disk; the running ones resume from their checkpoints
                stop_pool(pool)
                raise
    if failures:
        raise ReproductionError(failures)
    return outcomes


def _mean_ci(values: Sequence[float]) -> tuple[float, float]:
    """Mean and half-width of the 95 % Student-t interval (0 for a single value)."""
    x = np.asarray(values, dtype=float)
    if len(x) < 2:
        return float(x.mean()), 0.0
    t975 = {2: 12.706, 3: 4.303, 4: 3.182, 5: 2.776, 6: 2.571, 7: 2.447, 8: 2.365, 9: 2.306, 10: 2.262}
    t = t975.get(len(x), 1.96)
    return float(x.mean()), float(t * x.std(ddof=1) / math.sqrt(len(x)))


def table_blocks(outcomes: Sequence[RunOutcome], demos: int = 100) -> list[tuple[str, list[str], list[list[str]]]]:
    """Table 1 (ours beside the paper's) and, when present, Table 2, as (heading, header, rows)."""
    by: dict[tuple[str, str, int], list[float]] = {}
    for o in outcomes:
        by.setdefault((o.run.task, o.run.algo, o.run.demos), []).append(100 * o.success)
    tasks = list(dict.fromkeys(o.run.task for o in outcomes))
    algos = [a for a in ALGORITHMS if any(o.run.algo == a for o in outcomes)]

    def cell(values: list[float] | None) -> str:
        if not values:
            return "-"
        mean, ci = _mean_ci(values)
        return f"{mean:.0f} +- {ci:.0f}"

    rows = []
    for task in tasks:
        row = [task]
        for algo in algos:
            paper = PAPER_TABLE1.get(task, {}).get(algo)
            ref = f"{paper[0]:g} +- {paper[1]:g}" if paper else "-"
            row.append(f"{cell(by.get((task, algo, demos)))} / {ref}")
        rows.append(row)
    blocks = [(f"Table 1: success % ({demos} demonstrations; ours / paper)", ["Task", *algos], rows)]
    ablation = sorted(
        {o.run.demos for o in outcomes if o.run.task == "III"} - {demos} | ({demos} if "III" in tasks else set())
    )
    if len(ablation) > 1:
        rows = [
            [algo, *(f"{cell(by.get(('III', algo, n)))} / {PAPER_TABLE2[algo].get(n, '-')}" for n in ablation)]
            for algo in algos
            if algo in PAPER_TABLE2
        ]
        heading = "Table 2: Task III success % by demonstrations (ours / paper)"
        blocks.append((heading, ["Algorithm", *(str(n) for n in ablation)], rows))
    return blocks


def plot_curves(outcomes: Sequence[RunOutcome], path: Path, demos: int = 100) -> Path:
    """One panel per task: mean evaluation success over seeds against training episodes, per algorithm."""
    tasks = list(dict.fromkeys(o.run.task for o in outcomes))
    fig = Figure(figsize=(4.5 * len(tasks), 3.5))
    axes = fig.subplots(1, len(tasks), squeeze=False)
    for ax, task in zip(axes[0], tasks, strict=True):
        for algo in ALGORITHMS:
            curves = [o.curve for o in outcomes if o.run.task == task and o.run.algo == algo and o.run.demos == demos]
            curves = [c for c in curves if c]
            if not curves:
                continue
            n = min(len(c) for c in curves)
            episodes = [e for e, _ in curves[0][:n]]
            mean = np.mean([[s for _, s in c[:n]] for c in curves], axis=0)
            ax.plot(episodes, 100 * mean, marker="o", markersize=3, label=algo)
        ax.set_title(f"Task {task}")
        ax.set_xlabel("training episodes")
        ax.set_ylabel("success %")
        ax.set_ylim(-5, 105)
        ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    return path


def reproduce(
    out_dir: Path, runs: Sequence[Run], jobs: int = 1, backend: str = "local", command: str = ""
) -> tuple[Path, list[RunOutcome]]:
    """Run the protocol (on ``backend``, as :func:`run_all`) and write ``results.md``, ``results.html`` and
    ``curves.png``; ``command`` is the command line shown on the page. Returns the Markdown's path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    outcomes = run_all(runs, jobs, backend)
    wall = time.perf_counter() - start
    demos = max((r.demos for r in runs), default=100)
    plot_curves(outcomes, out_dir / "curves.png", demos)
    page = Page("Reproduction of the seed paper's evaluation")
    page.card(
        [
            ("runs", f"{len(runs)} of {max((r.episodes for r in runs), default=0)} training episodes each"),
            ("processes", f"{jobs} in parallel ({backend})"),
            ("wall time", f"{wall:.0f} s in this sitting (runs finished earlier are read with their own times)"),
            ("package", f"tissue-retract {__version__}, commit {_commit() or 'unknown'}"),
        ]
    )
    if command:
        page.heading("Command")
        page.command(command)
    for heading, header, rows in table_blocks(outcomes, demos):
        page.heading(heading)
        page.table(header, rows)
    page.figure(out_dir / "curves.png", "mean evaluation success against training episodes")
    page.heading("Every run")
    page.table(
        ["Task", "Algorithm", "Demos", "Seed", "Success", "Wall time", "Env steps/s once learning"],
        [
            [
                o.run.task,
                o.run.algo,
                str(o.run.demos),
                str(o.run.seed),
                percent(o.success),
                f"{o.wall_seconds:.0f} s" + (f" (from episode {o.resumed_from})" if o.resumed_from else ""),
                f"{o.steps_per_second:.0f}",
            ]
            for o in outcomes
        ],
    )
    path = page.write(out_dir, stem="results")["report_md"]
    return path, outcomes
