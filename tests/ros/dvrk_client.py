"""The dVRK 2.4 Python client (crtk, dvrk) as a test dependency, and sim-dvrk as a child process to run it on.

The client is not part of this package: its sources (``$DVRK_CLIENT_DIR``, default
``../shared/dvrk-client`` next to the repository) and PyKDL (unpacked by ``make install-dev`` into
``$VIRTUAL_ENV/opt/pykdl``) go on the client processes' PYTHONPATH and LD_LIBRARY_PATH only.
"""

from __future__ import annotations

import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from hardware_if.common.network import local_ros_env

REPOSITORY = Path(__file__).resolve().parents[2]
SCRIPTS_HERE = Path(__file__).resolve().parent
PYKDL = Path(sys.prefix) / "opt" / "pykdl"


def _origin() -> list[Path]:
    """The folder a local clone was made from (a fresh clone's ``origin``), if it is a local path."""
    try:
        url = subprocess.run(
            ["git", "-C", str(REPOSITORY), "config", "--get", "remote.origin.url"],
            capture_output=True,
            text=True,
            timeout=30,
            check=False,
        ).stdout.strip()
    except OSError:
        return []
    path = Path(url.removeprefix("file://"))
    return [path.resolve()] if url and path.is_absolute() and path.exists() else []


#: Where the client is looked for when ``$DVRK_CLIENT_DIR`` is not set: ``shared/dvrk-client`` beside the
#: repository or beside any folder above it, then beside the repository a clone was made from (a test
#: clone in /tmp), then the shared folder of the machine this project is developed on.
_CANDIDATES = [parent / "shared" / "dvrk-client" for root in (REPOSITORY, *_origin()) for parent in root.parents] + [
    Path("/work/shared/dvrk-client")
]


def client_dir() -> Path:
    """Where the dVRK client's ``crtk/`` and ``dvrk/`` are (the first candidate that has them)."""
    if os.environ.get("DVRK_CLIENT_DIR"):
        return Path(os.environ["DVRK_CLIENT_DIR"])
    return next((c for c in _CANDIDATES if (c / "crtk" / "__init__.py").is_file()), _CANDIDATES[0])


def missing() -> str | None:
    """Why the client cannot run here, or None."""
    where = client_dir()
    if not (where / "crtk" / "__init__.py").is_file() or not (where / "dvrk" / "__init__.py").is_file():
        looked = ", ".join(str(c) for c in _CANDIDATES) if not os.environ.get("DVRK_CLIENT_DIR") else str(where)
        return f"the dVRK client is not in {looked} (set DVRK_CLIENT_DIR to the folder holding crtk/ and dvrk/)"
    if not any((PYKDL / "usr" / "lib" / "python3" / "dist-packages").glob("PyKDL*.so")):
        return f"PyKDL is not in {PYKDL} (run `make install-dev`, which fetches it from Debian)"
    return None


def client_env(domain_id: int) -> dict[str, str]:
    """The environment of a client process: loopback ROS on ``domain_id``, the client and PyKDL on the paths."""
    env = local_ros_env(domain_id)
    paths = [str(client_dir()), str(PYKDL / "usr" / "lib" / "python3" / "dist-packages"), str(REPOSITORY)]
    env["PYTHONPATH"] = os.pathsep.join([*paths, *filter(None, [env.get("PYTHONPATH")])])
    libraries = [str(PYKDL / "usr" / "lib" / "x86_64-linux-gnu"), *filter(None, [env.get("LD_LIBRARY_PATH")])]
    env["LD_LIBRARY_PATH"] = os.pathsep.join(libraries)
    env["ROS_VERSION"] = "2"  # what a sourced ROS 2 set-up sets; crtk reads it
    return env


class Process:
    """A child process whose merged output is read line by line as it comes (so it can be waited on)."""

    def __init__(self, command: list[str], env: dict[str, str], stdin: str | None = None) -> None:
        self.process = subprocess.Popen(
            command,
            env=env,
            stdin=subprocess.PIPE if stdin is not None else subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        self.lines: list[str] = []
        self._queue: queue.Queue[str | None] = queue.Queue()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        if stdin is not None and self.process.stdin is not None:
            self.process.stdin.write(stdin)
            self.process.stdin.close()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self._queue.put(line)
        self._queue.put(None)

    def wait_for(self, text: str, timeout_s: float) -> bool:
        """Wait until a line containing ``text`` is printed; False on timeout or exit."""
        deadline = time.monotonic() + timeout_s
        if any(text in line for line in self.lines):
            return True
        while (left := deadline - time.monotonic()) > 0:
            try:
                line = self._queue.get(timeout=left)
            except queue.Empty:
                return False
            if line is None:
                return False
            self.lines.append(line)
            if text in line:
                return True
        return False

    def wait(self, timeout_s: float) -> int | None:
        """Wait for the process to end; its exit status, or None if it is still running."""
        try:
            return self.process.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            return None

    def output(self) -> str:
        """Everything printed so far (all of it once the process has ended)."""
        if self.process.poll() is not None:
            self._reader.join(timeout=10.0)
        while True:
            try:
                line = self._queue.get_nowait()
            except queue.Empty:
                break
            if line is not None:
                self.lines.append(line)
        return "".join(self.lines)

    def stop(self, sig: int = signal.SIGINT, timeout_s: float = 20.0) -> int:
        """Signal the process (if running), wait for it; its exit status (killed after ``timeout_s``)."""
        if self.process.poll() is None:
            self.process.send_signal(sig)
        if self.wait(timeout_s) is None:
            self.process.kill()
            self.process.wait()
        return int(self.process.returncode)


def start_sim(domain_id: int, *extra: str, ready_timeout_s: float = 240.0) -> Process:
    """Start ``tissue-retract sim-dvrk`` and wait until it serves (its start-up line)."""
    command = [sys.executable, "-m", "tissue_retract", "sim-dvrk", "--domain-id", str(domain_id), *extra]
    sim = Process(command, local_ros_env(domain_id))
    if not sim.wait_for("simulated ", ready_timeout_s):
        sim.stop()
        raise RuntimeError(f"sim-dvrk did not start within {ready_timeout_s} s:\n{sim.output()}")
    return sim


def run_client(script: Path, domain_id: int, *args: str, stdin: str | None = None) -> Process:
    """Start a client script (through ``run_dvrk_script.py``, which records every ``wait()``)."""
    command = [sys.executable, str(SCRIPTS_HERE / "run_dvrk_script.py"), str(script), *args]
    return Process(command, client_env(domain_id), stdin=stdin)


__all__ = ["PYKDL", "Process", "client_dir", "client_env", "missing", "run_client", "start_sim"]
