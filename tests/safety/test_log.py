"""The safety log's end-of-run summary: interventions, stops, peak force and time at a limit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from safety.log import SafetyLog


def test_summary_counts_interventions_stops_peak_force_and_time_at_limit(tmp_path: Path) -> None:
    """Per limit, interventions and time at the limit are counted from the rows; peak force is the maximum."""
    log = SafetyLog(("a", "b", "c"), dt=0.01, capacity=4)  # small: the arrays must grow
    a, b = log.mask(("a",)), log.mask(("b",))
    zeros = np.zeros(6)
    for k in range(10):
        log.record(
            k * 0.01,
            intervened=a if k < 3 else 0,
            active=(a | b) if k % 2 else b,
            nominal=zeros,
            filtered=zeros,
            force_n=0.1 * k,
            stiffness_n_per_m=400.0 + k,
        )
    log.record(0.1, stop_reason="deadman: measurement 0.2 s old")
    log.record(0.11, stop_reason="deadman: measurement 0.3 s old")
    summary = log.summary()
    assert summary.ticks == 12
    assert summary.duration_s == pytest.approx(0.12)
    assert summary.interventions == {"a": 3, "b": 0, "c": 0}
    assert summary.total_interventions == 3
    assert summary.time_at_limit_s == pytest.approx({"a": 0.05, "b": 0.10, "c": 0.0})
    assert summary.peak_force_n == pytest.approx(0.9)
    assert summary.safety_stops == 2
    assert summary.stop_reasons == {"deadman": 2}
    saved = np.load(log.save(tmp_path / "log.npz"))
    assert list(saved["limit_names"]) == ["a", "b", "c"] and saved["stamp"].shape == (12,)
