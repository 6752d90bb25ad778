"""Stopping a sweep: SIGINT and SIGTERM end it between trials, whatever signal handling it inherited.

A sweep started in the background of a script inherits SIGINT ignored (the shell does that for ``&``
jobs); one started from a thread that blocks signals (a test runner's, a library's) inherits them
blocked, and a blocked signal stays pending for ever; Python's default SIGTERM ends the process at once:
the pool's workers and semaphores are then left to the resource tracker, which warns of leaked
semaphores. :func:`stop_signals` installs handlers of the sweep's own for both (unblocked), which raise
:class:`SweepStopped` (a ``KeyboardInterrupt``) in the main thread; the executor then keeps the running
trials that finish within :data:`STOP_GRACE_S`, ends the pool's workers (:func:`stop_pool`) and the
command exits with 128 + the signal (130, 143). The pool's workers ignore both
(:func:`ignore_stop_signals`): a Ctrl-C at a terminal reaches the whole process group, and a worker killed
mid-trial would lose that trial.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterable, Iterator
from typing import Any

__all__ = [
    "STOP_GRACE_S",
    "STOP_SIGNALS",
    "SweepStopped",
    "handling",
    "ignore_stop_signals",
    "stop_pool",
    "stop_signals",
]

#: The signals that stop a sweep.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
#: How long a stopped sweep waits for its running trials before it ends their workers [s]: a stop takes
#: seconds, and a trial that did not finish is not lost (the resumed sweep runs it).
STOP_GRACE_S = 2.0


class SweepStopped(KeyboardInterrupt):
    """A stop signal arrived: the sweep ends after its running trials.

    Attributes:
        signum: The signal's number (the exit status is 128 + it).
    """

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(signal.Signals(signum).name)


def _raise(signum: int, _frame: Any) -> None:
    raise SweepStopped(signum)


@contextlib.contextmanager
def handling(signals: Iterable[int], handler: Callable[[int, Any], Any]) -> Iterator[None]:
    """``handler`` handles ``signals`` in the block, unblocked if they came blocked (a blocked signal would
    never arrive); the previous handlers and signal mask come back after. Off the main thread, which
    signals are never delivered to, nothing is installed."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    signals = tuple(signals)
    previous = {sig: signal.signal(sig, handler) for sig in signals}
    previous_mask = signal.pthread_sigmask(signal.SIG_UNBLOCK, signals)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous_mask)
        for sig, old in previous.items():
            signal.signal(sig, old)


def stop_signals() -> contextlib.AbstractContextManager[None]:
    """SIGINT and SIGTERM raise :class:`SweepStopped` in the block (:func:`handling`)."""
    return handling(STOP_SIGNALS, _raise)


def ignore_stop_signals() -> None:
    """In a pool worker: leave stopping to the sweep's process, which lets the running trial finish."""
    for sig in STOP_SIGNALS:
        signal.signal(sig, signal.SIG_IGN)


def stop_pool(pool: Any) -> None:
    """A stop signal reached a pool of long runs: cancel what has not started and end the running ones now.

    For runs that keep their own progress (a training run's checkpoints): waiting for them could take
    hours, and a stop must take seconds.
    """
    processes = list((getattr(pool, "_processes", None) or {}).values())  # shutdown forgets them
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.kill()  # a sweep's workers ignore SIGTERM (they leave stopping to the sweep)
    for process in processes:
        process.join()
