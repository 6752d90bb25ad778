"""A sweep's identity, recorded in its output folder so that a rerun never mixes two sweeps' episodes.

``sweep.json`` holds what decides a sweep's episodes: the policy (and the SHA-256 of its checkpoint),
the task, the varied ranges or grid, the seed, the number of episodes, the safety configuration and the
package version. Resuming into a folder whose identity differs is refused, naming every difference;
``fresh`` deletes the old episodes and starts over (as ``train --fresh`` does).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from psm_control.errors import TissueRetractError
from psm_control.outputs import write_atomic
from sim.strict_json import strict_dumps

__all__ = ["IDENTITY_FILE", "SweepIdentityError", "file_digest", "prepare_output"]

IDENTITY_FILE = "sweep.json"
_EPISODES_FILE = "episodes.jsonl"


class SweepIdentityError(TissueRetractError):
    """An output folder holds episodes of another sweep.

    Attributes:
        out: The folder.
        differences: ``(key, recorded, now)`` per setting that differs.
    """

    def __init__(self, out: Path, differences: list[tuple[str, object, object]]) -> None:
        self.out = out
        self.differences = differences
        listed = "; ".join(f"{key}: {old!r} there, {new!r} now" for key, old, new in differences)
        super().__init__(
            f"--out {out} holds episodes of another sweep ({listed}); pass --fresh to start over or choose "
            "another --out"
        )


def file_digest(path: str | Path) -> str | None:
    """SHA-256 of a file's bytes, or None when ``path`` is not a regular file (``scripted``, ``mod:fn``)."""
    path = Path(path)
    if not path.is_file():
        return None
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def prepare_output(out: Path, identity: Mapping[str, Any], *, fresh: bool = False) -> None:
    """Make ``out``, refuse it if it holds another sweep's episodes, and record ``identity`` there.

    Raises:
        SweepIdentityError: ``out`` holds episodes of a sweep with another identity (or of an unrecorded one).
        ConfigurationError: ``out`` cannot be created.
    """
    out.mkdir(parents=True, exist_ok=True)
    record = out / IDENTITY_FILE
    episodes = out / _EPISODES_FILE
    wanted = json.loads(strict_dumps(dict(identity), sort_keys=True, default=str))
    if fresh:
        for path in (episodes, record):
            path.unlink(missing_ok=True)
    elif record.is_file():
        try:
            saved = json.loads(record.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError):
            saved = None
        if not isinstance(saved, dict):
            raise SweepIdentityError(out, [(IDENTITY_FILE, "unreadable", "a sweep record")])
        differences = [
            (key, saved.get(key), wanted.get(key))
            for key in sorted(set(saved) | set(wanted))
            if saved.get(key) != wanted.get(key)
        ]
        if differences:
            raise SweepIdentityError(out, differences)
        return
    elif episodes.is_file() and episodes.stat().st_size > 0:
        raise SweepIdentityError(out, [(IDENTITY_FILE, None, "a recorded sweep")])
    write_atomic(record, strict_dumps(wanted, indent=2, sort_keys=True) + "\n", "--out")
