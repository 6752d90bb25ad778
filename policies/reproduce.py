"""The paper's evaluation protocol: Table 1 and Table 2, run as parallel processes on this machine or on Ray.

Table 1 trains each algorithm on Tasks I-III (``TissueRetract-Lift-v0``, ``-Target-v0``,
``-MultiSite-v0``) with 100 demonstrations and seeds 1, 2, 3; Table 2 varies the demonstrations
(25 / 50 / 100) on Task III. Each run is one ``train`` in its own process, in its own directory, so an
interrupted reproduction resumes run by run. The outcome is a report page (HTML and Markdown) with our
success rate (mean over seeds, 95 % t-interval) beside the paper's per cell, the learning curves, and
``results.json`` with every number on the page and the code every run trained on (:func:`code_identity`).
"""

from __future__ import annotations

import contextlib
import csv
import functools
import importlib.metadata
import json
import math
import multiprocessing
import os
import platform
import subprocess
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from matplotlib.figure import Figure

from policies.config import ALGORITHMS, PAPER_TASKS, TrainConfig
from policies.errors import ReproductionError
from policies.trainer import RunSpec, train
from psm_control import __version__
from psm_control.errors import UnknownVariantError
from sim.strict_json import write_strict_json
from sim.sweep import BACKENDS
from sim.sweep.cluster import ray_cluster
from sim.sweep.page import Page, percent
from sim.sweep.stopping import pool_worker_start, stop_pool

__all__ = [
    "CODE_DIRS",
    "OUTCOME_FILE",
    "PAPER_TABLE1",
    "PAPER_TABLE2",
    "START_FILE",
    "TASKS",
    "Cell",
    "Run",
    "RunOutcome",
    "cells",
    "code_identity",
    "machine",
    "plan",
    "plot_cells",
    "plot_curves",
    "reproduce",
    "run_all",
    "table_blocks",
]

#: Task label -> Gymnasium id, as in the paper.
TASKS = PAPER_TASKS

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
    code: dict[str, Any] = field(default_factory=dict)
    machine: dict[str, Any] = field(default_factory=dict)


