"""replay's summary: a run whose force was not finite (a recording keeps such a force as null), and a recording
from before deploys recorded their force sensing."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hardware_if.recording.recorder import Recorder
from hardware_if.recording.replay import NOT_RECORDED, RecordingSummary, load_recording, summarize_recording
from hardware_if.recording.replay_figure import draw_recording


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


def test_an_old_recording_without_the_sensing_replays_and_says_it_was_not_recorded(tmp_path: Path) -> None:
    """A recording from before deploys recorded their sensing (its meta's only sensing key the stale
    ``"force_sensing": "ideal"`` of a dVRK deploy) replays, says its sensing was not recorded, and plots
    without an error band or a travel bound."""
    path = tmp_path / "old.mcap"
    with Recorder(path) as recorder:
        meta = {"policy": "scripted", "target": "dvrk", "task": "lift", "dry_run": False, "force_sensing": "ideal"}
        recorder.write("/deploy/meta", meta)
        recorder.write("/deploy/event", {"kind": "episode_start", "episode": 0, "seed": 0})
        for k in range(3):
            recorder.write("/deploy/measured", {"q": [0.0] * 6, "force_n": [0.1 * k, 0.0, 0.0], "stamp_s": 0.01 * k})
            recorder.write("/deploy/command", {"q": [0.0] * 6, "sent": True, "safety_stop": False, "stamp_s": 0.01 * k})
        recorder.write("/deploy/report", {"force_limit_n": 3.0})
    rec = load_recording(path)
    assert f"force sensing: {NOT_RECORDED}" in summarize_recording(rec).lines()
    assert np.isnan(rec.travel_bound_n).all() and len(rec.travel_bound_n) == 3
    force = draw_recording(rec).axes[0]
    labels = [a.get_label() for a in (*force.get_lines(), *force.collections)]
    assert "force limit 3 N" in labels and "measured |force|" in labels
    assert not [label for label in labels if label.startswith(("sensing error", "travel bound"))], labels
