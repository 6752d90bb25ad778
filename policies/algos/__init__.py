"""The five algorithms, one file each, over the shared core in :mod:`policies.algos.base`."""

from __future__ import annotations

from policies.algos.base import Agent, Dims, TensorBatch
from policies.algos.col import CoL
from policies.algos.ddpg import DDPG
from policies.algos.ddpgbc import DDPGBC
from policies.algos.dex import DEX
from policies.algos.sqil import SQIL
from policies.config import TrainConfig

__all__ = ["AGENTS", "DDPG", "DDPGBC", "DEX", "SQIL", "Agent", "CoL", "Dims", "TensorBatch", "make_agent"]

#: Algorithm name -> agent class.
AGENTS: dict[str, type[Agent]] = {cls.name: cls for cls in (DDPG, SQIL, DDPGBC, CoL, DEX)}


def make_agent(dims: Dims, config: TrainConfig, seed: int = 0) -> Agent:
    """The agent of ``config.algo``."""
    return AGENTS[config.algo](dims, config, seed)
