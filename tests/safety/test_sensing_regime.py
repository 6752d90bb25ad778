"""A calibrated force is trusted to its bound only within the accelerations the calibration saw.

The force bound takes the tick's commanded acceleration: within the regime the filter's margin is the
calibration's bound, beyond it the wider one, counted; the force-limit watch reports an excursion only beyond
the bound in force on that tick.
"""

from __future__ import annotations

import numpy as np

from safety.force_bound import ForceBound, SensingRegime
from safety.force_watch import ForceLimitWatch

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
