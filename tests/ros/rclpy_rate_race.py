"""A race in rclpy's ``Node.create_rate`` (Jazzy 7.1), closed in the processes that run the dVRK's client.

``create_rate`` creates the rate's timer with no callback, and ``Rate`` sets the callback a few lines
later. The dVRK client spins its node on a thread of its own (``crtk/ral_ros2.py``) and creates rates
from the main thread (``check_connections`` among others). When the main thread is preempted for longer
than one period (10 ms at the 100 Hz the client asks for) between the two, the executor calls the timer's
callback, ``None``: ``TypeError: 'NoneType' object is not callable`` kills the spin thread, and the
client receives nothing more (measured under load: every later check timed out waiting for
``measured_js``). The client is run unmodified; rclpy's ``create_rate`` is replaced by the same code with
a no-op callback in place of ``None``, so that a tick before ``Rate`` takes over does nothing.
"""

from __future__ import annotations

from typing import Any

import rclpy.node
from rclpy.timer import Rate


def _no_tick() -> None:
    """The rate's timer before ``Rate`` sets its own callback: a tick then wakes no one."""


def _create_rate(self: Any, frequency: float, clock: Any = None) -> Rate:
    """``rclpy.node.Node.create_rate`` (7.1) with a callback from the start."""
    if frequency <= 0:
        raise ValueError("frequency must be > 0")
    timer = self.create_timer(1.0 / frequency, _no_tick, self._rate_group, clock)
    return Rate(timer, context=self.context)


def close_the_race() -> None:
    """Install the race-free ``create_rate`` in this process (before the client creates its node)."""
    rclpy.node.Node.create_rate = _create_rate
