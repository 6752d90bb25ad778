"""The executor every node of this project spins on: rclpy's C++ events executor.

At 1 kHz a node handles thousands of messages a second. rclpy's ``SingleThreadedExecutor`` rebuilds a
wait set and walks its callbacks in Python for each one, which alone took a third of the simulated
dVRK's CPU; ``rclpy.experimental.EventsExecutor`` (rclpy >= 7.1.5, Jazzy) dispatches from C++ and
calls only the callback itself in Python.

Its factory calls ``faulthandler.enable()``, which raises where ``sys.stderr`` has no file descriptor
(captured output under pytest, a notebook): :func:`make_executor` then hands it the process's own
stderr for that call, and falls back to ``SingleThreadedExecutor`` where even that has none or the
events executor is missing (an older rclpy). Both have the ``add_node``, ``spin_once`` and ``shutdown``
this project uses.

Spin with ``spin_once(timeout_sec=...)`` in a loop, not ``spin()``: the events executor's ``spin()``
(rclpy 7.1.6) ran no timer or subscription callback here and kept other Python threads from running.
"""

from __future__ import annotations

import contextlib
import sys
from typing import Any

__all__ = ["make_executor"]


def _has_fileno(stream: Any) -> bool:
    try:
        stream.fileno()
    except (AttributeError, OSError, ValueError):  # io.UnsupportedOperation is both of the latter
        return False
    return True


def make_executor(context: Any = None) -> Any:
    """A new executor for ``context`` (default: rclpy's default context): events executor if possible.

    Args:
        context: rclpy context whose nodes the executor spins.

    Returns:
        An ``EventsExecutor``, or a ``SingleThreadedExecutor`` where the events executor cannot start.
    """
    # The ros extra: rclpy, imported by the caller's module already.
    from rclpy.executors import SingleThreadedExecutor

    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:  # rclpy before 7.1.5
        return SingleThreadedExecutor(context=context)
    if _has_fileno(sys.stderr):
        return EventsExecutor(context=context)
    if not _has_fileno(sys.__stderr__):
        return SingleThreadedExecutor(context=context)
    # Where to print the stacks of a native crash: the process's own stderr, not the captured stream.
    with contextlib.redirect_stderr(sys.__stderr__):
        return EventsExecutor(context=context)
