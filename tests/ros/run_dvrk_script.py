"""Run one of the dVRK client's scripts unmodified, recording how every move handle's ``wait()`` ended.

Usage: ``run_dvrk_script.py SCRIPT [ARGS...]``. At exit it prints one line
``WAITS {"count": n, "false": k, "max_s": t}``: a ``wait()`` that returned False ran to its timeout.
"""

from __future__ import annotations

import atexit
import json
import runpy
import sys
import time
from typing import Any

import crtk  # type: ignore[import-not-found]

from tests.ros.rclpy_rate_race import close_the_race

close_the_race()

waits: list[tuple[bool, float]] = []
_original_wait = crtk.wait_move_handle.wait


def _recorded_wait(self: Any, *args: Any, **kwargs: Any) -> Any:
    start = time.monotonic()
    result = _original_wait(self, *args, **kwargs)
    waits.append((bool(result), time.monotonic() - start))
    return result


def _report() -> None:
    summary = {
        "count": len(waits),
        "false": sum(not ok for ok, _ in waits),
        "max_s": round(max((s for _, s in waits), default=0.0), 3),
    }
    print(f"WAITS {json.dumps(summary)}", flush=True)


crtk.wait_move_handle.wait = _recorded_wait
atexit.register(_report)
script = sys.argv[1]
sys.argv = sys.argv[1:]
runpy.run_path(script, run_name="__main__")