def plan(
    runs_dir: Path,
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
    """The runs of Table 1 and of Table 2's extra demonstration counts (100 demos are shared with Table 1),
    each in its own folder under ``runs_dir``."""
    extra = tuple(sorted((overrides or {}).items()))
    runs = []
    grid: list[tuple[str, str, int]] = [(task, algo, demos) for task in tasks for algo in algos]
    if ablation_task is not None and ablation_task in tasks:
        grid += [(ablation_task, algo, n) for algo in algos if algo in PAPER_TABLE2 for n in ablation_demos]
    for task, algo, n_demos in grid:
        for seed in seeds:
            run_dir = runs_dir / f"{task}-{algo}-d{n_demos}-s{seed}"
            runs.append(
                Run(task, tasks[task], algo, seed, n_demos, episodes, eval_every, eval_episodes, run_dir, extra)
            )
    return runs


#: Written in a run's folder when it finishes: what it scored, how long it took, on which code.
OUTCOME_FILE = "outcome.json"
#: Written in a run's folder when it first starts: the code it began on (a resumed run may end on other code).
START_FILE = "started_on.json"


def _execute(run: Run) -> RunOutcome:
    """Train one run (in a worker process); returns its outcome. A finished run is read, not retrained."""
    finished = _read_outcome(run)
    if finished is not None:
        return finished
    start = time.perf_counter()
    code = code_identity()
    started = run.out_dir / START_FILE  # the code the run began on, kept across resumptions
    if not started.exists():
        run.out_dir.mkdir(parents=True, exist_ok=True)
        write_strict_json(started, code, indent=1)
    began_on = json.loads(started.read_text())
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
    if began_on.get("trees") != code.get("trees"):
        code["began_on_other_code"] = began_on.get("commit", "unknown")
    outcome = RunOutcome(
        run, success, curve, time.perf_counter() - start, result.learning_steps_per_second, result.resumed_from, code,
        machine(),
    )  # fmt: skip
    record = {
        "episodes": run.episodes,
        "success": success,
        "curve": curve,
        "wall_seconds": outcome.wall_seconds,
        "steps_per_second": outcome.steps_per_second,
        "resumed_from": outcome.resumed_from,
        "code": code,
        "machine": outcome.machine,
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
        int(record.get("resumed_from", 0)), dict(record.get("code", {})), dict(record.get("machine", {})),
    )  # fmt: skip


#: The folders whose code decides what a run learns: a result names the git tree each had.
CODE_DIRS = ("psm_control", "safety", "sim", "policies")


def _git(*args: str) -> str | None:
    """A git command's output in the package's checkout, or None outside one."""
    try:
        out = subprocess.run(
            ["git", *args], cwd=Path(__file__).parent, capture_output=True, text=True, timeout=30, check=False
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


#: The vector extensions that choose torch's and numpy's kernels, widest first.
_SIMD = ("avx512f", "avx2", "avx", "sse4_2", "neon", "asimd")
#: The packages besides torch whose versions change what a run computes: its arrays, its physics, its kinematics.
_PACKAGES = ("numpy", "pybullet", "pin")


def _package_version(name: str) -> str:
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return ""


def machine() -> dict[str, Any]:
    """What a run trained on: the CPU (model name, family and model numbers, widest vector extension), its
    logical cores, Python, torch and the versions of :data:`_PACKAGES`.

    Training is deterministic on one machine, but the same seed and code can train another policy on a CPU
    whose kernels round differently (a virtual CPU's model name alone may not tell them apart).
    """
    info: dict[str, str] = {}
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            info.setdefault(key.strip(), value.strip())  # the first processor's
    flags = set(info.get("flags", info.get("Features", "")).split())
    return {
        "cpu": info.get("model name") or platform.processor() or platform.machine(),
        "cpu_family": info.get("cpu family", ""),
        "cpu_model": info.get("model", ""),
        "simd": next((name for name in _SIMD if name in flags), ""),
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "packages": {name: _package_version(name) for name in _PACKAGES},
    }


def code_identity() -> dict[str, Any]:
    """The code that runs: the commit, the git tree of each of :data:`CODE_DIRS` at that commit, and whether
    any of them has changes not committed (then the trees do not name what ran). Empty outside a checkout.

    Two runs with the same trees trained on the same code whatever their commits (a later commit that
    changed only the documentation leaves them equal).
    """
    commit = _git("rev-parse", "--short", "HEAD")
    if commit is None:
        return {}
    trees = {name: _git("rev-parse", f"HEAD:{name}") or "" for name in CODE_DIRS}
    changes = _git("status", "--porcelain", "--untracked-files=no", "--", *CODE_DIRS)
    return {"commit": commit, "trees": trees, "uncommitted_changes": changes is None or bool(changes)}


def _read_curve(path: Path) -> list[tuple[int, float]]:
    if not path.exists():
        return []
    with path.open() as f:
        return [(int(row["episode"]), float(row["success_rate"])) for row in csv.DictReader(f)]


def run_all(
    runs: Iterable[Run],
    jobs: int = 1,
    backend: str = "local",
    on_finished: Callable[[RunOutcome], None] | None = None,
) -> list[RunOutcome]:
    """Train every run, ``jobs`` processes at a time (each process uses one torch thread).

    Args:
        runs: The runs; a finished run (its ``outcome.json``) is read, not retrained.
        jobs: Parallel runs on the local pool, or CPUs of a local Ray cluster started here.
        backend: ``"local"`` (a process pool) or ``"ray"`` (``RAY_ADDRESS`` or a local cluster on
            127.0.0.1). On a cluster of several machines the output folder must be on storage they share.
        on_finished: Called with each outcome as its run ends (or is read back), in the order they end.

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
            outcome = result()
        except Exception as e:
            failures.append((run.out_dir.name, f"{type(e).__name__}: {e}"))
            return
        outcomes.append(outcome)
        if on_finished is not None:
            on_finished(outcome)

    if backend == "ray":
        with ray_cluster(jobs) as ray:
            # One CPU per run, as on the local pool; a failed run is reported, not retried.
            remote = ray.remote(num_cpus=1, max_retries=0)(_execute)
            pending = {remote.remote(run): run for run in runs}
            while pending:  # in the order they end, as on the local pool
                (ref,), _ = ray.wait(list(pending), num_returns=1)
                collect(pending.pop(ref), functools.partial(ray.get, ref))
    elif jobs <= 1:
        for run in runs:
            collect(run, functools.partial(_execute, run))
    else:
        with ProcessPoolExecutor(
            max_workers=jobs, mp_context=multiprocessing.get_context("spawn"), initializer=pool_worker_start
        ) as pool:
            futures = {pool.submit(_execute, run): run for run in runs}
            try:
                for future in as_completed(futures):
                    collect(futures[future], future.result)
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


@dataclass(frozen=True)
class Cell:
    """One cell of the paper's tables: an algorithm on a task with a number of demonstrations, over seeds.

    Attributes:
        table: 1 or 2.
        task: The task label (``I``, ``II``, ``III``).
        algo: The algorithm.
        demos: Demonstrations.
        seeds: The seeds that ran.
        success_pct: Each seed's final success [%], in the order of ``seeds``.
        paper_mean_pct: The paper's mean success [%], or None where the paper has none.
        paper_ci_pct: The paper's 95 % interval half-width [%]. The paper gives none in Table 2: its cells
            take Table 1's for Task III and the algorithm, the paper's own spread over seeds.
    """

    table: int
    task: str
    algo: str
    demos: int
    seeds: tuple[int, ...]
    success_pct: tuple[float, ...]
    paper_mean_pct: float | None
    paper_ci_pct: float | None

    @property
    def mean_pct(self) -> float:
        """Our mean over seeds [%]."""
        return _mean_ci(self.success_pct)[0]

    @property
    def ci_pct(self) -> float:
        """Our 95 % Student-t interval half-width over seeds [%]."""
        return _mean_ci(self.success_pct)[1]

    @property
    def meets_paper(self) -> bool | None:
        """Our mean is at or above the paper's mean minus its interval; None where the paper has no number."""
        if self.paper_mean_pct is None:
            return None
        return self.mean_pct >= self.paper_mean_pct - (self.paper_ci_pct or 0.0)


def cells(outcomes: Sequence[RunOutcome], demos: int = 100) -> list[Cell]:
    """Table 1's cells (``demos`` demonstrations), then Table 2's when Task III ran with several counts."""
    by: dict[tuple[str, str, int], list[RunOutcome]] = {}
    for o in sorted(outcomes, key=lambda o: o.run.seed):
        by.setdefault((o.run.task, o.run.algo, o.run.demos), []).append(o)
    tasks = list(dict.fromkeys(o.run.task for o in outcomes))
    algos = [a for a in ALGORITHMS if any(o.run.algo == a for o in outcomes)]

    def cell(table: int, task: str, algo: str, n: int, paper: tuple[float | None, float | None]) -> Cell | None:
        runs = by.get((task, algo, n))
        if not runs:
            return None
        seeds = tuple(o.run.seed for o in runs)
        return Cell(table, task, algo, n, seeds, tuple(100 * o.success for o in runs), *paper)

    table1 = [
        cell(1, task, algo, demos, PAPER_TABLE1.get(task, {}).get(algo, (None, None)))
        for task in tasks
        for algo in algos
    ]
    ablation = sorted({o.run.demos for o in outcomes if o.run.task == "III"} | {demos})
    table2 = []
    if "III" in tasks and len(ablation) > 1:
        for algo in (a for a in algos if a in PAPER_TABLE2):
            spread = PAPER_TABLE1["III"].get(algo, (None, None))[1]
            for n in ablation:
                paper = PAPER_TABLE2[algo].get(n)
                table2.append(cell(2, "III", algo, n, (None if paper is None else float(paper), spread)))
    return [c for c in table1 + table2 if c is not None]


def _ours(cell: Cell | None) -> str:
    return "-" if cell is None else f"{cell.mean_pct:.0f} +- {cell.ci_pct:.0f}"


def _paper(cell: Cell) -> str:
    return _paper_text(cell.paper_mean_pct, cell.paper_ci_pct if cell.table == 1 else None)


def _paper_text(mean: float | None, ci: float | None) -> str:
    """The paper's number as printed: its mean, with its interval where the paper gives one."""
    if mean is None:
        return "-"
    return f"{mean:g}" + ("" if ci is None else f" +- {ci:g}")


def table_blocks(outcomes: Sequence[RunOutcome], demos: int = 100) -> list[tuple[str, list[str], list[list[str]]]]:
    """Table 1 (ours beside the paper's) and, when present, Table 2, as (heading, header, rows)."""
    found = cells(outcomes, demos)
    table1 = {(c.task, c.algo): c for c in found if c.table == 1}
    table2 = {(c.algo, c.demos): c for c in found if c.table == 2}
    tasks = list(dict.fromkeys(c.task for c in table1.values()))
    algos = [a for a in ALGORITHMS if any(c.algo == a for c in found)]

    def paired(cell: Cell | None, paper: str) -> str:
        return f"{_ours(cell)} / {paper}"

    rows = [
        [
            task,
            *(
                paired(table1.get((task, a)), _paper_text(*PAPER_TABLE1.get(task, {}).get(a, (None, None))))
                for a in algos
            ),
        ]
        for task in tasks
    ]
    blocks = [(f"Table 1: success % ({demos} demonstrations; ours / paper)", ["Task", *algos], rows)]
    if table2:
        counts = sorted({n for _, n in table2})
        rows = [
            [algo, *(paired(table2.get((algo, n)), _paper_text(PAPER_TABLE2[algo].get(n), None)) for n in counts)]
            for algo in algos
            if algo in PAPER_TABLE2
        ]
        heading = "Table 2: Task III success % by demonstrations (ours / paper)"
        blocks.append((heading, ["Algorithm", *(str(n) for n in counts)], rows))
    return blocks


def plot_cells(found: Sequence[Cell], path: Path) -> Path:
    """Ours (mean, 95 % interval over seeds) beside the paper's per cell; one panel per table.

    A cell below the paper's mean minus its interval is drawn in red.
    """
    tables = sorted({c.table for c in found})
    fig = Figure(figsize=(11, 3.4 * len(tables)))
    axes = fig.subplots(len(tables), 1, squeeze=False)
    for ax, table in zip(axes[:, 0], tables, strict=True):
        row = [c for c in found if c.table == table]
        x = np.arange(len(row))
        for i, c in enumerate(row):
            colour = "#b00020" if c.meets_paper is False else "#1f77b4"
            ax.errorbar(i - 0.15, c.mean_pct, yerr=c.ci_pct, fmt="o", color=colour, capsize=3)
            ax.plot([i - 0.15] * len(c.success_pct), c.success_pct, ".", color=colour, alpha=0.4)
            if c.paper_mean_pct is not None:
                ax.errorbar(
                    i + 0.15, c.paper_mean_pct, yerr=c.paper_ci_pct or 0.0, fmt="s", mfc="none", color="#555",
                    capsize=3,
                )  # fmt: skip
        labels = [f"{c.task} {c.algo}" if table == 1 else f"{c.algo} {c.demos}" for c in row]
        ax.set_xticks(x, labels, rotation=45, ha="right", fontsize=8)
        ax.set_ylim(-5, 105)
        ax.set_ylabel("success %")
        ax.set_title(f"Table {table}: ours (dots: each seed; circle: mean, 95 % interval) / paper (square)")
        ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


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


def _code_summary(outcomes: Sequence[RunOutcome]) -> tuple[dict[str, Any] | None, str]:
    """The code every run trained on (None if they differ or it is unknown) and a line that says so."""
    versions = {json.dumps(o.code.get("trees"), sort_keys=True) for o in outcomes}
    dirs = ", ".join(CODE_DIRS)
    resumed = [o.run.out_dir.name for o in outcomes if "began_on_other_code" in o.code]
    if resumed:
        return None, f"runs resumed on other code than they began on: {', '.join(resumed)}"
    if not outcomes or any(not o.code or o.code.get("uncommitted_changes") for o in outcomes):
        return None, f"unknown for some runs: not in a git checkout, or {dirs} had uncommitted changes"
    if len(versions) > 1:
        return None, f"runs trained on {len(versions)} different versions of {dirs} (see Every run)"
    code = dict(outcomes[0].code)
    commits = sorted({o.code["commit"] for o in outcomes})
    return code, f"{dirs} as at commit {code['commit']} for every run (run at {', '.join(commits)})"


def _cell_record(cell: Cell) -> dict[str, Any]:
    return {
        "table": cell.table,
        "task": cell.task,
        "algo": cell.algo,
        "demos": cell.demos,
        "seeds": list(cell.seeds),
        "success_pct": list(cell.success_pct),
        "mean_pct": cell.mean_pct,
        "ci95_pct": cell.ci_pct,
        "paper_mean_pct": cell.paper_mean_pct,
        "paper_ci95_pct": cell.paper_ci_pct,
        "meets_paper": cell.meets_paper,
    }


def _run_record(o: RunOutcome) -> dict[str, Any]:
    return {
        "task": o.run.task,
        "task_id": o.run.task_id,
        "algo": o.run.algo,
        "demos": o.run.demos,
        "seed": o.run.seed,
        "episodes": o.run.episodes,
        "success_pct": 100 * o.success,
        "wall_seconds": o.wall_seconds,
        "env_steps_per_second": o.steps_per_second,
        "resumed_from_episode": o.resumed_from,
        "curve": [{"episode": e, "success_pct": 100 * v} for e, v in o.curve],
        "code": o.code,
        "machine": o.machine,
    }


def reproduce(
    out_dir: Path,
    runs: Sequence[Run],
    jobs: int = 1,
    backend: str = "local",
    command: str = "",
    on_finished: Callable[[RunOutcome], None] | None = None,
) -> tuple[Path, list[RunOutcome]]:
    """Run the protocol (on ``backend``, as :func:`run_all`) and write the report into ``out_dir``:
    ``results.md`` and ``results.html`` (the same page), ``results.json`` (every number on it, every run's
    learning curve and the code it trained on), ``results-cells.png`` and ``results-curves.png``.
    ``command`` is the command line shown on the page; ``on_finished`` is called as each run ends.
    Returns the Markdown's path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    finished = run_all(runs, jobs, backend, on_finished)
    outcomes = sorted(finished, key=lambda o: (o.run.task, o.run.algo, o.run.demos, o.run.seed))
    wall = time.perf_counter() - start
    demos = max((r.demos for r in runs), default=100)
    found = cells(outcomes, demos)
    code, code_line = _code_summary(outcomes)
    below = [c for c in found if c.meets_paper is False]
    episodes = max((r.episodes for r in runs), default=0)
    machines = _machines(outcomes)
    write_strict_json(
        out_dir / "results.json",
        {
            "command": command,
            "package_version": __version__,
            "commit": None if code is None else code["commit"],
            "code": code,
            "episodes_per_run": episodes,
            "eval_every": max((r.eval_every for r in runs), default=0),
            "eval_episodes": max((r.eval_episodes for r in runs), default=0),
            "machines": machines,
            "processes": jobs,
            "backend": backend,
            "cells": [_cell_record(c) for c in found],
            "runs": [_run_record(o) for o in outcomes],
        },
        indent=1,
    )
    plot_cells(found, out_dir / "results-cells.png")
    plot_curves(outcomes, out_dir / "results-curves.png", demos)
    page = Page("Reproduction of the seed paper's evaluation")
    page.card(
        [
            ("runs", f"{len(runs)} runs of {episodes} training episodes each, seeds {_seeds(runs)}"),
            ("processes", f"{jobs} in parallel ({backend})"),
            ("machine", "; ".join(_machine_line(m) for m in machines) or "unknown"),
            ("wall time", f"{wall:.0f} s in this sitting (runs finished earlier are read with their own times)"),
            ("package", f"tissue-retract {__version__}"),
            ("code", code_line),
            ("below the paper", f"{len(below)} of {len(found)} cells" + "".join(f"; {_label(c)}" for c in below)),
        ],
        alert=[label for label, bad in (("code", code is None), ("below the paper", bool(below))) if bad],
    )
    if command:
        page.heading("Command")
        page.command(command)
    for heading, header, rows in table_blocks(outcomes, demos):
        page.heading(heading)
        page.table(header, rows)
    page.heading("Ours against the paper, per cell")
    page.paragraph(
        "A cell is below the paper when our mean over seeds is under the paper's mean minus its 95 % interval. "
        "The paper gives no interval in Table 2: its cells take Table 1's for Task III and the algorithm."
    )
    page.figure(out_dir / "results-cells.png", "ours (each seed, and the mean with its 95 % interval) beside the paper")
    page.table(
        ["Table", "Task", "Algorithm", "Demos", "Each seed", "Ours", "Paper", "At or above the paper"],
        [
            [
                str(c.table), c.task, c.algo, str(c.demos), " / ".join(f"{v:.0f}" for v in c.success_pct),
                _ours(c), _paper(c), {True: "yes", False: "no", None: "-"}[c.meets_paper],
            ]
            for c in found
        ],
    )  # fmt: skip
    page.heading("Learning curves")
    page.figure(out_dir / "results-curves.png", "mean evaluation success over seeds against training episodes")
    page.heading("Every run")
    page.table(
        ["Task", "Algorithm", "Demos", "Seed", "Success", "Wall time", "Env steps/s once learning", "Commit"],
        [
            [
                o.run.task,
                o.run.algo,
                str(o.run.demos),
                str(o.run.seed),
                percent(o.success),
                f"{o.wall_seconds:.0f} s" + (f" (from episode {o.resumed_from})" if o.resumed_from else ""),
                f"{o.steps_per_second:.0f}",
                str(o.code.get("commit", "unknown"))
                + (" (uncommitted changes)" if o.code.get("uncommitted_changes") else ""),
            ]
            for o in outcomes
        ],
    )
    path = page.write(out_dir, stem="results")["report_md"]
    return path, outcomes


def _machines(outcomes: Sequence[RunOutcome]) -> list[dict[str, Any]]:
    """The distinct machines the runs were measured on."""
    found: dict[str, dict[str, Any]] = {}
    for o in outcomes:
        if o.machine:
            found.setdefault(json.dumps(o.machine, sort_keys=True), o.machine)
    return list(found.values())


def _machine_line(m: dict[str, Any]) -> str:
    cpu = str(m.get("cpu"))
    if m.get("cpu_family"):  # records written before these were kept have only the model name
        cpu += f" (family {m['cpu_family']} model {m['cpu_model']}, {m['simd'] or 'no'} vectors)"
    packages = "".join(f", {name} {version}" for name, version in m.get("packages", {}).items())
    return f"{cpu}, {m.get('cpus')} logical cores, Python {m.get('python')}, torch {m.get('torch')}{packages}"


def _seeds(runs: Sequence[Run]) -> str:
    return ", ".join(str(s) for s in sorted({r.seed for r in runs}))


def _label(cell: Cell) -> str:
    return f"Task {cell.task} {cell.algo} ({cell.demos} demos) {cell.mean_pct:.0f} % against {_paper(cell)}"
