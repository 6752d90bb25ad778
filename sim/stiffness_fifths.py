"""Where the force promise stops a retraction: a sweep's success and force-limit stalls by fifth of the
drawn tissue stiffness, the policy's beside the scripted expert's on the same trials.

The safety filter holds the pull at the force limit; on stiff tissue that can stall the retraction short of
its goal (failure class ``force_limit_stall``, :mod:`sim.evaluation`). Ordering a sweep's trials by the
Young's modulus their flap was drawn with and cutting them into five groups of (nearly) equal size, each
fifth says how often the policy succeeded there and how often the limit stopped it; run beside the same
trials by the scripted expert (``robustness --beside-expert``), it tells a stall the limit imposes on any
controller from one the policy could have avoided.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sim.success_interval import wilson_interval
from sim.sweep.stats import THIN_BIN_EPISODES

__all__ = [
    "STALL",
    "STIFFNESS_KEY",
    "StiffnessFifth",
    "by_stiffness_fifth",
    "expert_summary",
    "stiffness_kpa",
    "stop_reason",
]

#: The record's (and the randomization's) name of the flap's Young's modulus [kPa].
STIFFNESS_KEY = "tissue_youngs_modulus_kpa"
#: The failure class of an episode the force limit stopped.
STALL = "force_limit_stall"
_FIFTHS = 5


def stiffness_kpa(record: Mapping[str, Any]) -> float | None:
    """The Young's modulus a trial's flap was drawn with [kPa]: as its episode recorded it, or as the sweep
    fixed it (records of older sweeps); None when neither says."""
    value = record.get(STIFFNESS_KEY, (record.get("options") or {}).get(STIFFNESS_KEY))
    return None if value is None else float(value)


def _finished(records: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    return [r for r in records if "error" not in r]


def _stalled(record: Mapping[str, Any]) -> bool:
    return record.get("failure_class") == STALL


def stop_reason(record: Mapping[str, Any]) -> str | None:
    """What ended an unsuccessful episode (None for a success): its failure class, and for the force limit what its
    bound was on (the last stall event's ``force_source``: ``travel`` or ``measured``)."""
    if record.get("success"):
        return None
    failure = str(record.get("failure_class", "none"))
    if failure != STALL:
        return failure
    events = record.get("force_limit_stall") or ()
    source = str(events[-1].get("force_source", "measured")) if events else "measured"
    return f"{STALL} ({'travel bound' if source == 'travel' else 'measured force'})"


def _largest_peak(records: Sequence[Mapping[str, Any]]) -> float | None:
    """The largest true peak force of ``records`` [N] (None: none recorded one)."""
    peaks = [float(r["peak_force_n"]) for r in records if r.get("peak_force_n") is not None]
    return max(peaks) if peaks else None


def _share(count: int | None, total: int) -> float | None:
    """``count`` of ``total`` as a fraction (None of no episodes)."""
    return None if count is None or total == 0 else count / total


@dataclass(frozen=True)
class StiffnessFifth:
    """One fifth of a sweep's trials, by the drawn stiffness.

    Attributes:
        stiffness_low_kpa: The least Young's modulus among its trials [kPa].
        stiffness_high_kpa: The greatest [kPa].
        trials: Its trials (finished episodes of the policy).
        successes: The policy's successful episodes among them.
        force_limit_stall_episodes: The policy's episodes the force limit stopped (failure class
            ``force_limit_stall``; not the stall events a summary's ``force_limit_stalls`` counts).
        expert_trials: The scripted expert's finished episodes of the same trials (None: no expert pass).
        expert_successes: The expert's successful episodes among them.
        expert_force_limit_stall_episodes: The expert's episodes the force limit stopped.
        stopped_by: What ended the policy's unsuccessful episodes: their failure classes, the force limit's split
            by what its bound was on (``force_limit_stall (travel bound)``: the grasp point's travel, where the
            sensing cannot tell the limit; ``force_limit_stall (measured force)``), with counts.
        largest_peak_n: The largest true peak retraction force of the policy's trials [N] (None: none recorded):
            with exact sensing, what a retraction of this stiffness needed; the room a force limit must leave.
        expert_largest_peak_n: The same of the expert's episodes.
    """

    stiffness_low_kpa: float
    stiffness_high_kpa: float
    trials: int
    successes: int
    force_limit_stall_episodes: int
    expert_trials: int | None = None
    expert_successes: int | None = None
    expert_force_limit_stall_episodes: int | None = None
    stopped_by: dict[str, int] = dataclasses.field(default_factory=dict)
    largest_peak_n: float | None = None
    expert_largest_peak_n: float | None = None

    @property
    def thin(self) -> bool:
        """Too few trials to read its rates alone (the report's thin bins, :data:`THIN_BIN_EPISODES`)."""
        return self.trials < THIN_BIN_EPISODES

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the counts, and their shares of the fifth's trials (``success``, ``force_limit_stall``)."""
        out: dict[str, Any] = {
            "stiffness_low_kpa": self.stiffness_low_kpa,
            "stiffness_high_kpa": self.stiffness_high_kpa,
            "trials": self.trials,
            "thin": self.thin,
            "successes": self.successes,
            "success": self.successes / self.trials,
            "force_limit_stall_episodes": self.force_limit_stall_episodes,
            "force_limit_stall": self.force_limit_stall_episodes / self.trials,
            "stopped_by": dict(self.stopped_by),
            "largest_peak_force_n": self.largest_peak_n,
        }
        if self.expert_trials is not None:
            out.update(
                {
                    "expert_trials": self.expert_trials,
                    "expert_successes": self.expert_successes,
                    "expert_success": _share(self.expert_successes, self.expert_trials),
                    "expert_force_limit_stall_episodes": self.expert_force_limit_stall_episodes,
                    "expert_force_limit_stall": _share(self.expert_force_limit_stall_episodes, self.expert_trials),
                    "expert_largest_peak_force_n": self.expert_largest_peak_n,
                }
            )
        return out


def by_stiffness_fifth(
    records: Sequence[Mapping[str, Any]], expert_records: Sequence[Mapping[str, Any]] | None = None
) -> list[StiffnessFifth]:
    """The policy's finished trials with a known stiffness, ordered by it (then by trial index) and cut into
    five groups whose sizes differ by at most one (fewer groups for fewer than five trials).

    Args:
        records: The policy's sweep records.
        expert_records: The scripted expert's records of the same trials (by ``index``); None: none ran.
    """
    rows = [(stiffness, int(r["index"]), r) for r in _finished(records) if (stiffness := stiffness_kpa(r)) is not None]
    rows.sort(key=lambda row: (row[0], row[1]))
    expert = {int(r["index"]): r for r in _finished(expert_records)} if expert_records is not None else None
    fifths: list[StiffnessFifth] = []
    if not rows:
        return fifths
    for group in np.array_split(np.arange(len(rows)), min(_FIFTHS, len(rows))):
        members = [rows[i] for i in group]
        fifth = StiffnessFifth(
            stiffness_low_kpa=members[0][0],
            stiffness_high_kpa=members[-1][0],
            trials=len(members),
            successes=sum(bool(r.get("success")) for _, _, r in members),
            force_limit_stall_episodes=sum(_stalled(r) for _, _, r in members),
            stopped_by=dict(
                sorted(Counter(reason for _, _, r in members if (reason := stop_reason(r)) is not None).items())
            ),
            largest_peak_n=_largest_peak([r for _, _, r in members]),
        )
        if expert is not None:
            beside = [expert[index] for _, index, _ in members if index in expert]
            fifth = dataclasses.replace(
                fifth,
                expert_trials=len(beside),
                expert_successes=sum(bool(r.get("success")) for r in beside),
                expert_force_limit_stall_episodes=sum(_stalled(r) for r in beside),
                expert_largest_peak_n=_largest_peak(beside),
            )
        fifths.append(fifth)
    return fifths


def expert_summary(expert_records: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The scripted expert's overall numbers beside a sweep's: success with its 95 % Wilson interval, and
    the share of its episodes the force limit stopped."""
    finished = _finished(expert_records)
    successes = sum(bool(r.get("success")) for r in finished)
    stalls = sum(_stalled(r) for r in finished)
    total = len(finished)
    return {
        "expert_episodes": len(expert_records),
        "expert_errors": len(expert_records) - total,
        "expert_successes": successes,
        "expert_success": _share(successes, total),
        "expert_ci95": list(wilson_interval(successes, total)),
        "expert_force_limit_stall_episodes": stalls,
        "expert_force_limit_stall": _share(stalls, total),
    }
