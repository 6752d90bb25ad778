"""The tissue stiffness RLS: convergence from noisy pairs, clamping and the no-force case."""

from __future__ import annotations

import numpy as np
import pytest

from safety.stiffness import StiffnessEstimator


def _pull(estimator: StiffnessEstimator, stiffness: float, steps: int, noise_n: float, seed: int = 0) -> float:
    rng = np.random.default_rng(seed)
    anchor = np.zeros(3)
    direction = np.array([0.0, 0.6, 0.8])
    value = estimator.value
    for k in range(steps):
        displacement = 0.004 + 0.003 * np.sin(0.05 * k)  # back and forth along the pull
        tip = anchor + displacement * direction
        force = stiffness * displacement * direction + rng.normal(0.0, noise_n, 3)
        value = estimator.update(tip, force)
    return value


def test_rls_converges_to_the_true_stiffness_from_noisy_pairs() -> None:
    """From a 400 N/m prior, noisy (displacement, force) pairs of an 800 N/m tissue give 800 N/m within 5 %."""
    estimator = StiffnessEstimator(400.0)
    assert _pull(estimator, 800.0, 2000, noise_n=0.01) == pytest.approx(800.0, rel=0.05)
    assert estimator.updates > 50


def test_estimate_stays_within_its_bounds() -> None:
    """However stiff or soft the tissue, every estimate returned stays within [min, max]."""
    for tissue in (5000.0, 20.0):
        estimator = StiffnessEstimator(400.0, min_n_per_m=50.0, max_n_per_m=1000.0)
        values: list[float] = []
        rng = np.random.default_rng(0)
        for k in range(2000):
            displacement = 0.004 + 0.003 * np.sin(0.05 * k)
            tip = displacement * np.array([0.0, 0.6, 0.8])
            force = tissue * tip + rng.normal(0.0, 0.001, 3)
            values.append(estimator.update(tip, force))
        assert min(values) >= 50.0 and max(values) <= 1000.0
        assert values[-1] == pytest.approx(1000.0) if tissue > 1000.0 else values[-1] < 100.0


def test_no_force_or_non_finite_input_learns_nothing() -> None:
    """Below the smallest trusted force, or with NaN input, the estimate stays at the prior."""
    estimator = StiffnessEstimator(400.0)
    for k in range(100):
        estimator.update(np.array([0.0, 0.0, 0.001 * k]), np.zeros(3))
        estimator.update(np.array([0.0, 0.0, 0.001 * k]), np.array([np.nan, 1.0, 0.0]))
    assert estimator.value == 400.0 and estimator.updates == 0
