"""Stopping a command: SIGINT, SIGTERM and SIGHUP end it between trials, whatever signal handling it inherited.

A sweep started in the background of a script inherits SIGINT ignored (the shell does that for ``&``
jobs); one started from a thread that blocks signals (a test runner's, a library's) inherits them
blocked, and a blocked signal stays pending for ever; Python's default SIGTERM ends the process at once:
the pool's workers and semaphores are then left to the resource tracker, which warns of leaked
semaphores. :func:`stop_signals` installs handlers of the sweep's own for all three (unblocked), which raise
:class:`SweepStopped` (a ``KeyboardInterrupt``) in the main thread; the executor then keeps the running
trials that finish within :data:`STOP_GRACE_S`, ends the pool's workers (:func:`stop_pool`) and the
command exits with 128 + the signal (130, 143, 129). The pool's workers ignore them
(:func:`ignore_stop_signals`): a Ctrl-C at a terminal reaches the whole process group, and a worker killed
mid-trial would lose that trial.

A command that runs other programs (a ``bench`` that starts ``sim-dvrk`` and deploys) starts them through
:class:`ChildProcesses`: each in a process group of its own, so that the command, not the terminal, stops
them, once and in order (the last started first: a deploy before its console), and bound to the command
(:func:`end_with_parent`), so that not even a SIGKILL of the command leaves one running.
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import os
import signal
import subprocess
import sys
import tempfile
import threading
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

__all__ = [
    "CHILD_STOP_S",
    "STOP_GRACE_S",
    "STOP_SIGNALS",
    "ChildProcesses",
    "SweepStopped",
    "end_with_parent",
    "handling",
    "ignore_stop_signals",
    "pool_worker_start",
    "stop_pool",
    "stop_signals",
]

#: The signals that stop a sweep or a command's children: Ctrl-C, ``kill``, a closed terminal.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
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
    """SIGINT, SIGTERM and SIGHUP raise :class:`SweepStopped` in the block (:func:`handling`)."""
    return handling(STOP_SIGNALS, _raise)


def ignore_stop_signals() -> None:
    """In a pool worker: leave stopping to the sweep's process, which lets the running trial finish."""
    for sig in STOP_SIGNALS:
        signal.signal(sig, signal.SIG_IGN)


def pool_worker_start() -> None:
    """Pool initializer: leave stopping to the pool's process, and end as soon as that process is gone (even
    after a SIGKILL).

    The worker ignores the stop signals (:func:`ignore_stop_signals`): its trial finishes and is kept.
    A spawned process holds a sentinel that becomes ready when its parent dies; a daemon thread waits on
    it, so no orphaned worker (and, with them gone, no orphaned resource tracker) keeps running.
    """
    ignore_stop_signals()
    parent = multiprocessing.parent_process()
    if parent is None:
        return

    def watch() -> None:
        parent.join()
        os._exit(1)

    threading.Thread(target=watch, name="end-with-parent", daemon=True).start()


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


#: How long a stopped command waits for each of its children to stop before it kills it [s]: a deploy or a
#: ``sim-dvrk`` stops within a second on an idle machine and within a few on a loaded one.
CHILD_STOP_S = 30.0
#: ``prctl`` option of Linux: the signal a process gets when the thread that started it ends.
_PR_SET_PDEATHSIG = 1


def end_with_parent(signum: int = signal.SIGTERM) -> Callable[[], None] | None:
    """A ``preexec_fn`` that binds a child to this process: the child gets ``signum`` when this process ends.

    Linux's ``prctl(PR_SET_PDEATHSIG)`` (through ctypes: the standard library has no call for it) is the one
    binding that holds when this process is killed with SIGKILL, which no handler of its own sees. It is set
    in the child between fork and exec, so it holds from the program's first instruction; a parent that
    ended in between (the child was reparented) ends the child at once. The signal is SIGTERM, which every
    command of this project stops on cleanly. The death signal follows the thread that started the child,
    so children are started from the main thread. The function allocates nothing in the child (libc is
    loaded here, before the fork), as a ``preexec_fn`` in a process with threads must. None off Linux.
    """
    if not sys.platform.startswith("linux"):
        return None
    parent = os.getpid()
    prctl = ctypes.CDLL(None, use_errno=True).prctl
    prctl.argtypes = (ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong)
    prctl.restype = ctypes.c_int

    def bind() -> None:
        prctl(_PR_SET_PDEATHSIG, int(signum), 0, 0, 0)
        if os.getppid() != parent:
            os._exit(128 + int(signum))

    return bind


