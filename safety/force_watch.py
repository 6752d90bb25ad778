"""What the retraction-force limit did: each excursion above it, and a retraction it held back.

The force limit is a soft row of the safety filter: a force already above the limit takes steps to relax,
and a limit below what holding the tissue costs cannot be met at all. Neither may pass unseen.

- A :class:`ForceLimitWatch` takes the measured force of every control tick and reports each excursion
  above the limit (:class:`ForceExcursion`: when it began, how long it lasted, its peak) so that evaluate,
  deploy, sweeps and recordings count it as a ``force_limit_exceeded`` event. Given the force sensing's
  error bound (a dVRK's ``measured_cf`` is off by newtons in free space), it reports only what the
  measurement can tell: a measured force more than the bound above the limit, where the true force was
  above it too. The simulation watches the true force (bound 0).
- A :class:`ForceLimitStallWatch` tells when the limit, not the policy, stops the retraction: for a
  second with tissue in the jaws the filter cut the policy's motion for the force on nearly every tick
  and the grasp point crawled (below :data:`STALL_SPEED_M_S`). The bound is then kept by not lifting and
  the task stalls; the ``force_limit_stall`` event (:class:`ForceLimitStall`) names the load the held
  tissue put on the jaws meanwhile, its static load where the tool was held, so that a user sees a limit
  set below what the retraction costs.
"""

from __future__ import annotations

import collections
import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

__all__ = [
    "FORCE_LIMIT_EXCEEDED",
    "FORCE_LIMIT_STALL",
    "STALL_SPEED_M_S",
    "ForceExcursion",
    "ForceLimitStall",
    "ForceLimitStallWatch",
    "ForceLimitWatch",
]

#: The excursion event's name in recordings and summaries.
FORCE_LIMIT_EXCEEDED = "force_limit_exceeded"
#: The stall event's name in recordings and summaries.
FORCE_LIMIT_STALL = "force_limit_stall"


@dataclass(frozen=True)
class ForceExcursion:
    """One stretch of consecutive ticks with the force above the limit.

    Attributes:
        start_s: Time of its first tick [s] (the clock the watch was given).
        duration_s: Ticks above the limit times the control period [s].
        peak_n: Largest force magnitude during it [N].
        limit_n: The force limit in force [N].
        open: Still going on at the last tick seen.
        error_n: The force sensing's error bound [N]: the true force reached at least ``peak_n - error_n``.
    """

    start_s: float
    duration_s: float
    peak_n: float
    limit_n: float
    open: bool = False
    error_n: float = 0.0

    @property
    def excess_n(self) -> float:
        """How far the true force went past the limit at least [N]."""
        return self.peak_n - self.error_n - self.limit_n

    @property
    def ratio(self) -> float:
        """The true force's peak over the limit, at least."""
        return (self.peak_n - self.error_n) / self.limit_n

    def to_event(self) -> dict[str, Any]:
        """The ``force_limit_exceeded`` event, JSON-ready."""
        return {"kind": FORCE_LIMIT_EXCEEDED, **asdict(self), "excess_n": self.excess_n, "ratio": self.ratio}


class ForceLimitWatch:
    """Watches the measured force tick by tick and reports its excursions above ``limit_n``.

    Args:
        limit_n: The force limit [N] (positive).
        period_s: The control period [s]: the time each tick above the limit counts for.
        error_n: How far the measured force may be from the true one [N] (0: exact): a tick counts when the
            measured force is above ``limit_n + error_n``.
    """

    def __init__(self, limit_n: float, period_s: float, error_n: float = 0.0) -> None:
        self.limit_n = float(limit_n)
        self.period_s = float(period_s)
        self.error_n = float(error_n)
        self._error = self.error_n  # the widest bound of the excursion in progress
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

    def update(
        self, force_n: np.ndarray | float, stamp_s: float, error_n: float | None = None
    ) -> ForceExcursion | None:
        """Take one tick's measured force (a 3-vector or a magnitude) [N]; return an excursion that just ended.

        ``error_n``: this tick's error bound where it is wider than the watch's (a calibration beyond the
        accelerations it was fitted on, :class:`safety.force_bound.SensingRegime`; inf: the force is not trusted on
        this tick, which is not judged). A non-finite force counts as above the limit: it is no evidence that the
        force is below it.
        """
        vector = np.asarray(force_n, dtype=float).reshape(-1)
        magnitude = float(math.sqrt(float(vector @ vector))) if vector.size > 1 else abs(float(vector[0]))
        tick_error_n = self.error_n if error_n is None else max(self.error_n, float(error_n))
        # NaN fails the comparison; a force not trusted at all (an infinite bound) is no evidence either way.
        if magnitude <= self.limit_n + tick_error_n or tick_error_n == math.inf:
            return self.finish()
        if self._ticks == 0:
            self._start, self._peak, self._error = float(stamp_s), 0.0, self.error_n
        self._error = max(self._error, tick_error_n)
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
        return ForceExcursion(self._start, self._ticks * self.period_s, self._peak, self.limit_n, open_, self._error)


