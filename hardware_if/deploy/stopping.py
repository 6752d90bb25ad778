"""Stopping a deploy on a signal, never in the middle of a control tick.

SIGINT, SIGTERM and SIGHUP stop between two control ticks: the deploy closes its recording and exits with
128 + the signal number (130, 143, 129). ``ready-arm`` and ``calibrate-wrench`` stop on them the same way.
"""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Iterator
from typing import Any

from sim.sweep.stopping import handling

__all__ = ["EXIT_INTERRUPTED", "STOP_SIGNALS", "Interrupted", "Stopper"]

#: Exit status of a deploy stopped with Ctrl-C (SIGINT); SIGTERM gives 143 and SIGHUP 129 (128 + signal).
EXIT_INTERRUPTED = 130
#: Signals that stop a deploy between two ticks, as Ctrl-C does.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class Interrupted(KeyboardInterrupt):
    """A stop signal arrived (SIGINT, SIGTERM or SIGHUP): stop commanding between two ticks.

    Attributes:
        signum: The signal's number.
    """

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(signal.Signals(signum).name)


class Stopper:
    """Turns stop signals into :class:`Interrupted`, never in the middle of a control tick.

    Outside a tick the signal raises at once (a wait for the arm is cut short); inside one
    (``with stopper.tick():``) it is noted and raised when the tick has been sent and recorded.
    """

    def __init__(self) -> None:
        self.signum = 0
        self._in_tick = False

    def _handle(self, signum: int, _frame: Any) -> None:
        self.signum = self.signum or signum
        if not self._in_tick:
            raise Interrupted(self.signum)

    @contextlib.contextmanager
    def installed(self) -> Iterator[Stopper]:
        with handling(STOP_SIGNALS, self._handle):
            yield self

    @contextlib.contextmanager
    def tick(self) -> Iterator[None]:
        self._in_tick = True
        try:
            yield
        finally:
            self._in_tick = False
        if self.signum:
            raise Interrupted(self.signum)
