"""Seeded parameter sweeps of independent episodes, run on a local process pool or a Ray cluster.

The engine knows nothing about tissue: a sweep is a list of :class:`Trial` (index, seed, parameters)
handed to a worker function named ``"module:function"``; each result is appended to a JSON-lines file
as soon as it arrives, so an interrupted sweep resumes where it stopped and a crashed worker's trials
are retried rather than lost. Robustness evaluation and safety tuning are built on it.
"""

from sim.sweep.executor import BACKENDS, cap_jobs, run_trials
from sim.sweep.identity import SweepIdentityError, file_digest, prepare_output
from sim.sweep.space import ParameterRange, Trial, make_trials, parse_ranges
from sim.sweep.stats import binned_success, wilson_interval
from sim.sweep.store import EpisodeStore

__all__ = [
    "BACKENDS",
    "EpisodeStore",
    "ParameterRange",
    "SweepIdentityError",
    "Trial",
    "binned_success",
    "cap_jobs",
    "file_digest",
    "make_trials",
    "parse_ranges",
    "prepare_output",
    "run_trials",
    "wilson_interval",
]
