"""Statistics of a sweep: success rates with 95 % confidence intervals, per parameter bin."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["BinStats", "binned_success", "wilson_interval"]

_Z95 = 1.959963984540054


def wilson_interval(successes: int, total: int, z: float = _Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95 % by default).

    Chosen over the normal approximation because it stays inside [0, 1] and behaves at 0 % and
    100 % success, which robustness sweeps hit often.
    """
    if total <= 0:
        return (0.0, 1.0)
    p = successes / total
    denominator = 1.0 + z * z / total
    centre = (p + z * z / (2 * total)) / denominator
    half = z * math.sqrt(p * (1 - p) / total + z * z / (4 * total * total)) / denominator
    # At 0 or all successes the exact bound is 0 or 1; rounding would otherwise leave it a hair inside.
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    high = 1.0 if successes == total else min(1.0, centre + half)
    return (low, high)


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


def binned_success(
    records: Sequence[dict[str, Any]], parameter: str, bins: int = 5, relative: bool = False
) -> list[BinStats]:
    """Split records into ``bins`` bins of one parameter's value and report success per bin.

    Records with an ``error`` are excluded (they are counted separately). Relative parameters are
    binned geometrically.
    """
    rows = [r for r in records if "error" not in r and parameter in r.get("params", {})]
    if not rows:
        return []
    values = np.array([float(r["params"][parameter]) for r in rows])
    low, high = float(values.min()), float(values.max())
    if low == high:
        edges = np.array([low, high])
    elif relative and low > 0:
        edges = np.geomspace(low, high, bins + 1)
    else:
        edges = np.linspace(low, high, bins + 1)
    which = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, len(edges) - 2)
    result = []
    for b in range(len(edges) - 1):
        members = [rows[i] for i in np.flatnonzero(which == b)]
        successes = sum(1 for r in members if r.get("success"))
        forces = [float(r["peak_force_n"]) for r in members if r.get("peak_force_n") is not None]
        ci = wilson_interval(successes, len(members))
        result.append(
            BinStats(
                float(edges[b]),
                float(edges[b + 1]),
                len(members),
                successes,
                ci[0],
                ci[1],
                float(np.percentile(forces, 95)) if forces else math.nan,
                max(forces) if forces else math.nan,
                dict(Counter(str(r.get("failure_class", "none")) for r in members)),
            )
        )
    return result
