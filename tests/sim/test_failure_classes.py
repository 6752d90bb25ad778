"""An unsuccessful episode is classed by its gravest event; a force-limit stall explains an otherwise bare timeout."""

from __future__ import annotations

from sim.evaluation import FAILURE_CLASSES, failure_class


def test_the_gravest_event_names_the_failure() -> None:
    assert failure_class(False, {"grip_loss": 3, "safety_stop": 1}, stalled=True) == "safety_stop"
    assert failure_class(False, {"sim_unstable": 1, "safety_stop": 9}, stalled=False) == "sim_unstable"
    assert failure_class(False, {"improper_grasp": 0, "grip_loss": 2}, stalled=False) == "grip_loss"


def test_a_stall_explains_a_failure_with_no_graver_event() -> None:
    assert failure_class(False, {"safety_stop": 0}, stalled=True) == "force_limit_stall"
    assert failure_class(False, {}, stalled=False) == "timeout"


def test_a_success_has_no_failure_class_whatever_it_met() -> None:
    assert failure_class(True, {"grip_loss": 1}, stalled=True) == "none"


def test_every_class_it_gives_is_listed() -> None:
    given = {
        failure_class(False, {event: 1}, stalled=False)
        for event in ("sim_unstable", "safety_stop", "invalid_action", "tissue_damage", "grip_loss", "improper_grasp")
    }
    given |= {failure_class(False, {}, stalled=s) for s in (True, False)} | {failure_class(True, {}, stalled=False)}
    assert given == set(FAILURE_CLASSES)
