"""The force-limit monitor: every time the measured retraction force passes the limit, as an event.

The filter keeps the *predicted* force below the limit; the monitor watches the *measured* one, so an
exceedance the prediction missed is never silent. One :class:`ForceLimitExceeded` per stretch of ticks
above the limit, with its largest excess and its duration; summaries (evaluate, deploy, sweeps) count
them. It also says, once per episode, when the limit is below what holding the tissue already costs.
"""

from __future__ import annotations

import math
from typing import NamedTuple

__all__ = ["ForceLimitExceeded", "ForceLimitMonitor"]


class ForceLimitExceeded(NamedTuple):
    """One stretch of time with the measured force above the limit.

    Attributes:
        start_s: Stamp of the first reading above the limit [s].
        duration_s: Time above the limit [s] (readings above it times the reading period).
        peak_n: Largest force magnitude in the stretch [N].
        limit_n: The force limit [N].
    """

    start_s: float
    duration_s: float
    peak_n: float
    limit_n: float

    @property
    def excess_n(self) -> float:
        """How far the force went past the limit [N]."""
        return self.peak_n - self.limit_n

    def to_dict(self) -> dict[str, float]:
        """JSON-ready, with the excess."""
        return {**self._asdict(), "excess_n": self.excess_n}


class ForceLimitMonitor:
    """Turns force readings into :class:`ForceLimitExceeded` events.

    Args:
        force_limit_n: The limit [N].
        period_s: Time one reading stands for [s] (the control period).
    """

    def __init__(self, force_limit_n: float, period_s: float) -> None:
        self.force_limit_n = float(force_limit_n)
        self.period_s = float(period_s)
        self.events: list[ForceLimitExceeded] = []
        self._start = math.nan
        self._ticks = 0
        self._peak = 0.0
        self._taken = 0

    def reset(self) -> None:
        """Forget every event (a new episode)."""
        self.events.clear()
        self._ticks = 0
        self._taken = 0

    @property
    def current(self) -> ForceLimitExceeded | None:
        """The stretch under way, if the last reading was above the limit."""
        if not self._ticks:
            return None
        return ForceLimitExceeded(self._start, self._ticks * self.period_s, self._peak, self.force_limit_n)

    def update(self, stamp_s: float, force_norm_n: float) -> None:
        """Take one reading of the force magnitude [N] (non-finite readings are ignored)."""
        if not math.isfinite(force_norm_n):
            return
        if force_norm_n > self.force_limit_n:
            if not self._ticks:
                self._start, self._peak = float(stamp_s), 0.0
            self._ticks += 1
            self._peak = max(self._peak, float(force_norm_n))
        elif self._ticks:
            self.finish()

    def finish(self) -> None:
        """Close the stretch under way, if any (the end of an episode)."""
        current = self.current
        if current is not None:
            self.events.append(current)
        self._ticks = 0

    def take(self) -> list[ForceLimitExceeded]:
        """Events finished since the last call."""
        new = self.events[self._taken :]
        self._taken = len(self.events)
        return new