class ChildProcesses:
    """The programs a command runs, and its temporary folder: bound to the command and stopped with it.

    Used as a context manager around the command's work. Each child starts in a process group of its own
    (a Ctrl-C at the terminal reaches the command alone, which stops its children once and in order) and
    bound to the command (:func:`end_with_parent`). When the block ends while children still run (a stop
    signal, an error), each gets SIGTERM, the last started first (a deploy before its console), and is
    waited for up to :data:`CHILD_STOP_S`, then killed with its process group; a second stop signal in
    that time kills those left at once. Then the temporary folder is removed, and one line on stderr says
    what was stopped and removed.

    Args:
        command: The command's name, for that line (``bench rehearsal``).
        folder_prefix: Make a temporary folder with this prefix (:attr:`folder`), removed last.
    """

    def __init__(self, command: str, *, folder_prefix: str | None = None) -> None:
        self.command = command
        self._folder_prefix = folder_prefix
        self._temporary: tempfile.TemporaryDirectory[str] | None = None
        self._folder: Path | None = None
        self._running: list[tuple[str, subprocess.Popen[Any]]] = []

    @property
    def folder(self) -> Path:
        """The temporary folder (with ``folder_prefix``, inside the block)."""
        if self._folder is None:
            raise RuntimeError(f"{self.command}: no temporary folder (folder_prefix) was asked for")
        return self._folder

    def __enter__(self) -> ChildProcesses:
        if self._folder_prefix is not None:
            self._temporary = tempfile.TemporaryDirectory(prefix=self._folder_prefix)
            self._folder = Path(self._temporary.name)
        return self

    def __exit__(self, _type: Any, error: BaseException | None, _traceback: Any) -> None:
        stopped = self._stop_all() if self._running else []
        removed = ""
        if self._temporary is not None:
            self._temporary.cleanup()
            removed = f"removed {self._folder}"
        if error is None or not (stopped or removed):
            return
        signum = getattr(error, "signum", None)
        why = signal.Signals(signum).name if isinstance(signum, int) else type(error).__name__
        what = ", ".join(f"{name} (pid {pid}, exit {status})" for name, pid, status in stopped)
        done = "; ".join(part for part in (f"stopped {what}" if what else "", removed) if part)
        print(f"{self.command}: {why}: {done}", file=sys.stderr, flush=True)

    def start(self, name: str, argv: Sequence[str], **popen: Any) -> subprocess.Popen[Any]:
        """Start ``argv`` (``subprocess.Popen``'s keywords) as the child ``name``, bound to this process."""
        process: subprocess.Popen[Any] = subprocess.Popen(
            list(argv), process_group=0, preexec_fn=end_with_parent(), **popen
        )
        self._running.append((name, process))
        return process

    def run(
        self, name: str, argv: Sequence[str], *, timeout_s: float | None = None, **popen: Any
    ) -> subprocess.CompletedProcess[Any]:
        """Run ``argv`` to its end (its output captured as text unless ``popen`` says where it goes); one that
        outlasts ``timeout_s`` is stopped."""
        popen = {"stdout": subprocess.PIPE, "stderr": subprocess.PIPE, "text": True, **popen}
        process = self.start(name, argv, **popen)
        try:
            stdout, stderr = process.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            process.send_signal(signal.SIGTERM)
            stdout, stderr = _ended(process)
        self._forget(process)
        return subprocess.CompletedProcess(list(argv), int(process.returncode), stdout, stderr)

    def stop(self, process: subprocess.Popen[Any], signum: int = signal.SIGTERM) -> int:
        """Stop one child with ``signum`` (killed with its group after :data:`CHILD_STOP_S`); its exit status."""
        if process.poll() is None:
            process.send_signal(signum)
        _ended(process)
        self._forget(process)
        return int(process.returncode)

    def _forget(self, process: subprocess.Popen[Any]) -> None:
        self._running = [(n, p) for n, p in self._running if p is not process]

    def _stop_all(self) -> list[tuple[str, int, int]]:
        """SIGTERM to each running child, the last started first; a second stop signal kills the rest."""
        stopped: list[tuple[str, int, int]] = []

        def hurry(signum: int, _frame: Any) -> None:
            raise SweepStopped(signum)

        with handling(STOP_SIGNALS, hurry):
            try:
                while self._running:
                    name, process = self._running[-1]
                    stopped.append((name, process.pid, self.stop(process)))
            except SweepStopped:
                for name, process in self._running:
                    _kill_group(process)
                    stopped.append((name, process.pid, int(process.returncode)))
                self._running = []
        return stopped


def _ended(process: subprocess.Popen[Any]) -> tuple[Any, Any]:
    """Wait for a signalled child, reading what is left of its output (a child blocked on a full pipe never
    ends); kill it and its process group after :data:`CHILD_STOP_S`. Its output, as ``communicate`` gives it."""
    try:
        return process.communicate(timeout=CHILD_STOP_S)
    except subprocess.TimeoutExpired:
        _kill_group(process)
        return process.communicate()  # the rest, up to the kill
    except ValueError:  # its pipes were closed by whoever read them: wait without them
        try:
            process.wait(timeout=CHILD_STOP_S)
        except subprocess.TimeoutExpired:
            _kill_group(process)
        return None, None


def _kill_group(process: subprocess.Popen[Any]) -> None:
    """SIGKILL to a child and its process group (its own children); wait for it."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(process.pid, signal.SIGKILL)
    with contextlib.suppress(ProcessLookupError):
        process.kill()
    process.wait()
