"""A reset chain behaves the same whatever it did before: episodes do not leak into each other."""

from __future__ import annotations

import numpy as np

from psm_control.commands import CartesianDelta, MeasuredState
from psm_control.robot import PsmModel
from safety.chain import ControlChain


def _episode(chain: ControlChain, seed: int, ticks: int = 300) -> np.ndarray:
    """Drive the chain with seeded random targets against a kinematic arm; return the commands."""
    rng = np.random.default_rng(seed)
    q = PsmModel().home()
    stamp = 0.0
    chain.reset(MeasuredState(q, np.zeros(6), 0.0, np.zeros(3), stamp))
    commands = []
    for tick in range(ticks):
        # Forces around the 3 N limit and large steps keep the IK and filter QPs engaged.
        measured = MeasuredState(q, np.zeros(6), 0.0, np.array([0.0, 0.0, rng.uniform(2.0, 3.5)]), stamp)
        if tick % 5 == 0:
            chain.set_target(CartesianDelta(rng.uniform(-0.04, 0.04, 3)), measured)
        q = np.array(chain.tick(measured).command.q)
        commands.append(q)
        stamp += chain.control_period_s
    return np.array(commands)


def test_reset_makes_episodes_independent_of_history() -> None:
    """Episode B gives bit-identical commands on a fresh chain and on one that first ran episode A."""
    fresh = _episode(ControlChain(), seed=2)
    used = ControlChain()
    _episode(used, seed=1)
    np.testing.assert_array_equal(_episode(used, seed=2), fresh)
