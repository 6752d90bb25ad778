"""Registration sanity: a site registered with the jaws on the flap passes; open jaws or the air do not."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from hardware_if.client.registration_checks import check_registration
from hardware_if.console.sim_task import PLACEABLE_SITES, TaskArm


@pytest.fixture(scope="module")
def lift() -> Iterator[TaskArm]:
    """The Task I scene of seed 2, as sim-dvrk --blind serves it."""
    arm = TaskArm("lift", seed=2, blind=True)
    yield arm
    arm.close()


@pytest.mark.parametrize("name", PLACEABLE_SITES)
def test_jaws_placed_on_a_site_register_it_without_findings(lift: TaskArm, name: str) -> None:
    """Jaws placed on a site have their grasp point on it (0.1 mm) and that registration raises nothing."""
    sample = lift.reset(lift.jaws_on(name), 0.0)
    state = lift.task_state()
    if name == "site":
        assert np.linalg.norm(state["grasp_point"] - state["site"]) < 1e-4
    assert check_registration(state["grasp_point"], lift.base_frame, sample.jaw) == []


def test_jaws_open_in_the_air_are_refused_with_numbers(lift: TaskArm) -> None:
    """At the start joints' RCM (the 14 cm case): open jaws and a site outside the box are refused, in numbers."""
    lift.reset(np.zeros(6), 0.6)
    findings = check_registration(lift.task_state()["grasp_point"], lift.base_frame, 0.6)
    refusals = [f.text for f in findings if f.refuse]
    assert any("jaws are open (0.60 rad" in text for text in refusals), refusals
    assert any("outside the workspace box" in text and "box -200..-50 mm" in text for text in refusals), refusals
    assert any(not f.refuse and "far from any surface" in f.text for f in findings), findings


def test_jaws_above_the_flap_are_warned_about(lift: TaskArm) -> None:
    """At the task's home, 2 cm above the flap, the site is inside the box but far from the tissue: a warning."""
    lift.reset(lift.home_q, 0.0)
    findings = check_registration(lift.task_state()["grasp_point"], lift.base_frame, 0.0)
    assert [f.refuse for f in findings] == [False], findings
    assert "above the tissue's surface" in findings[0].text
