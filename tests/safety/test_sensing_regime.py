"""A calibrated force is trusted to its bound only within the accelerations and tip speeds the calibration saw.

The force bound takes the tick's commanded acceleration: within the regime the filter's margin is the
calibration's bound, beyond it the wider one, counted; the force-limit watch reports an excursion only beyond
the bound in force on that tick.
"""

from __future__ import annotations

import math

import numpy as np

from psm_control.commands import CartesianDelta, MeasuredState
from safety.chain import ControlChain
from safety.config import SafetyConfig
from safety.force_bound import INSIDE, OUTSIDE, UNTRUSTED, ForceBound, SensingRegime
from safety.force_watch import ForceLimitWatch
from safety.limits.retraction_force import may_hold_tissue

COVERED = np.array([2.0, 2.0, 0.5, 3.0, 3.0, 3.0])


def _bound() -> ForceBound:
    return ForceBound(3.0, 1.0, 100.0, 0.3, 0.01, SensingRegime(COVERED, 8.0))


def test_the_margin_is_the_regimes_bound_within_it_and_the_wider_one_beyond() -> None:
    bound = _bound()
    force = np.array([0.5, 0.0, 0.0])
    inside = bound.update(0.8, np.zeros(3), force, 50.0, 0.5 * COVERED)
    assert inside.margin_n == 1.0 and bound.tick_error_n == 1.0 and bound.ticks_outside_regime == 0
    beyond = bound.update(0.8, np.zeros(3), force, 50.0, np.where(np.arange(6) == 2, 0.6, 0.0))
    assert beyond.margin_n == 8.0 and bound.tick_error_n == 8.0 and bound.ticks_outside_regime == 1
    unknown = bound.update(0.8, np.zeros(3), force, 50.0, None)  # no acceleration given: the regime's bound
    assert unknown.margin_n == 1.0
    assert bound.at_limit(2.0).regime is bound.regime


def test_beyond_the_regime_a_held_tissue_is_bounded_by_its_travel() -> None:
    """With the jaws closed on tissue and the wider bound above the limit, the travel bound decides the tick."""
    bound = _bound()
    grasp = np.zeros(3)
    bound.update(0.0, grasp, np.zeros(3), 50.0, 0.5 * COVERED)  # the jaws close: the grasp
    inside = bound.update(0.0, grasp + np.array([0.0, 0.0, 0.02]), np.array([0.2, 0.0, 0.0]), 50.0, 0.5 * COVERED)
    beyond = bound.update(0.0, grasp + np.array([0.0, 0.0, 0.02]), np.array([0.2, 0.0, 0.0]), 50.0, 2.0 * COVERED)
    assert inside.source == "measured" and beyond.source == "travel"


def test_the_watch_counts_an_excursion_only_beyond_the_ticks_bound() -> None:
    watch = ForceLimitWatch(3.0, 0.01, 1.0)
    assert watch.update(np.array([5.0, 0.0, 0.0]), 0.0, 8.0) is None and not watch.above  # within 3 + 8 N
    assert watch.update(np.array([5.0, 0.0, 0.0]), 0.01, 1.0) is None and watch.above  # beyond 3 + 1 N
    watch.update(np.array([12.0, 0.0, 0.0]), 0.02, 8.0)  # beyond 3 + 8 N too
    excursion = watch.finish()
    assert excursion is not None and excursion.error_n == 8.0 and excursion.peak_n == 12.0
    assert excursion.ratio == (12.0 - 8.0) / 3.0
    # A tick whose force is not trusted is not judged, whatever it reads, and ends an excursion in progress.
    assert watch.update(np.array([5.0, 0.0, 0.0]), 0.03, 1.0) is None and watch.above
    assert watch.update(np.full(3, np.nan), 0.04, np.inf) is not None and not watch.above
    assert watch.update(np.array([50.0, 0.0, 0.0]), 0.05, np.inf) is None and not watch.above


def test_above_the_retraction_speeds_the_wider_bound_and_beyond_the_covered_speed_none() -> None:
    """The tight bound was judged at retraction speeds only: faster ticks take the wider one, and ticks faster than
    any the calibration's logs reached trust the force not at all (an infinite margin, counted apart); a held
    tissue is then bounded by its travel, and an open jaw takes no contact from the force."""
    bound = ForceBound(3.0, 1.0, 100.0, 0.3, 0.01, SensingRegime(COVERED, 8.0, 0.1, 0.25))
    force = np.array([0.0, 0.0, 2.5])  # would tell a contact with the 1 N bound
    slow = bound.update(0.8, np.zeros(3), force, 50.0, 0.5 * COVERED, 0.05)
    assert slow.margin_n == 1.0 and may_hold_tissue(0.8, slow.force_n, slow.margin_n)
    fast = bound.update(0.8, np.zeros(3), force, 50.0, 0.5 * COVERED, 0.2)
    assert fast.margin_n == 8.0 and bound.ticks_outside_regime == 1 and bound.ticks_untrusted == 0
    untrusted = bound.update(0.8, np.zeros(3), force, 50.0, 0.5 * COVERED, 0.3)
    assert untrusted.margin_n == math.inf and bound.tick_error_n == math.inf and bound.ticks_untrusted == 1
    assert not may_hold_tissue(0.8, untrusted.force_n, untrusted.margin_n)
    assert bound.regime is not None and bound.regime.where(None, math.nan) == UNTRUSTED
    assert bound.regime.where(None, None) == INSIDE and bound.regime.where(2.0 * COVERED, 0.05) == OUTSIDE
    grasp = np.zeros(3)
    bound.update(0.0, grasp, np.zeros(3), 50.0, 0.5 * COVERED, 0.05)  # the jaws close: the grasp
    held = bound.update(0.0, grasp + np.array([0.0, 0.0, 0.001]), np.zeros(3), 50.0, 0.5 * COVERED, 0.3)
    assert held.source == "travel" and held.margin_n == 0.3  # a zero reading is not trusted either


def test_the_chain_gives_the_bound_its_commanded_tip_speed() -> None:
    """On a dVRK deploy's chain the regime sees the tip speed the chain commands: a move faster than the regime's
    covered speed is counted untrusted, a slower one not."""
    counts = []
    for covered_speed in (1.0, 0.005):
        chain = ControlChain(SafetyConfig(force_sensing_error_n=1.0))
        chain.force_bound.regime = SensingRegime(np.full(6, np.inf), 8.0, 0.1, covered_speed)
        q = chain.model.home()
        measured = MeasuredState(q, np.zeros(6), 0.6, np.zeros(3), 0.0)
        chain.reset(measured)
        chain.set_target(CartesianDelta(np.array([0.0, 0.004, 0.0]), 0.0, 0.6, "base"), measured)
        for k in range(1, 60):
            command = chain.tick(measured).command
            measured = MeasuredState(command.q, command.qd, 0.6, np.zeros(3), k * 0.01)
        counts.append(chain.force_bound.ticks_untrusted)
    assert counts[0] == 0 < counts[1], counts
