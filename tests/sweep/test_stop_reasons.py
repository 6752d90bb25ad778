"""What ended a sweep's unsuccessful retractions, said per fifth of the drawn stiffness, with the run's warnings
on the report page and the held tissue's force named for what it is (a measurement, or the travel bound)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from sim.evaluation import describe_stalls
from sim.stiffness_fifths import STALL, STIFFNESS_KEY, by_stiffness_fifth, stop_reason
from sim.sweep.report import write_report


def _record(index: int, stiffness: float, outcome: str, source: str = "travel") -> dict[str, Any]:
    stalls = [{"force_source": source, "static_load_n": 3.0, "limit_n": 3.0}] if outcome == STALL else []
    return {
        "index": index,
        STIFFNESS_KEY: stiffness,
        "success": outcome == "none",
        "failure_class": outcome,
        "force_limit_stall": stalls,
        "peak_force_n": 0.1,
        "options": {},
    }


def _records() -> list[dict[str, Any]]:
    outcomes = [("none", "travel"), (STALL, "travel"), (STALL, "measured"), ("timeout", "travel"), ("none", "")]
    return [_record(i, 3.0 + i, outcome, source) for i, (outcome, source) in enumerate(outcomes * 2)]


def test_each_unsuccessful_episode_names_what_ended_it() -> None:
    records = _records()
    assert [stop_reason(r) for r in records[:5]] == [
        None,
        f"{STALL} (travel bound)",
        f"{STALL} (measured force)",
        "timeout",
        None,
    ]
    fifths = by_stiffness_fifth(records)
    assert sum(sum(f.stopped_by.values()) for f in fifths) == 6
    assert sum(f.stopped_by.get(f"{STALL} (travel bound)", 0) for f in fifths) == 2
    assert all(f.to_dict()["stopped_by"] == f.stopped_by for f in fifths)


def test_the_report_page_carries_the_warnings_and_the_reasons(tmp_path: Path) -> None:
    warning = "WARNING: force limit 3 N is below the force sensing's error bound 7.21 N (dvrk-calibrated): ..."
    files = write_report(
        tmp_path,
        _records(),
        [],
        title="Robustness",
        context={"policy": "toy"},
        force_limit_n=3.0,
        warnings=[warning],
    )
    for name in ("report_md", "report_html"):
        text = files[name].read_text()
        assert "Warnings at the start of the run" in text and "force limit 3 N is below" in text
        assert "what ended the policy&#x27;s unsuccessful episodes" in text or "what ended the policy's" in text
        assert f"{STALL} (travel bound) 1" in text and "timeout 1" in text


def test_the_held_tissue_force_is_named_for_what_it_is() -> None:
    summary = {"force_limit_stalls": 2, "stall_static_load_n": 3.0, "stall_static_load_to_limit": 1.0}
    travel = describe_stalls({**summary, "stall_force_sources": {"travel": 2}})
    assert "the travel bound on the held tissue's force, not a measured force" in travel
    measured = describe_stalls({**summary, "stall_force_sources": {"measured": 2}})
    assert "the measured force on the held tissue was 3.000 N" in measured
    both = describe_stalls({**summary, "stall_force_sources": {"measured": 1, "travel": 1}})
    assert "measured in 1 and bounded by its travel in 1" in both
