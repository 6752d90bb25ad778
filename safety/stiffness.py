"""Online estimate of the tissue's stiffness along the retraction direction (recursive least squares).

The force limit predicts the force a step adds as ``K * displacement``. ``K`` starts from a deliberately
stiff prior (a stiffer tissue means smaller allowed steps: the safe side) and is refined from pairs of
tool displacement and force change along the current force direction, with exponential forgetting so
it follows tissue that softens or stiffens. The value used is kept within ``[k_min, k_max]``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["StiffnessEstimator"]


class StiffnessEstimator:
    """Scalar RLS for ``dF = K dx`` along the force direction.

    Args:
        prior_n_per_m: Initial estimate [N/m].
        min_n_per_m: Lowest value ever returned [N/m].
        max_n_per_m: Highest value ever returned [N/m].
        forgetting: Forgetting factor in (0, 1]; 0.98 remembers about the last 50 updates.
        prior_variance: Initial variance of the estimate [(N/m)^2]; small keeps the prior for longer.
        min_displacement_m: Displacement along the force direction that triggers an update [m];
            shorter increments are accumulated, so sensor noise is not divided by a tiny motion.
        min_force_n: Below this force no direction is defined and nothing is learned [N].
    """

    def __init__(
        self,
        prior_n_per_m: float = 400.0,
        *,
        min_n_per_m: float = 50.0,
        max_n_per_m: float = 5000.0,
        forgetting: float = 0.98,
        prior_variance: float = 1e4,
        min_displacement_m: float = 2e-4,
        min_force_n: float = 0.05,
    ) -> None:
        self.prior = float(prior_n_per_m)
        self.min = float(min_n_per_m)
        self.max = float(max_n_per_m)
        self.forgetting = float(forgetting)
        self.prior_variance = float(prior_variance)
        self.min_displacement_m = float(min_displacement_m)
        self.min_force_n = float(min_force_n)
        self.updates = 0
        self.reset()

    def reset(self) -> None:
        """Return to the prior."""
        self._k = self.prior
        self._p = self.prior_variance
        self._x_ref: list[float] | None = None
        self._f_ref: list[float] | None = None

    @property
    def value(self) -> float:
        """The stiffness to use [N/m], within ``[min, max]``."""
        return float(min(max(self._k, self.min), self.max))

    def update(self, tool_position_m: np.ndarray, retraction_force_n: np.ndarray) -> float:
        """Feed one (position, force) sample and return the current estimate [N/m]."""
        x = np.asarray(tool_position_m, dtype=float).tolist()
        f = np.asarray(retraction_force_n, dtype=float).tolist()
        magnitude = math.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2])
        # NaN fails every comparison, so a non-finite sample only moves the reference.
        finite = math.isfinite(magnitude) and math.isfinite(x[0] + x[1] + x[2])
        if not (finite and magnitude >= self.min_force_n) or self._x_ref is None or self._f_ref is None:
            self._x_ref, self._f_ref = x, f
            return self.value
        n = [c / magnitude for c in f]
        dx = sum(n[i] * (x[i] - self._x_ref[i]) for i in range(3))
        if abs(dx) < self.min_displacement_m:
            return self.value
        df = sum(n[i] * (f[i] - self._f_ref[i]) for i in range(3))
        gain = self._p * dx / (self.forgetting + dx * self._p * dx)
        self._k += gain * (df - dx * self._k)
        self._p = (self._p - gain * dx * self._p) / self.forgetting
        self._x_ref, self._f_ref = x, f
        self.updates += 1
        return self.value
