"""Run a sweep's trials on a local process pool or on Ray, retrying trials whose worker died.

A worker is a top-level function named ``"module:function"`` that takes a trial (as a dict) and
keyword arguments and returns a JSON-ready dict. It runs in a separate process (one physics client
per process); it may cache expensive set-up (an environment, a policy) in module globals, since a
worker process serves many trials. Results are stored the moment they arrive.
"""

from __future__ import annotations

import importlib
import os
import sys
import traceback
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from multiprocessing import get_context
from typing import Any

from tqdm import tqdm

from psm_control.errors import ConfigurationError, UnknownVariantError
from sim.sweep.cluster import ray_cluster
from sim.sweep.memory import WorkerMemory, resident_mb
from sim.sweep.space import Trial
from sim.sweep.stopping import STOP_GRACE_S, pool_worker_start, stop_pool
from sim.sweep.store import EpisodeStore

__all__ = ["BACKENDS", "call_worker", "cap_jobs", "run_trials"]

#: Execution backends.
BACKENDS = ("local", "ray")


def _resolve(worker: str) -> Callable[..., dict[str, Any]]:
    module_name, sep, function_name = worker.partition(":")
    if not sep:
        raise ConfigurationError("worker", worker, "'module:function'")
    function = getattr(importlib.import_module(module_name), function_name, None)
    if not callable(function):
        raise ConfigurationError("worker", worker, "the name of a callable")
    return function


def call_worker(worker: str, trial: dict[str, Any], kwargs: dict[str, Any]) -> dict[str, Any]:
    """Run one trial in the current process; an exception becomes an error record, not a lost trial."""
    try:
        outcome = _resolve(worker)(trial, **kwargs)
    except KeyboardInterrupt:
        raise
    except BaseException as e:
        return {**trial, "error": f"{type(e).__name__}: {e}", "traceback": traceback.format_exc(limit=5)}
    return {**trial, **outcome, "worker_pid": os.getpid(), "worker_rss_mb": resident_mb()}


def cap_jobs(jobs: int | None) -> int:
    """Worker processes for ``--jobs``: at most the machine's cores (more only compete for them).

    Raises:
        ConfigurationError: ``jobs`` below 1.
    """
    cores = os.cpu_count() or 1
    if jobs is None:
        return cores
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ConfigurationError("jobs", jobs, f"an integer from 1 to the {cores} cores")
    if jobs > cores:
        print(f"--jobs {jobs} capped to this machine's {cores} cores", file=sys.stderr)
    return min(jobs, cores)


def _crash_record(trial: Trial, attempts: int) -> dict[str, Any]:
    return {**trial.to_dict(), "error": f"worker process died on all {attempts} attempts"}


def _run_local(
    pending: list[Trial],
    worker: str,
    kwargs: dict[str, Any],
    jobs: int,
    store: EpisodeStore,
    max_attempts: int,
    progress: tqdm,
    memory: WorkerMemory,
) -> None:
    attempts = {t.index: 0 for t in pending}
    queue = list(pending)
    while queue:
        # A pool breaks as a whole when one of its processes dies; the trials it was running are
        # charged one attempt each and the pool is rebuilt for whatever is left.
        with ProcessPoolExecutor(
            max_workers=min(jobs, len(queue)), mp_context=get_context("spawn"), initializer=pool_worker_start
        ) as pool:
            running: dict[Future[dict[str, Any]], Trial] = {}
            broken = False
            try:
                while (queue or running) and not broken:
                    while queue and len(running) < 2 * jobs and not broken:
                        trial = queue[0]
                        try:
                            future = pool.submit(call_worker, worker, trial.to_dict(), kwargs)
                        except BrokenProcessPool:
                            broken = True
                            break
                        queue.pop(0)
                        attempts[trial.index] += 1
                        running[future] = trial
                    if not running:
                        break
                    finished, _ = wait(running, return_when=FIRST_COMPLETED)
                    for future in finished:
                        trial = running.pop(future)
                        try:
                            record = future.result()
                        except BrokenProcessPool:
                            broken = True
                            queue.insert(0, trial)
                            continue
                        store.append(memory.take(record))
                        progress.update(1)
            except KeyboardInterrupt:  # a stop signal: start nothing new, keep the trials that finish in the grace
                wait(running, timeout=STOP_GRACE_S)
                for future in running:
                    if future.done() and not future.cancelled() and future.exception() is None:
                        store.append(memory.take(future.result()))
                        progress.update(1)
                stop_pool(pool)  # the rest never finished: the resumed sweep runs them
                raise
            if broken:
                for future, trial in running.items():
                    future.cancel()
                    queue.insert(0, trial)
                for trial in [t for t in queue if attempts[t.index] >= max_attempts]:
                    queue.remove(trial)
                    store.append(_crash_record(trial, attempts[trial.index]))
                    progress.update(1)
                queue.sort(key=lambda t: t.index)


