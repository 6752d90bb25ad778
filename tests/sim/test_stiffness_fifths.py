"""Success and force-limit stops by fifth of the drawn stiffness, the expert's beside."""

from __future__ import annotations

import itertools
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.stiffness_fifths import STALL, STIFFNESS_KEY, by_stiffness_fifth, expert_summary, stiffness_kpa
from sim.sweep.stats import THIN_BIN_EPISODES

_OUTCOMES = st.sampled_from(["none", STALL, "timeout", "error"])


def _records(outcomes: list[tuple[float, str]]) -> list[dict[str, Any]]:
    records: list[dict[str, Any]] = []
    for index, (stiffness, outcome) in enumerate(outcomes):
        if outcome == "error":
            records.append({"index": index, "error": "RuntimeError: boom"})
        else:
            records.append(
                {"index": index, STIFFNESS_KEY: stiffness, "success": outcome == "none", "failure_class": outcome}
            )
    return records


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.tuples(st.floats(2.0, 30.0), _OUTCOMES), max_size=60),
    st.lists(_OUTCOMES, max_size=60),
)
def test_fifths_partition_the_finished_trials_in_stiffness_order(
    policy: list[tuple[float, str]], expert: list[str]
) -> None:
    """Every finished trial is in exactly one fifth; fifths differ in size by at most one, follow each other in
    stiffness, count their successes and stalls, and hold the expert's episodes of the same trials."""
    records = _records(policy)
    expert_records = _records([(0.0, outcome) for outcome in expert])
    fifths = by_stiffness_fifth(records, expert_records)
    finished = [r for r in records if "error" not in r]
    assert sum(f.trials for f in fifths) == len(finished)
    assert len(fifths) == min(5, len(finished))
    assert max((f.trials for f in fifths), default=0) - min((f.trials for f in fifths), default=0) <= 1
    assert all(f.stiffness_low_kpa <= f.stiffness_high_kpa for f in fifths)
    assert all(a.stiffness_high_kpa <= b.stiffness_low_kpa for a, b in itertools.pairwise(fifths))
    assert sum(f.successes for f in fifths) == sum(r["success"] for r in finished)
    assert sum(f.force_limit_stall_episodes for f in fifths) == sum(r["failure_class"] == STALL for r in finished)
    expert_done = {r["index"]: r for r in expert_records if "error" not in r}
    beside = [expert_done[r["index"]] for r in finished if r["index"] in expert_done]
    assert sum(f.expert_trials or 0 for f in fifths) == len(beside)
    assert sum(f.expert_successes or 0 for f in fifths) == sum(r["success"] for r in beside)
    for f in fifths:
        row = f.to_dict()
        assert row["thin"] == (f.trials < THIN_BIN_EPISODES)
        assert row["success"] == f.successes / f.trials
        assert row["force_limit_stall"] == f.force_limit_stall_episodes / f.trials


def test_without_an_expert_pass_the_fifths_have_no_expert_fields() -> None:
    """A sweep without --beside-expert: the fifths' records name the policy's numbers only."""
    records = _records([(float(k), "none") for k in range(7)])
    assert all(not any(key.startswith("expert") for key in f.to_dict()) for f in by_stiffness_fifth(records))


def test_the_stiffness_of_an_older_record_is_its_swept_option() -> None:
    """A record without the drawn modulus (an older sweep's) takes the one the sweep fixed; without either, none."""
    assert stiffness_kpa({"options": {STIFFNESS_KEY: 12.5}}) == 12.5
    assert stiffness_kpa({STIFFNESS_KEY: 8.0, "options": {STIFFNESS_KEY: 12.5}}) == 8.0
    assert stiffness_kpa({"options": {}}) is None


def test_the_experts_overall_success_has_its_wilson_interval() -> None:
    """9 of 10 with one error: success 9/10, the interval every command states for it, one error counted."""
    records = _records([(10.0, "none")] * 9 + [(10.0, STALL), (10.0, "error")])
    summary = expert_summary(records)
    assert summary["expert_success"] == 0.9 and summary["expert_errors"] == 1
    assert summary["expert_force_limit_stall"] == 0.1
    assert summary["expert_ci95"][0] < 0.9 < summary["expert_ci95"][1] < 1.0


def test_each_fifth_names_the_largest_true_peak_force_of_its_trials() -> None:
    """The policy's and the expert's largest true peak retraction force per fifth: what retracting that stiffness
    took; none where no episode recorded one."""
    records = [{"index": k, STIFFNESS_KEY: float(k), "success": True, "peak_force_n": 0.1 * k} for k in range(10)]
    expert = [{"index": k, STIFFNESS_KEY: float(k), "success": True, "peak_force_n": 0.2 * (9 - k)} for k in range(10)]
    fifths = by_stiffness_fifth(records, expert)
    assert [f.largest_peak_n for f in fifths] == pytest.approx([0.1, 0.3, 0.5, 0.7, 0.9])
    assert [f.to_dict()["expert_largest_peak_force_n"] for f in fifths] == [
        1.8,
        1.4000000000000001,
        1.0,
        0.6000000000000001,
        0.2,
    ]
    assert (
        by_stiffness_fifth([{"index": 0, STIFFNESS_KEY: 1.0, "success": True}])[0].to_dict()["largest_peak_force_n"]
        is None
    )
