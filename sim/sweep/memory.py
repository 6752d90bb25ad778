"""How much memory a sweep's workers hold, trial after trial: growth would bound how long a sweep can run.

Each worker's result comes back with its process id and resident memory after the trial (``worker_pid``,
``worker_rss_mb``, from ``/proc/self/statm``; absent where there is no ``/proc``). :class:`WorkerMemory`
takes them off the record (the stored episode stays a function of the trial alone) and compares, per
worker, the memory after its first :data:`WARM_UP_TRIALS` trials (imports, the first environment and
policy) with its last.
"""

from __future__ import annotations

import os
from typing import Any

__all__ = ["WARM_UP_TRIALS", "WorkerMemory", "resident_mb"]

#: Trials a worker runs before its memory is taken as its baseline.
WARM_UP_TRIALS = 20


def resident_mb() -> float | None:
    """This process's resident memory [MB], or None where ``/proc`` does not tell."""
    try:
        with open("/proc/self/statm") as f:
            pages = int(f.read().split()[1])
    except (OSError, ValueError, IndexError):
        return None
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


class WorkerMemory:
    """Resident memory of each worker process over the trials it ran, in the order they finished."""

    def __init__(self) -> None:
        self.series: dict[int, list[float]] = {}

    def take(self, record: dict[str, Any]) -> dict[str, Any]:
        """Remove the worker's facts from a result (returned) and keep its memory."""
        pid, rss = record.pop("worker_pid", None), record.pop("worker_rss_mb", None)
        if isinstance(pid, int) and isinstance(rss, int | float):
            self.series.setdefault(pid, []).append(float(rss))
        return record

    def growth_mb(self) -> float | None:
        """The largest growth of one worker after its warm-up [MB]; None when no worker ran long enough."""
        rows = [v for v in self.series.values() if len(v) > WARM_UP_TRIALS]
        return max(v[-1] - v[WARM_UP_TRIALS - 1] for v in rows) if rows else None

    def line(self) -> str:
        """Per worker, memory after its warm-up and at its last trial, and the largest growth ("" if none)."""
        rows = [v for v in self.series.values() if len(v) > WARM_UP_TRIALS]
        if not rows:
            return ""
        parts = [f"{v[WARM_UP_TRIALS - 1]:.1f} -> {v[-1]:.1f} MB over {len(v)} episodes" for v in rows]
        return (
            f"worker memory (resident): {'; '.join(parts)} "
            f"(largest growth {self.growth_mb():+.1f} MB after each worker's first {WARM_UP_TRIALS} episodes)"
        )
