"""Every stretch of time the measured retraction force spends above its limit, with its amount and duration.

The force limit is a soft row of the safety filter: a force already above the limit takes steps to relax,
and a limit below what holding the tissue costs cannot be met at all. Neither may pass unseen. A
:class:`ForceLimitWatch` takes the measured force of every control tick and reports each excursion above
the limit (:class:`ForceExcursion`: when it began, how long it lasted, its peak) so that evaluate, deploy,
sweeps and recordings count it as a ``force_limit_exceeded`` event.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["FORCE_LIMIT_EXCEEDED", "ForceExcursion", "ForceLimitWatch"]

#: The event's name in recordings and summaries.
FORCE_LIMIT_EXCEEDED = "force_limit_exceeded"


@dataclass(frozen=True)
class ForceExcursion:
    """One stretch of consecutive ticks with the force above the limit.

    Attributes:
        start_s: Time of its first tick [s] (the clock the watch was given).
        duration_s: Ticks above the limit times the control period [s].
        peak_n: Largest force magnitude during it [N].
        limit_n: The force limit in force [N].
        open: Still going on at the last tick seen.
    """

    start_s: float
    duration_s: float
    peak_n: float
    limit_n: float
    open: bool = False

    @property
    def excess_n(self) -> float:
        """How far the peak went past the limit [N]."""
        return self.peak_n - self.limit_n

    @property
    def ratio(self) -> float:
        """Peak over limit."""
        return self.peak_n / self.limit_n

    def to_event(self) -> dict[str, Any]:
        """The ``force_limit_exceeded`` event, JSON-ready."""
        return {
            "kind": FORCE_LIMIT_EXCEEDED,
            "start_s": self.start_s,
            "duration_s": self.duration_s,
            "peak_n": self.peak_n,
            "limit_n": self.limit_n,
            "excess_n": self.excess_n,
            "ratio": self.ratio,
            "open": self.open,
        }


class ForceLimitWatch:
    """Watches the measured force tick by tick and reports its excursions above ``limit_n``.

    Args:
        limit_n: The force limit [N] (positive).
        period_s: The control period [s]: the time each tick above the limit counts for.
    """

    def __init__(self, limit_n: float, period_s: float) -> None:
        self.limit_n = float(limit_n)
        self.period_s = float(period_s)
        self.excursions: list[ForceExcursion] = []
        self._start = 0.0
        self._ticks = 0
        self._peak = 0.0

    def reset(self) -> None:
        """A new run or episode: forget every excursion."""
        self.excursions = []
        self._ticks = 0
        self._peak = 0.0

    @property
    def above(self) -> bool:
        """The last tick's force was above the limit."""
        return self._ticks > 0

    def update(self, force_n: np.ndarray | float, stamp_s: float) -> ForceExcursion | None:
        """Take one tick's measured force (a 3-vector or a magnitude) [N]; return an excursion that just ended.

        A non-finite force counts as above the limit: it is no evidence that the force is below it.
        """
        vector = np.asarray(force_n, dtype=float).reshape(-1)
        magnitude = float(math.sqrt(float(vector @ vector))) if vector.size > 1 else abs(float(vector[0]))
        if magnitude <= self.limit_n:  # NaN fails this comparison
            return self.finish()
        if self._ticks == 0:
            self._start, self._peak = float(stamp_s), 0.0
        self._ticks += 1
        self._peak = max(self._peak, magnitude) if math.isfinite(magnitude) else math.inf
        return None

    def finish(self) -> ForceExcursion | None:
        """End an excursion in progress (at the end of an episode) and return it, or None."""
        if self._ticks == 0:
            return None
        excursion = self._current(open_=False)
        self.excursions.append(excursion)
        self._ticks = 0
        return excursion

    def all(self) -> list[ForceExcursion]:
        """Every excursion so far, the one in progress included (marked ``open``)."""
        return self.excursions + ([self._current(open_=True)] if self._ticks else [])

    def _current(self, *, open_: bool) -> ForceExcursion:
        return ForceExcursion(self._start, self._ticks * self.period_s, self._peak, self.limit_n, open_)
