"""bench rehearsal reads a deploy's recording: the holds with what they said."""

from __future__ import annotations

from pathlib import Path

from hardware_if.recording.recorder import Recorder
from tissue_retract.cli.bench_rehearsal import _timing


def test_a_hold_is_reported_with_its_reason(tmp_path: Path) -> None:
    """A hold event's text (what the deploy printed on HOLD) is what the rehearsal reports, not an empty string."""
    path = tmp_path / "run.mcap"
    with Recorder(path) as recorder:
        recorder.write("/deploy/event", {"kind": "hold", "text": "stale: measured_js 0.2 s old", "fault": "stale"})
    assert _timing(path)["holds"] == ["stale: measured_js 0.2 s old"]