def _run_ray(
    pending: list[Trial],
    worker: str,
    kwargs: dict[str, Any],
    jobs: int,
    store: EpisodeStore,
    max_attempts: int,
    progress: tqdm,
    memory: WorkerMemory,
) -> None:
    with ray_cluster(jobs) as ray:
        # Ray re-runs a task whose worker process died, up to max_retries times.
        remote = ray.remote(max_retries=max_attempts - 1, retry_exceptions=False)(call_worker)
        refs = {remote.remote(worker, t.to_dict(), kwargs): t for t in pending}
        while refs:
            ready, _ = ray.wait(list(refs), num_returns=1)
            for ref in ready:
                trial = refs.pop(ref)
                try:
                    record = ray.get(ref)
                except (ray.exceptions.WorkerCrashedError, ray.exceptions.RayTaskError) as e:
                    record = {**_crash_record(trial, max_attempts), "error_detail": str(e)[:500]}
                store.append(memory.take(record))
                progress.update(1)


def run_trials(
    trials: Sequence[Trial],
    worker: str,
    *,
    store: EpisodeStore,
    backend: str = "local",
    jobs: int | None = None,
    worker_kwargs: dict[str, Any] | None = None,
    max_attempts: int = 3,
    show_progress: bool = True,
) -> list[dict[str, Any]]:
    """Run every trial not yet in ``store`` and return all records in trial order.

    Args:
        trials: The sweep.
        worker: ``"module:function"`` run once per trial in a worker process.
        store: Where results go; trials already in it are skipped (resumption).
        backend: ``"local"`` (a process pool) or ``"ray"`` (``RAY_ADDRESS`` or a local cluster).
        jobs: Worker processes (default and at most: all cores).
        worker_kwargs: Keyword arguments for the worker (must pickle).
        max_attempts: Tries per trial when its worker process dies; after that it is recorded as an error.
        show_progress: Show a progress bar.

    Raises:
        UnknownVariantError: Unknown backend.
        ConfigurationError: Bad worker name, jobs or attempts.
    """
    if backend not in BACKENDS:
        raise UnknownVariantError("backend", backend, BACKENDS)
    jobs = cap_jobs(jobs)
    if max_attempts < 1:
        raise ConfigurationError("max_attempts", max_attempts, "an integer >= 1")
    _resolve(worker)  # fail fast, before any process starts
    done = store.done()
    memory = WorkerMemory()
    pending = [t for t in trials if t.index not in done]
    with tqdm(
        total=len(trials), initial=len(trials) - len(pending), desc="episodes", unit="ep", disable=not show_progress
    ) as progress:
        if pending:
            run = _run_local if backend == "local" else _run_ray
            run(pending, worker, dict(worker_kwargs or {}), jobs, store, max_attempts, progress, memory)
    if memory.line():
        print(memory.line(), file=sys.stderr)
    wanted = {t.index for t in trials}
    return [r for r in store.ordered() if r["index"] in wanted]
