"""Run the real command line (:func:`tissue_retract.cli.main`) in children forked from the test's process.

A fresh ``python -m tissue_retract`` spends 0.6 s of CPU before it reads its arguments, and 3 s once a command
imports torch and the simulation; a child forked from a process that has imported them starts at ``main``. Each
child is what ``python -m tissue_retract ARGS`` would be: its own output streams, an exception escaping ``main``
printed as the interpreter prints it, the exit status the interpreter would give. It runs in a process group of its
own, which is ended with it (a sweep's pool workers), and is killed after a hang guard.
"""

from __future__ import annotations

import atexit
import contextlib
import importlib
import io
import os
import select
import signal
import subprocess
import sys
import tempfile
import time
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NoReturn

__all__ = ["default_signals", "end_as_the_interpreter", "run_forked", "run_one", "standard_streams"]

#: Modules the commands import once their arguments are checked: imported here once, not in every child.
PRELOAD = (
    "torch",
    "sim.envs",
    "sim.evaluation",
    "policies.checkpoint",
    "policies.resolve",
    "policies.trainer",
    "tissue_retract.workers",
)


def run_forked(
    argvs: Sequence[Sequence[str]], *, parallel: int = 2, timeout_s: float = 300.0
) -> list[subprocess.CompletedProcess[str]]:
    """Run ``tissue-retract ARGV`` for each ARGV, ``parallel`` at a time, each in a child forked from this process.

    Args:
        argvs: The commands' arguments (after ``tissue-retract``).
        parallel: Children running at once (the machine has two cores).
        timeout_s: A child still running after this long is killed [s] (a hang guard, not a timing: its
            return code is then ``-SIGKILL`` and its stderr says so).

    Returns:
        One completed process per command, in their order, with its exit status and output.
    """
    from tissue_retract.cli import build_parser

    for argv in argvs:  # the subcommands' modules
        build_parser(list(argv))
    for name in PRELOAD:
        importlib.import_module(name)
    results: list[subprocess.CompletedProcess[str] | None] = [None] * len(argvs)
    with tempfile.TemporaryDirectory(prefix="forked-cli-") as folder:
        pending = list(enumerate(argvs))
        running: dict[int, tuple[int, int, float]] = {}  # pidfd -> (index, pid, started)
        sys.stdout.flush()
        sys.stderr.flush()
        try:
            while pending or running:
                while pending and len(running) < parallel:
                    index, argv = pending.pop(0)
                    streams = (Path(folder) / f"{index}.out", Path(folder) / f"{index}.err")
                    pid = os.fork()
                    if pid == 0:
                        _child(list(argv), *streams)
                    running[os.pidfd_open(pid)] = (index, pid, time.monotonic())
                first_deadline = min(started for _, _, started in running.values()) + timeout_s
                ready, _, _ = select.select(list(running), [], [], max(0.0, first_deadline - time.monotonic()))
                now = time.monotonic()
                for pidfd in list(running):
                    index, pid, started = running[pidfd]
                    if pidfd not in ready and now - started < timeout_s:
                        continue
                    del running[pidfd]
                    os.close(pidfd)
                    with contextlib.suppress(ProcessLookupError, PermissionError):
                        os.killpg(pid, signal.SIGKILL)  # what it started; a hung child itself
                    status = os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])
                    out, err = (Path(folder) / f"{index}{suffix}" for suffix in (".out", ".err"))
                    stderr = err.read_text(errors="replace")
                    if pidfd not in ready:
                        stderr += f"\n(killed after {timeout_s:g} s)\n"
                    results[index] = subprocess.CompletedProcess(
                        list(argvs[index]), status, out.read_text(errors="replace"), stderr
                    )
        finally:  # the test stopped (a failure, its timeout, Ctrl-C): no child outlives it
            for pidfd, (_, pid, _) in running.items():
                with contextlib.suppress(ProcessLookupError, PermissionError):
                    os.killpg(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                os.close(pidfd)
    return [r for r in results if r is not None]


def run_one(*args: str, timeout_s: float = 300.0) -> subprocess.CompletedProcess[str]:
    """``tissue-retract ARGS`` in a child forked from this process (:func:`run_forked` of one command)."""
    (done,) = run_forked([args], timeout_s=timeout_s)
    return done


def _child(argv: list[str], stdout: Path, stderr: Path) -> None:
    """In the forked child: run the command as ``python -m tissue_retract`` would, then leave at once."""
    atexit._clear()  # this process's exit handlers are the test's: the child runs only those it registers

    def command() -> int | None:
        os.setpgid(0, 0)
        out, err = (os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600) for path in (stdout, stderr))
        standard_streams(out, err)
        default_signals(signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGALRM)
        signal.signal(signal.SIGINT, signal.default_int_handler)  # as a fresh interpreter has it
        signal.pthread_sigmask(signal.SIG_SETMASK, set())
        if "torch" in sys.modules:
            # OpenMP's threads do not survive a fork: a child's first parallel operation waited for ever on the
            # threads of a parent that had used them (a 2000 x 2000 matmul). One thread has no pool to wait on.
            sys.modules["torch"].set_num_threads(1)
        import tissue_retract.__main__
        from tissue_retract.cli import main

        sys.argv = [tissue_retract.__main__.__file__, *argv]
        return main(argv)

    end_as_the_interpreter(command, exit_handlers=True)


def standard_streams(stdout_fd: int, stderr_fd: int) -> None:
    """In a forked child: file descriptors 1 and 2 become ``stdout_fd`` and ``stderr_fd`` (the same one for one
    stream of both), Python's streams are made anew on them, line-buffered, and stdin reads nothing."""
    os.dup2(stdout_fd, 1)
    os.dup2(stderr_fd, 2)
    sys.stdout = io.TextIOWrapper(io.FileIO(1, "w", closefd=False), line_buffering=True)
    sys.stderr = io.TextIOWrapper(io.FileIO(2, "w", closefd=False), line_buffering=True)
    sys.stdin = io.TextIOWrapper(io.FileIO(os.open(os.devnull, os.O_RDONLY), "r"))


def default_signals(*signals: signal.Signals) -> None:
    """In a forked child: ``signals`` back to their default actions (the test's handlers are not the command's)."""
    for sig in signals:
        signal.signal(sig, signal.SIG_DFL)


def end_as_the_interpreter(command: Callable[[], int | None], *, exit_handlers: bool) -> NoReturn:
    """In a forked child: run ``command`` (its set-up and a command's ``main``) and end the process as the
    interpreter ends ``python -m tissue_retract``: ``main``'s status, a ``SystemExit``'s code or message, the
    traceback of an exception that escapes (status 1); then the exit handlers the child registered
    (``exit_handlers``), the streams flushed, and ``os._exit``: never the test's own clean-up."""
    status: int = 1
    try:
        status = command() or 0
    except SystemExit as e:  # what the interpreter makes of it
        if e.code is None or isinstance(e.code, int):
            status = e.code or 0
        else:
            print(e.code, file=sys.stderr)
    except BaseException:  # an exception escaping main: the traceback the interpreter would print
        traceback.print_exc()
    finally:
        if exit_handlers:
            with contextlib.suppress(BaseException):
                atexit._run_exitfuncs()
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(BaseException):  # the child must reach _exit whatever happened
                stream.flush()
        os._exit(status if 0 <= status < 256 else 1)
