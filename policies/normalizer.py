"""Running mean/std normaliser for observations and goals.

As in the HER reference code the paper's algorithms build on: raw values are clipped to
``[-obs_clip, obs_clip]``, standardised with a standard deviation of at least ``eps``, and the result is
clipped to ``[-clip, clip]``. Statistics are float64 sums so that they can be merged and checkpointed.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Normalizer"]


class Normalizer:
    """Standardises vectors of a fixed size with statistics of everything it has been shown.

    Args:
        size: Length of the vectors.
        eps: Smallest standard deviation divided by.
        clip: Bound of the normalised output.
        obs_clip: Bound of the raw input.
    """

    def __init__(self, size: int, eps: float = 0.01, clip: float = 5.0, obs_clip: float = 200.0) -> None:
        self.size = size
        self.eps = eps
        self.clip = clip
        self.obs_clip = obs_clip
        self.sum = np.zeros(size)
        self.sumsq = np.zeros(size)
        self.count = 0.0
        self.mean = np.zeros(size, dtype=np.float32)
        self.std = np.ones(size, dtype=np.float32)

    def update(self, values: np.ndarray) -> None:
        """Add rows of ``values`` (any leading shape, last axis ``size``) to the statistics."""
        flat = np.clip(np.asarray(values, dtype=np.float64).reshape(-1, self.size), -self.obs_clip, self.obs_clip)
        self.sum += flat.sum(axis=0)
        self.sumsq += np.square(flat).sum(axis=0)
        self.count += flat.shape[0]
        self._recompute()

    def _recompute(self) -> None:
        if self.count <= 0:
            return
        mean = self.sum / self.count
        var = np.maximum(self.eps**2, self.sumsq / self.count - np.square(mean))
        self.mean = mean.astype(np.float32)
        self.std = np.sqrt(var).astype(np.float32)

    def __call__(self, values: np.ndarray) -> np.ndarray:
        """The normalised values, float32, same shape."""
        x = np.clip(np.asarray(values, dtype=np.float32), -self.obs_clip, self.obs_clip)
        return np.clip((x - self.mean) / self.std, -self.clip, self.clip)

    def state(self) -> dict[str, np.ndarray]:
        """The statistics as arrays (for checkpoints)."""
        return {"sum": self.sum.copy(), "sumsq": self.sumsq.copy(), "count": np.array([self.count])}

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore statistics saved by :meth:`state`."""
        self.sum = np.asarray(state["sum"], dtype=np.float64).reshape(self.size).copy()
        self.sumsq = np.asarray(state["sumsq"], dtype=np.float64).reshape(self.size).copy()
        self.count = float(np.asarray(state["count"]).reshape(-1)[0])
        self._recompute()
