"""A training run's wall-clock budget (``train --budget-s``): what still fits, and when to stop.

The budget covers the whole command, the interpreter's start included. Every phase asks it before a unit
of work: a chunk of demonstrations, a chunk of pretraining (these two within the preparation's share of the
budget, the demonstrations stopping early enough for all of the pretraining, timed on the first of them),
a training episode, an evaluation episode. On a loaded machine the estimates are the last measured ones,
and an evaluation that would run past the end is cut short (its success rate is then over the episodes it
ran), so a run ends within about one such unit of its budget.
"""

from __future__ import annotations

import time
from collections.abc import Callable

__all__ = ["FINISH_RESERVE_S", "PREPARATION_SHARE", "Budget"]

#: Kept free at the end of a budget [s]: closing the environments and the interpreter's exit with torch,
#: Numba and PyBullet loaded took 0.8-1.2 s on the 2-core machine of the README's figures.
FINISH_RESERVE_S = 1.5


#: Share of a budget that demonstrations and pretraining may take unless told otherwise; the rest is for
#: training and evaluation.
PREPARATION_SHARE = 0.5


class Budget:
    """The run's wall-clock budget: whether one more unit of work still fits.

    Every estimate is the last measured one: a training episode's wall time (collection and updates), an
    evaluation's with its checkpoint; before the first evaluation, its episodes at the collection's wall
    time per step, doubled (the actor's forward passes and the checkpoint come on top). The process's exit
    (:data:`FINISH_RESERVE_S`) is kept free too.

    Args:
        budget_s: The budget [s]; None: no budget (everything fits).
        started_s: When it started, on ``clock``.
        clock: Monotonic clock [s].
        preparation_share: Share of the budget demonstrations and pretraining may take.
    """

    def __init__(
        self,
        budget_s: float | None,
        started_s: float,
        clock: Callable[[], float] = time.monotonic,
        preparation_share: float = PREPARATION_SHARE,
    ) -> None:
        self.budget_s = budget_s
        self.started_s = started_s
        self.preparation_share = preparation_share
        self._clock = clock
        self.episode_s = 0.0
        self.step_s = 0.0
        self.evaluation_s: float | None = None
        #: What the pretraining after the demonstrations will take [s], once timed: kept free by them.
        self.pretraining_s = 0.0

    def elapsed(self) -> float:
        """Seconds since the budget started."""
        return self._clock() - self.started_s

    def evaluation_estimate_s(self, eval_episodes: int, horizon: int) -> float:
        """How long the next evaluation will take [s]: the last one's time, else estimated from the step time."""
        return self.evaluation_s if self.evaluation_s is not None else 2.0 * eval_episodes * horizon * self.step_s

    def out_of_time(self, keep_s: float = 0.0) -> bool:
        """True when less than ``keep_s`` (and the exit's reserve) is left (never without a budget)."""
        if self.budget_s is None:
            return False
        return self.elapsed() + keep_s + FINISH_RESERVE_S > self.budget_s

    def preparing_fits(self, keep_s: float = 0.0) -> bool:
        """More demonstrations or pretraining fit: less than the preparation's share of the budget, less
        ``keep_s``, is spent."""
        return self.budget_s is None or self.elapsed() + keep_s < self.preparation_share * self.budget_s

    def demonstrations_fit(self) -> bool:
        """More demonstrations fit: they and the pretraining after them (:attr:`pretraining_s`) end within the
        preparation's share of the budget."""
        return self.preparing_fits(self.pretraining_s)

    def fits_episode(self, eval_episodes: int, horizon: int) -> bool:
        """One more episode and the last evaluation end within the budget (always, without a budget)."""
        return not self.out_of_time(self.episode_s + self.evaluation_estimate_s(eval_episodes, horizon))
