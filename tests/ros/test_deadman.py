"""The client-side deadman's rules, one at a time (no ROS needed for the decision itself)."""

from __future__ import annotations

import numpy as np
import pytest

from hardware_if.client import deadman as rules
from hardware_if.client.deadman import ArmFacts, Deadman
from psm_control.errors import ConfigurationError

Q = np.array([0.1, -0.1, 0.12, 0.0, 0.2, -0.2])


def _facts(**changes: object) -> ArmFacts:
    facts = ArmFacts(
        now_s=10.0, measured_rx_s=9.99, publishers=1, state="ENABLED", is_homed=True, measured_q=Q, setpoint_q=Q
    )
    return facts._replace(**changes)


def test_fresh_enabled_homed_tracking_arm_is_ok() -> None:
    """A fresh, present, ENABLED, homed arm that tracks its set-point may be commanded."""
    status = Deadman().update(_facts())
    assert status.ok and not status.holding and status.reason == ""


@pytest.mark.parametrize(
    ("changes", "prefix"),
    [
        ({"measured_rx_s": 9.5}, "stale"),
        ({"publishers": 0}, "publisher gone"),
        ({"publishers": 2}, "publisher conflict"),
        ({"conflict": "another commander: /teleop publishes /PSM1/servo_jp"}, "another commander: /teleop"),
        ({"data_fault": "invalid data: measured_js: non-finite yaw"}, "invalid data: measured_js"),
        ({"measured_rx_s": None, "measured_q": None}, "no measurement"),
        ({"state": "DISABLED"}, "not ready"),
        ({"state": "FAULT"}, "not ready"),
        ({"is_homed": False}, "not ready"),
        ({"setpoint_q": Q + np.array([0, 0, 0.051, 0, 0, 0])}, "tracking error: insertion"),
        ({"setpoint_q": Q + np.array([0.51, 0, 0, 0, 0, 0])}, "tracking error: yaw"),
        ({"setpoint_q": Q + np.array([0, 0, 0, 0, 0, 0.61])}, "tracking error: wrist_yaw"),
    ],
)
def test_each_fault_latches_a_hold_with_its_reason(changes: dict[str, object], prefix: str) -> None:
    """Each fault trips a hold naming it, and the hold stays after the fault clears until released."""
    deadman = Deadman()
    status = deadman.update(_facts(**changes))
    assert status.holding and not status.ok and status.reason.startswith(prefix), status
    assert deadman.update(_facts()).holding
    assert not deadman.release(_facts()).holding


def test_tracking_within_dvrk_tolerances_does_not_trip() -> None:
    """Errors just inside the dVRK's tolerances (0.5 rad, 0.05 m, 0.6 rad) do not trip."""
    setpoint = Q + np.array([0.49, -0.49, 0.049, 0.59, -0.59, 0.59])
    assert Deadman().update(_facts(setpoint_q=setpoint)).ok


def test_release_keeps_holding_while_a_fault_remains() -> None:
    """release() does not clear a hold while a rule still fails."""
    deadman = Deadman()
    deadman.update(_facts(publishers=0))
    assert deadman.release(_facts(state="DISABLED")).holding


def test_bad_settings_are_rejected() -> None:
    """A non-positive timeout or a malformed tolerance is a ConfigurationError naming the field."""
    with pytest.raises(ConfigurationError, match="timeout_s"):
        Deadman(timeout_s=0.0)
    with pytest.raises(ConfigurationError, match="tracking_tolerance"):
        Deadman(tracking_tolerance=np.ones(3))


def test_a_repeated_measurement_goes_stale_by_its_stamp() -> None:
    """A console that repeats its last measurement (same stamp) holds once the timeout passed since the stamp
    last advanced, and the reason says the stamp has not advanced, however recently the repeat arrived."""
    repeated = _facts(now_s=10.0, measured_rx_s=9.84, repeated_rx_s=9.999)
    status = Deadman(timeout_s=0.15).update(repeated)
    assert status.holding and status.reason.startswith("stale: measured_js stamp has not advanced for 0.160 s")
    assert Deadman(timeout_s=0.15).update(repeated._replace(measured_rx_s=9.86)).ok  # within the timeout


@pytest.mark.parametrize(
    ("previous", "stamp", "between_s", "fault"),
    [
        (100.0, 100.01, 0.01, ""),  # one period later, one period between arrivals
        (100.0, 100.2, 0.01, ""),  # a late message followed by a prompt one: within the jump allowance
        (100.0, 100.01, 2.0, ""),  # a console that stalled and came back: its stamps did not run ahead
        (100.0, 100.0, 0.01, ""),  # a repeat: no fault here, and no new measurement (the listener's rule)
        (100.0, 95.01, 0.01, "stamp went back 4.99 s"),
        (100.0, 99.9999, 0.01, "stamp went back 0.0001 s"),
        (100.0, 3700.0, 0.01, "stamp jumped 3600 s further ahead"),
        (100.0, 101.011, 0.01, "stamp jumped"),  # STAMP_JUMP_S, 1 s, beyond the arrivals' 0.01 s
        (100.0, 101.009, 0.01, ""),
    ],
)
def test_stamps_are_judged_against_each_other_and_the_arrivals(
    previous: float, stamp: float, between_s: float, fault: str
) -> None:
    """A stamp may not go back, nor run ahead of the arrivals by more than STAMP_JUMP_S; the console's clock
    itself may be anywhere (these stamps are 100 s after its epoch, and the arrivals on another clock)."""
    found = rules.stamp_step_fault(previous, stamp, stamp - previous - between_s)
    assert rules.STAMP_JUMP_S == 1.0  # the rows above are about this allowance
    assert found.startswith(fault) if fault else found == "", found
