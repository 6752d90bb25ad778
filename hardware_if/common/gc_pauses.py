"""Short garbage-collector pauses for the processes that keep a real-time rate: ``sim-dvrk`` and ``deploy``.

CPython's cyclic garbage collector stops every thread of its process while it runs. Its full (oldest
generation) pass walks every object the interpreter tracks: after start-up, with PyBullet, Pinocchio,
rclpy and a task scene loaded, about 136,000 of them, 30-54 ms on an idle core of this project's 2-core
machine, and longer when the machine is busy (a 76.7 ms pass in ``sim-dvrk`` under load). That is longer
than the deploy's deadman timeout (50 ms, five periods of the dVRK's 100 Hz): a full pass in ``sim-dvrk``
stops its ``measured_js`` and the rehearsing deploy holds on ``stale``, a full pass in ``deploy`` delays its
own ticks. Rehearsals on a loaded machine held with the console's stamps stopped for 50-90 ms.

:func:`freeze_startup_heap` moves everything alive at the end of start-up to the collector's permanent
generation (``gc.freeze``), which its passes no longer walk: modules, classes, functions, the node and the
first scene. Objects made later (a new scene's, an episode's) are collected as before, and full passes walk
only them. The cost: reference cycles among the frozen objects that later become garbage (the first scene's,
once a reset replaces it) are never collected, a one-off amount that does not grow with the episodes.
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
