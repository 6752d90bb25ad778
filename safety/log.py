"""The safety log: one compact row per tick and a summary at the end of every run.

Per tick it keeps the time, whether the tick stopped, which limits intervened and which were active
(bit masks over the limit names), the nominal and filtered joint steps, the retraction force and the
stiffness estimate, in preallocated NumPy arrays (no per-tick Python objects), and the text of every
safety stop. :meth:`SafetyLog.save` writes one compressed ``.npz``; :meth:`SafetyLog.summary` gives the
numbers a run ends with: interventions per limit, safety stops, peak force and time spent at a limit.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["SafetyLog", "SafetySummary"]


@dataclass(frozen=True)
class SafetySummary:
    """End-of-run safety figures.

    Attributes:
        ticks: Ticks recorded.
        duration_s: Time covered [s].
        safety_stops: Ticks that held or braked instead of following the policy.
        stop_reasons: Count of each stop reason's first words.
        interventions: Per limit, ticks where the nominal command violated it.
        time_at_limit_s: Per limit, time during which it was active [s].
        peak_force_n: Largest retraction-force magnitude seen [N].
        final_stiffness_n_per_m: Last stiffness estimate [N/m].
    """

    ticks: int
    duration_s: float
    safety_stops: int
    stop_reasons: dict[str, int] = field(default_factory=dict)
    interventions: dict[str, int] = field(default_factory=dict)
    time_at_limit_s: dict[str, float] = field(default_factory=dict)
    peak_force_n: float = 0.0
    final_stiffness_n_per_m: float = float("nan")

    @property
    def total_interventions(self) -> int:
        """Interventions summed over the limits."""
        return sum(self.interventions.values())


class SafetyLog:
    """Compact per-tick record of what the safety layer did.

    Args:
        limit_names: Names of the filter's limits, in order (at most 32).
        dt: Control period [s].
        dof: Joints per step.
        capacity: Initial number of rows; the arrays double when full.
    """

    def __init__(self, limit_names: tuple[str, ...], dt: float, dof: int = 6, capacity: int = 4096) -> None:
        if len(limit_names) > 32:
            raise ValueError(f"at most 32 limits can be logged, got {len(limit_names)}")
        self.limit_names = tuple(limit_names)
        self.dt = dt
        self.dof = dof
        self._bits = {name: np.uint32(1 << i) for i, name in enumerate(self.limit_names)}
        self._allocate(capacity)
        self.stops: list[tuple[float, str]] = []

    def _allocate(self, capacity: int) -> None:
        self.n = 0
        self.stamp = np.zeros(capacity)
        self.stopped = np.zeros(capacity, dtype=bool)
        self.intervened = np.zeros(capacity, dtype=np.uint32)
        self.active = np.zeros(capacity, dtype=np.uint32)
        self.nominal = np.zeros((capacity, self.dof), dtype=np.float32)
        self.filtered = np.zeros((capacity, self.dof), dtype=np.float32)
        self.force = np.zeros(capacity, dtype=np.float32)
        self.stiffness = np.zeros(capacity, dtype=np.float32)

    def clear(self) -> None:
        """Forget every row (keeps the memory)."""
        self.n = 0
        self.stops.clear()

    def _grow(self) -> None:
        for name in ("stamp", "stopped", "intervened", "active", "nominal", "filtered", "force", "stiffness"):
            old = getattr(self, name)
            new = np.zeros((2 * old.shape[0], *old.shape[1:]), dtype=old.dtype)
            new[: old.shape[0]] = old
            setattr(self, name, new)

    def mask(self, names: tuple[str, ...]) -> int:
        """Bit mask of the named limits."""
        value = 0
        for name in names:
            value |= int(self._bits[name])
        return value

    def record(
        self,
        stamp_s: float,
        *,
        stop_reason: str = "",
        intervened: int = 0,
        active: int = 0,
        nominal: np.ndarray | None = None,
        filtered: np.ndarray | None = None,
        force_n: float = 0.0,
        stiffness_n_per_m: float = 0.0,
    ) -> None:
        """Append one tick."""
        if self.n == self.stamp.shape[0]:
            self._grow()
        i = self.n
        self.stamp[i] = stamp_s
        self.stopped[i] = bool(stop_reason)
        self.intervened[i] = intervened
        self.active[i] = active
        self.nominal[i] = 0.0 if nominal is None else nominal
        self.filtered[i] = 0.0 if filtered is None else filtered
        self.force[i] = force_n
        self.stiffness[i] = stiffness_n_per_m
        if stop_reason:
            self.stops.append((stamp_s, stop_reason))
        self.n += 1

    def summary(self) -> SafetySummary:
        """The end-of-run figures."""
        n = self.n
        interventions = {name: int(np.count_nonzero(self.intervened[:n] & bit)) for name, bit in self._bits.items()}
        at_limit = {name: float(np.count_nonzero(self.active[:n] & bit)) * self.dt for name, bit in self._bits.items()}
        reasons = Counter(reason.split(":")[0] for _, reason in self.stops)
        return SafetySummary(
            ticks=n,
            duration_s=n * self.dt,
            safety_stops=int(np.count_nonzero(self.stopped[:n])),
            stop_reasons=dict(reasons),
            interventions=interventions,
            time_at_limit_s=at_limit,
            peak_force_n=float(self.force[:n].max()) if n else 0.0,
            final_stiffness_n_per_m=float(self.stiffness[n - 1]) if n else float("nan"),
        )

    def save(self, path: str | Path) -> Path:
        """Write the rows, the limit names and the stop texts to a compressed ``.npz``."""
        path = Path(path)
        n = self.n
        np.savez_compressed(
            path,
            limit_names=np.array(self.limit_names),
            stamp=self.stamp[:n],
            stopped=self.stopped[:n],
            intervened=self.intervened[:n],
            active=self.active[:n],
            nominal=self.nominal[:n],
            filtered=self.filtered[:n],
            force=self.force[:n],
            stiffness=self.stiffness[:n],
            stop_stamp=np.array([s for s, _ in self.stops]),
            stop_reason=np.array([r for _, r in self.stops]),
        )
        return path
