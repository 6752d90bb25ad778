"""The one interval every command states for a success rate: the 95 % Wilson score interval.

Evaluations, sweeps, tuning and the shipped policies' claims all print success as ``90 % (9 of 10),
95 % CI 60-98 %``, so a reader compares like with like (and never meets ``1.000 +- 0.000`` for 10 of 10).
"""

from __future__ import annotations

import math

__all__ = ["describe_success", "wilson_interval"]

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


def describe_success(successes: int, total: int) -> str:
    """Success with its 95 % Wilson interval, as every command prints it: ``90 % (9 of 10), 95 % CI 60-98 %``."""
    if total <= 0:
        return "no episodes"
    low, high = wilson_interval(successes, total)
    return f"{100 * successes / total:.0f} % ({successes} of {total}), 95 % CI {100 * low:.0f}-{100 * high:.0f} %"
