"""Statistics of a sweep: success rates with 95 % confidence intervals, per parameter bin."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sim.success_interval import describe_success, wilson_interval

__all__ = ["THIN_BIN_EPISODES", "BinStats", "binned_success", "describe_success", "wilson_interval"]

#: Fewer episodes than this in a bin: its success rate is flagged as thin (with 20 episodes at 50 % success the
#: Wilson 95 % interval is already 30-70 %).
THIN_BIN_EPISODES = 20


@dataclass(frozen=True)
class BinStats:
    """Success within one bin of a varied parameter.

    Attributes:
        low: Bin's lower edge.
        high: Bin's upper edge.
        episodes: Episodes in the bin.
        successes: Successful episodes in the bin.
        ci_low: Lower end of the 95 % interval of the success rate.
        ci_high: Upper end of the 95 % interval.
        peak_force_p95_n: 95th percentile of the episodes' peak force [N] (nan if none reported).
        peak_force_max_n: Largest peak force of the bin's episodes [N] (nan if none reported).
        failure_classes: Episodes per failure class in the bin.
    """

    low: float
    high: float
    episodes: int
    successes: int
    ci_low: float
    ci_high: float
    peak_force_p95_n: float
    peak_force_max_n: float = math.nan
    failure_classes: dict[str, int] = field(default_factory=dict)

    @property
    def success_rate(self) -> float:
        """Fraction of successful episodes (nan for an empty bin)."""
        return self.successes / self.episodes if self.episodes else math.nan


#: An integer parameter with at most this many distinct values gets one bin per value.
_MAX_INTEGER_BINS = 20


def binned_success(
    records: Sequence[dict[str, Any]], parameter: str, bins: int = 5, relative: bool = False, integer: bool = False
) -> list[BinStats]:
    """Split records into ``bins`` bins of one parameter's value and report success per bin.

    Records with an ``error`` are excluded (they are counted separately). Relative parameters are
    binned geometrically. Integer parameters get one bin per value (``low == high``) when they take at
    most 20 values, else bins of whole numbers (``low..high`` inclusive).
    """
    rows = [r for r in records if "error" not in r and parameter in r.get("params", {})]
    if not rows:
        return []
    values = np.array([float(r["params"][parameter]) for r in rows])
    low, high = float(values.min()), float(values.max())
    if integer:
        values = np.round(values)
        distinct = np.unique(values)
        if len(distinct) <= _MAX_INTEGER_BINS:
            starts, ends = distinct, distinct
        else:
            starts = np.unique(np.floor(np.linspace(distinct[0], distinct[-1] + 1, bins + 1)))[:-1]
            ends = np.append(starts[1:] - 1, distinct[-1])
        which = np.searchsorted(starts, values, side="right") - 1
        return [
            _bin(float(starts[b]), float(ends[b]), [rows[i] for i in np.flatnonzero(which == b)])
            for b in range(len(starts))
        ]
    if low == high:
        edges = np.array([low, high])
    elif relative and low > 0:
        edges = np.geomspace(low, high, bins + 1)
    else:
        edges = np.linspace(low, high, bins + 1)
    which = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, len(edges) - 2)
    return [
        _bin(float(edges[b]), float(edges[b + 1]), [rows[i] for i in np.flatnonzero(which == b)])
        for b in range(len(edges) - 1)
    ]


def _bin(low: float, high: float, members: list[dict[str, Any]]) -> BinStats:
    """Success, force and failure classes of one bin's records."""
    successes = sum(1 for r in members if r.get("success"))
    forces = [float(r["peak_force_n"]) for r in members if r.get("peak_force_n") is not None]
    ci = wilson_interval(successes, len(members))
    return BinStats(
        low,
        high,
        len(members),
        successes,
        ci[0],
        ci[1],
        float(np.percentile(forces, 95)) if forces else math.nan,
        max(forces) if forces else math.nan,
        dict(Counter(str(r.get("failure_class", "none")) for r in members)),
    )
