"""The episode's start includes the jaw: a rehearsal starts each episode as the simulation does."""

from __future__ import annotations

import math

import numpy as np

from hardware_if.client.arm_pose import JAW_START_TOLERANCE_RAD, start_offset

START = np.array([0.0, 0.0, 0.12, 0.0, 0.0, 0.0])


def test_an_arm_at_its_start_with_the_jaw_open_is_at_the_start() -> None:
    assert start_offset(START, START, measured_jaw=0.6 - 0.5 * JAW_START_TOLERANCE_RAD, start_jaw=0.6) == ""


def test_jaws_closed_at_the_start_are_not_at_the_start() -> None:
    # The last episode ends with the jaws closed on the flap: the next one must not start so.
    offset = start_offset(START, START, measured_jaw=0.0, start_jaw=0.6)
    assert offset.startswith("jaw at 0 rad, 0.6 rad from the episode's start 0.6 rad")


def test_a_non_finite_jaw_is_not_at_the_start() -> None:
    assert start_offset(START, START, measured_jaw=math.nan, start_jaw=0.6)


def test_joints_and_jaw_off_name_the_worst_joint_and_the_jaw() -> None:
    q = START.copy()
    q[0] += 0.1
    offset = start_offset(q, START, measured_jaw=0.0, start_jaw=0.6)
    assert offset.startswith("yaw is 0.1 rad from the episode's start")
    assert offset.endswith("1 joint(s) off, and the jaw)")


def test_without_a_start_jaw_only_the_joints_count() -> None:
    assert start_offset(START, START, measured_jaw=0.0) == ""
