"""The sweep's results file: one JSON line per finished trial, written as each trial finishes."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from sim.strict_json import strict_dumps

__all__ = ["EpisodeStore"]


class EpisodeStore:
    """Append-only JSON-lines store of trial results, keyed by trial index.

    Each record is flushed and fsync'ed as soon as it is appended, so an interrupted sweep keeps
    every trial that finished. A partial last line (the process was killed mid-write) is ignored on
    reading and overwritten by the resumed sweep.

    Args:
        path: The ``episodes.jsonl`` file; created if missing.
    """

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.records: dict[int, dict[str, Any]] = {}
        self._load()

    def _load(self) -> None:
        if not self.path.exists():
            return
        valid_bytes = 0
        with self.path.open("rb") as handle:
            for line in handle:
                try:
                    record = json.loads(line)
                except json.JSONDecodeError:
                    break  # a torn final write: everything before it is intact
                if not line.endswith(b"\n"):
                    break
                self.records[int(record["index"])] = record
                valid_bytes += len(line)
        if valid_bytes != self.path.stat().st_size:
            with self.path.open("r+b") as handle:
                handle.truncate(valid_bytes)

    def done(self) -> set[int]:
        """Indices of the trials already recorded."""
        return set(self.records)

    def append(self, record: dict[str, Any]) -> None:
        """Record one finished trial durably."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        line = strict_dumps(record, sort_keys=True) + "\n"
        with self.path.open("a") as handle:
            handle.write(line)
            handle.flush()
            os.fsync(handle.fileno())
        self.records[int(record["index"])] = record

    def ordered(self) -> list[dict[str, Any]]:
        """All records by trial index."""
        return [self.records[i] for i in sorted(self.records)]
