"""Shared fixtures."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from psm_control.robot import PsmModel
from psm_control.spec import ARMS


@pytest.fixture(params=ARMS)
def model(request: pytest.FixtureRequest) -> PsmModel:
    """The PSM model of each known arm variant."""
    return PsmModel.from_variant(request.param)


@pytest.fixture
def classic() -> PsmModel:
    """The default PSM: Classic arm, 400006 large needle driver."""
    return PsmModel.from_variant("classic")


def random_joints(model: PsmModel, rng: np.random.Generator, count: int) -> np.ndarray:
    """Uniform random joint vectors within the limits, shape (count, 6)."""
    return rng.uniform(model.lower, model.upper, size=(count, model.dof))


def run_cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    """Run ``tissue-retract ARGS`` as a user would, in a fresh interpreter, capturing its output."""
    return subprocess.run(
        [sys.executable, "-m", "tissue_retract", *args], capture_output=True, text=True, timeout=timeout, check=False
    )