#: A retraction the limit slows below this is stalled [m/s]: measured on the tasks (expert, 1 s windows
#: after the grasp) the grasp point moved at 11-18 mm/s under limits of 0.05 and 0.1 N, where the
#: retraction never finished, and at 25-39 mm/s under the nerve preset's 0.4 N, where it did (25.0 mm/s:
#: Lift, seed 901, since the flap's mesh is scaled at load). 20 mm/s lies between the two.
STALL_SPEED_M_S = 0.020


@dataclass(frozen=True)
class ForceLimitStall:
    """The force limit held the retraction back to a crawl for a whole window while the jaws held tissue.

    Attributes:
        start_s: Time of the window's first tick [s].
        duration_s: The window [s].
        static_load_n: Median force the held tissue put on the jaws over the window's last quarter [N]:
            what holding it where the filter kept the tool costs.
        load_rise_n: How much that load grew over the window (last quarter's median less the first's) [N].
        limit_n: The force limit [N].
        speed_m_s: The grasp point's mean speed over the window, as the filter let it move [m/s].
        asked_speed_m_s: The mean speed the policy asked for [m/s].
        stiffness_n_per_m: The tissue stiffness the filter assumed at the window's last tick [N/m].
        force_source: What the load is from: ``measured`` (the force sensor, with its error bound as
            margin) or ``travel`` (the bound from the grasp point's travel, where the sensing cannot tell
            the limit: :mod:`safety.force_bound`).
    """

    start_s: float
    duration_s: float
    static_load_n: float
    load_rise_n: float
    limit_n: float
    speed_m_s: float
    asked_speed_m_s: float
    stiffness_n_per_m: float
    force_source: str = "measured"

    def to_event(self) -> dict[str, Any]:
        """The ``force_limit_stall`` event, JSON-ready, with the warning for the user as ``text``."""
        return {"kind": FORCE_LIMIT_STALL, **asdict(self), "text": self.warning()}

    def warning(self) -> str:
        """The warning for the user: what happened, what it means, what to change."""
        left_n = max(0.0, self.limit_n - self.static_load_n)
        if self.force_source == "travel":
            return (
                f"force limit {self.limit_n:g} N stalls the retraction: the force sensing cannot tell the limit, so "
                f"the filter bounds the force from the grasp point's travel since the grasp, and that bound reached "
                f"{self.static_load_n:.3f} N ({100 * self.static_load_n / self.limit_n:.0f} % of the limit) at "
                f"{self.stiffness_n_per_m:.0f} N/m; for {self.duration_s:.1f} s it held the tool to "
                f"{1000 * self.speed_m_s:.0f} mm/s (the policy asked for {1000 * self.asked_speed_m_s:.0f}). Calibrate "
                "the force sensing (calibrate-wrench), declare a softer tissue (tissue_stiffness_bound_n_per_m) if it "
                "is, or raise force_limit_n (--safety-config) if the tissue allows it"
            )
        return (
            f"force limit {self.limit_n:g} N stalls the retraction: for {self.duration_s:.1f} s with tissue in "
            f"the jaws the safety filter held it to {1000 * self.speed_m_s:.0f} mm/s (the policy asked for "
            f"{1000 * self.asked_speed_m_s:.0f}). Holding the tissue there costs {self.static_load_n:.3f} N "
            f"({100 * self.static_load_n / self.limit_n:.0f} % of the limit, up {self.load_rise_n:.3f} N in that "
            f"time); at the {self.stiffness_n_per_m:.0f} N/m the filter assumes for the tissue, the {left_n:.3f} N "
            f"left allow {1000 * left_n / self.stiffness_n_per_m:.2f} mm more pull. The bound is kept by not "
            "lifting, so a retraction that takes more than the limit stops here: raise force_limit_n "
            "(--safety-config) if the tissue allows it"
        )


