"""One interval for success everywhere: the 95 % Wilson interval, labelled ``95 % CI``."""

from __future__ import annotations

import math

import pytest

from sim.evaluation import EpisodeResult, summarize
from sim.success_interval import describe_success


def test_success_is_stated_with_the_wilson_interval() -> None:
    """10 of 10 and 0 of 3 get honest intervals, not +- 0."""
    assert describe_success(10, 10) == "100 % (10 of 10), 95 % CI 72-100 %"
    assert describe_success(0, 3) == "0 % (0 of 3), 95 % CI 0-56 %"
    assert describe_success(2, 8) == "25 % (2 of 8), 95 % CI 7-59 %"


def test_evaluation_summary_carries_the_wilson_interval() -> None:
    """The evaluate summary's ci95 is [low, high] of the Wilson interval."""
    results = [EpisodeResult(i, True, 50, 0.5, "none", 0, False, 0, False, 0.0, 0, 0.0, 0.05, 0, 0) for i in range(10)]
    summary = summarize(results, elapsed_s=1.0)
    low, high = summary["ci95"]
    assert low == pytest.approx(0.7225, abs=1e-3) and high == 1.0
    assert not any(isinstance(v, float) and math.isnan(v) for v in (low, high))
