"""Fixtures of the simulation tests."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

import sim
from sim.envs import TASKS


def make_env(task: str = "multisite", **kwargs: Any) -> Any:
    """A registered environment (through the control chain, as every environment)."""
    return sim.envs.make(task, **kwargs)


def _reversal_blocked() -> bool:
    """True while the chain's acceleration limit keeps a joint with a float-residue velocity from reversing.

    A joint whose commanded velocity is, say, -1e-12 (left over by Ruckig at the end of a stop) has a
    stopping distance of ~1e-25, yet the limit bounds its step to ``dq <= -1e-25``: it can never move the
    other way, and the expert's tool stalls for many steps (measured: 60 % instead of 100 % success).
    """
    from safety.limits import FilterState, JointAccelerationLimit

    one = np.ones(1)
    limit = JointAccelerationLimit(one, 0.01 * one, -one, one)
    state = FilterState(0 * one, -1e-12 * one, np.zeros(3), np.zeros((3, 1)), np.zeros(3), 100.0, 0.01)
    _, upper = limit.compute_joint_bounds(state)
    return bool(upper[0] <= 0.0)


#: Tests that need the expert to succeed: expected to fail while the stall above is in the chain.
needs_chain_reversal = pytest.mark.xfail(
    _reversal_blocked(),
    reason="safety.limits.JointAccelerationLimit blocks reversal at a float-residue velocity (fix due in safety/)",
    strict=False,
)


@pytest.fixture(params=list(TASKS))
def task(request: pytest.FixtureRequest) -> str:
    """Every task id."""
    return str(request.param)


@pytest.fixture
def env() -> Iterator[Any]:
    """A Task III environment, closed after the test."""
    environment = make_env("multisite")
    yield environment
    environment.close()