class ForceLimitStallWatch:
    """Tells, once per episode, when the force limit stalls the retraction (see the module notes).

    A stall is a window of ticks with the jaws holding tissue in which the limit cut the policy's motion
    on nearly every tick and the grasp point crawled: a limit that trims a pull now and then, or slows a
    retraction that still gets on, is the filter doing its work and is not reported.

    Args:
        limit_n: The force limit [N].
        period_s: The control period [s].
        window_s: How long the limit must hold the motion back [s].
        held_back: Fraction of the window's ticks on which it must cut the policy's motion (a tick it lets
            through does not end a stall: the filter lets a step through as the force relaxes).
        stall_speed_m_s: The grasp point's mean speed over the window must be below this [m/s].
    """

    def __init__(
        self,
        limit_n: float,
        period_s: float,
        *,
        window_s: float = 1.0,
        held_back: float = 0.9,
        stall_speed_m_s: float = STALL_SPEED_M_S,
    ) -> None:
        self.limit_n = float(limit_n)
        self.period_s = float(period_s)
        self._size = max(1, math.ceil(window_s / period_s - 1e-9))
        self._duration_s = self._size * self.period_s
        self._needed = math.ceil(held_back * self._size - 1e-9)
        self._stall_distance_m = stall_speed_m_s * self._duration_s
        #: Per tick: counted (held back with tissue held), force [N], time [s], asked and allowed motion [m].
        self._window: collections.deque[tuple[bool, float, float, float, float]] = collections.deque(maxlen=self._size)
        self._count = 0
        # The window's allowed motion, kept as it slides: summing a 1 s window of 1 kHz ticks on every tick
        # cost more than the rest of the chain's tick while the limit held a pull back. Non-finite motion is
        # counted apart (it is no evidence of a crawl), and the sum is rebuilt once per window length so
        # that its rounding does not build up.
        self._allowed_m = 0.0
        self._allowed_nonfinite = 0
        self._until_rebuild = self._size
        self.stall: ForceLimitStall | None = None

    def reset(self) -> None:
        """A new episode: forget the window and the stall."""
        self._window.clear()
        self._count = 0
        self._allowed_m = 0.0
        self._allowed_nonfinite = 0
        self._until_rebuild = self._size
        self.stall = None

    def _slide_allowed(self, leaving: float | None, entering: float) -> None:
        """Keep the window's allowed-motion sum as one tick leaves (None: none yet) and one enters."""
        for value, sign in ((leaving, -1), (entering, 1)):
            if value is None:
                continue
            if math.isfinite(value):
                self._allowed_m += sign * value
            else:
                self._allowed_nonfinite += sign
        self._until_rebuild -= 1
        if self._until_rebuild <= 0:
            self._allowed_m = math.fsum(e[4] for e in self._window if math.isfinite(e[4]))
            self._until_rebuild = self._size

    def update(
        self,
        *,
        holding: bool,
        held_back: bool,
        force_n: float,
        asked_m: float,
        allowed_m: float,
        stiffness_n_per_m: float,
        stamp_s: float,
        force_source: str = "measured",
    ) -> ForceLimitStall | None:
        """Take one tick; return the stall on the tick it is first seen (at most once until :meth:`reset`).

        Args:
            holding: The jaws may hold tissue this tick.
            held_back: The force limit cut the policy's motion this tick.
            force_n: The measured force magnitude [N].
            asked_m: How far the policy's step would move the grasp point [m].
            allowed_m: How far the filtered step moves it [m].
            stiffness_n_per_m: The tissue stiffness the filter assumes this tick [N/m].
            stamp_s: The tick's time [s].
            force_source: What ``force_n`` is from (:class:`ForceLimitStall`).
        """
        counted = bool(holding and held_back and math.isfinite(force_n))
        leaving = None
        if len(self._window) == self._size:
            self._count -= self._window[0][0]
            leaving = self._window[0][4]
        self._window.append((counted, float(force_n), float(stamp_s), float(asked_m), float(allowed_m)))
        self._count += counted
        self._slide_allowed(leaving, float(allowed_m))
        if self.stall is not None or len(self._window) < self._size or self._count < self._needed:
            return None
        if self._allowed_nonfinite or not self._allowed_m <= self._stall_distance_m:  # NaN motion: no evidence
            return None
        allowed = math.fsum(entry[4] for entry in self._window)  # once per episode: the exact figure
        if not allowed <= self._stall_distance_m:
            return None
        loads = [force for counted, force, *_ in self._window if counted]
        quarter = max(1, len(loads) // 4)
        static_load = float(np.median(loads[-quarter:]))
        self.stall = ForceLimitStall(
            start_s=self._window[0][2],
            duration_s=self._duration_s,
            static_load_n=static_load,
            load_rise_n=static_load - float(np.median(loads[:quarter])),
            limit_n=self.limit_n,
            speed_m_s=allowed / self._duration_s,
            asked_speed_m_s=sum(entry[3] for entry in self._window) / self._duration_s,
            stiffness_n_per_m=float(stiffness_n_per_m),
            force_source=force_source,
        )
        return self.stall
