"""Fixtures of the simulation tests."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

import sim
from sim.envs import TASKS


def make_env(task: str = "multisite", **kwargs: Any) -> Any:
    """A registered environment (through the control chain, as every environment)."""
    return sim.envs.make(task, **kwargs)


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
