"""The force-limit monitor alone, and the chain's warning when the limit is below the static load."""

from __future__ import annotations

import numpy as np
import pytest

from psm_control.commands import MeasuredState
from safety.chain import ControlChain
from safety.config import SafetyConfig
from safety.force_monitor import ForceLimitMonitor


def test_each_stretch_above_the_limit_is_one_event_with_its_excess_and_duration() -> None:
    """Readings above the limit make one event per stretch, with the peak excess and the time above."""
    monitor = ForceLimitMonitor(0.4, 0.01)
    for k, force in enumerate([0.1, 0.5, 0.7, 0.3, 0.2, 0.45, float("nan"), 0.1]):
        monitor.update(0.01 * k, force)
    monitor.finish()
    events = monitor.take()
    assert len(events) == 2
    assert events[0].start_s == pytest.approx(0.01) and events[0].duration_s == pytest.approx(0.02)
    assert events[0].excess_n == pytest.approx(0.3)
    assert events[1].duration_s == pytest.approx(0.01) and events[1].to_dict()["excess_n"] == pytest.approx(0.05)
    assert monitor.take() == []


def test_a_limit_below_the_static_load_is_warned_about_with_the_load() -> None:
    """A chain reset while the tissue already pulls harder than the limit names the measured load."""
    chain = ControlChain(SafetyConfig(force_limit_n=0.05))
    q = chain.model.home()
    chain.reset(MeasuredState(q, np.zeros(6), 0.0, np.array([0.0, 0.0, -0.08]), 0.0))
    assert len(chain.force_warnings) == 1
    assert "0.080 N" in chain.force_warnings[0] and "0.05 N" in chain.force_warnings[0]
    chain.reset(MeasuredState(q, np.zeros(6), 0.0, np.zeros(3), 0.0))
    assert len(chain.force_warnings) == 1  # nothing new below the limit
