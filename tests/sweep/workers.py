"""Toy sweep workers: deterministic functions of a trial, and one that kills its own process once."""

from __future__ import annotations

import os
import signal
from pathlib import Path
from typing import Any

import numpy as np


def toy_episode(
    trial: dict[str, Any], kill_marker_dir: str | None = None, kill_indices: tuple[int, ...] = ()
) -> dict[str, Any]:
    """A fake episode: success and force depend only on the trial's seed and parameters.

    With ``kill_marker_dir``, the first attempt at each index in ``kill_indices`` SIGKILLs its own
    worker process, as an out-of-memory killer or a segfaulting physics engine would.
    """
    index = int(trial["index"])
    if kill_marker_dir is not None and index in kill_indices:
        marker = Path(kill_marker_dir) / f"killed-{index}"
        if not marker.exists():
            marker.write_text(str(os.getpid()))
            os.kill(os.getpid(), signal.SIGKILL)
    rng = np.random.default_rng(int(trial["seed"]))
    stiffness = float(trial["params"].get("stiffness", 1.0))
    force = float(stiffness * rng.uniform(0.5, 1.5))
    success = bool(rng.uniform() < 1.0 / stiffness)
    return {
        "success": success,
        "peak_force_n": force,
        "failure_class": "none" if success else "timeout",
        "interventions": {"force": int(force > 1.0)},
        "pid": os.getpid(),
    }


def failing_episode(trial: dict[str, Any]) -> dict[str, Any]:
    """A worker whose trials raise: the sweep must record the error, not stop."""
    raise RuntimeError(f"broken trial {trial['index']}")
