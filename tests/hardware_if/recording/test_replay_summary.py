"""replay's summary of a run whose force was not finite: a recording keeps such a force as null."""

from __future__ import annotations

import numpy as np

from hardware_if.recording.replay import RecordingSummary


def test_a_null_force_reads_not_finite() -> None:
    summary = RecordingSummary(
        duration_s=1.0,
        commands=3,
        commands_sent=2,
        safety_stop_ticks=0,
        holds=["invalid data: measured_js effort: the calibrated force inf N is no measurement"],
        peak_force_n=float("nan"),
        tracking_error_max=np.zeros(6),
        episodes=[{"episode": 0, "success": False, "steps": 1, "peak_force_n": None}],
        dry_run=False,
        target="dvrk",
        force_limit_exceeded=[{"episode": 0, "peak_n": None, "limit_n": 3.0, "duration_s": 0.01}],
    )
    text = "\n".join(summary.lines())
    assert "peak force: not finite" in text
    assert "episode 0: not finite against 3 N" in text
    assert "episode 0: success=False steps=1 peak force not finite" in text
