"""Short garbage-collector pauses for the processes that keep a real-time rate: ``sim-dvrk`` and ``deploy``.

CPython's cyclic garbage collector stops every thread of its process while it runs. Its full (oldest
generation) pass walks every object the interpreter tracks: after start-up, with PyBullet, Pinocchio,
rclpy and a task scene loaded, about 150,000 of them, 30-55 ms on an idle core of this project's 2-core
machine and about twice that when the machine is busy. That is longer than the deploy's deadman timeout
(50 ms, five periods of the dVRK's 100 Hz): a full pass in ``sim-dvrk`` stops its ``measured_js`` and the
rehearsing deploy holds on ``stale``, a full pass in ``deploy`` delays its own ticks. Rehearsals on a
loaded machine held so (the console's stamps stopped for 50-90 ms, about a second after a scene reset,
when the new scene's objects push the collector into a full pass).

:func:`freeze_startup_heap` moves everything allocated during start-up to the collector's permanent
generation (``gc.freeze``), which its passes no longer walk: modules, classes, functions and the first
scene are never garbage. Objects made later (a new scene's, an episode's) are collected as before, so
nothing leaks that would not have leaked anyway; the full passes walk only them.
"""

from __future__ import annotations

import gc

__all__ = ["freeze_startup_heap"]


def freeze_startup_heap() -> int:
    """Collect once, then keep every object alive now out of the collector's passes; return how many.

    Call it once, when start-up is over and before the real-time loop starts: the one full collection it
    runs is then still outside the loop.
    """
    gc.collect()
    gc.freeze()
    return gc.get_freeze_count()
