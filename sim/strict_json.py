"""Strict JSON out: every file and line we write parses with any JSON parser.

Python's ``json`` writes ``NaN`` and ``Infinity`` for non-finite floats, which strict parsers (browsers'
``JSON.parse``, jq, most other languages) reject. Here a non-finite float becomes ``null`` (the quantity
is unknown or did not occur) and numpy scalars and arrays become plain numbers and lists.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from psm_control.outputs import write_atomic

__all__ = ["strict_dumps", "to_strict", "write_strict_json"]


def to_strict(value: Any) -> Any:
    """``value`` with non-finite floats as None and containers and numpy values converted recursively."""
    if isinstance(value, bool) or value is None or isinstance(value, str | int):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): to_strict(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [to_strict(v) for v in value]
    if hasattr(value, "tolist") and callable(value.tolist):  # numpy arrays and scalars
        return to_strict(value.tolist())
    return value


def strict_dumps(value: Any, **kwargs: Any) -> str:
    """``json.dumps`` of :func:`to_strict` ``(value)``; refuses anything still non-finite."""
    return json.dumps(to_strict(value), allow_nan=False, **kwargs)


def write_strict_json(
    path: Path, value: Any, indent: int | None = 2, sort_keys: bool = False, field: str = "output"
) -> None:
    """Write ``value`` as strict JSON atomically: a crash leaves the old file or none, never half a file.

    Written by :func:`psm_control.outputs.write_atomic`: a device or FIFO at ``path`` is never replaced, and
    a full disk is an :class:`~psm_control.errors.OutputWriteError` naming ``field`` and the path.
    """
    write_atomic(path, strict_dumps(value, indent=indent, sort_keys=sort_keys) + "\n", field)
