"""What some faults of the matrix need around the deploy: a full file system, an arm moved off its start.

:func:`small_filesystem` mounts a tmpfs of a given size (as root) and optionally fills it up to a given
free space, so a recording meets a real ``ENOSPC`` when it grows past it; where mounting is not permitted
it says so instead (the fault then cannot run as intended). :func:`move_arm_off_start` enables and homes
the simulated arm and moves it away from the task's start with the console's own trajectory, as a
colleague's script would between two deploys.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from hardware_if.common.errors import DvrkTimeoutError
from psm_control.errors import ConfigurationError
from psm_control.robot import PsmModel

__all__ = ["MOVED_OFFSET_RAD", "move_arm_off_start", "small_filesystem", "wait_until_served"]

#: How far the arm is moved off the episode's start, on its first joint (yaw) [rad].
MOVED_OFFSET_RAD = 0.25


@contextlib.contextmanager
def small_filesystem(folder: Path, size_bytes: int, free_bytes: int | None = None) -> Iterator[Path]:
    """A tmpfs of ``size_bytes`` mounted on ``folder`` for the block, filled to leave ``free_bytes`` free.

    Raises:
        ConfigurationError: The mount is not permitted (it needs root, or CAP_SYS_ADMIN).
    """
    folder.mkdir(parents=True, exist_ok=True)
    mount = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size_bytes}", "tmpfs", str(folder)], capture_output=True, text=True
    )
    if mount.returncode != 0:
        raise ConfigurationError("small file system", str(folder), f"a tmpfs mount (root): {mount.stderr.strip()}")
    try:
        if free_bytes is not None:
            filler = folder / "filler"
            with filler.open("wb") as f, contextlib.suppress(OSError):
                stat = os.statvfs(folder)
                f.write(b"\0" * max(0, stat.f_bavail * stat.f_frsize - free_bytes))
        yield folder
    finally:
        subprocess.run(["umount", "-l", str(folder)], capture_output=True)


def move_arm_off_start(domain_id: int, guard_s: float, arm: str = "PSM1") -> np.ndarray:
    """Enable and home the arm, then move it :data:`MOVED_OFFSET_RAD` off the task's start; its joints.

    With a client of its own context on ``domain_id``, closed before returning (it must not stay in the
    graph as another commander).
    """
    import rclpy  # the ros extra
    from rclpy.context import Context

    from hardware_if.client.psm_client import PsmClient

    moved = PsmModel.from_variant().home()
    moved[0] += MOVED_OFFSET_RAD
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        with PsmClient(arm, node_name=f"colleague_{os.getpid()}", context=context) as client:
            client.wait_for_measurement(guard_s)
            client.enable(guard_s)
            client.home(guard_s)
            client.move_jp(moved)
            deadline = time.monotonic() + guard_s
            while abs(client.measure().q[0] - moved[0]) > 1e-3:  # each new measurement, until it is there
                if time.monotonic() > deadline:
                    raise DvrkTimeoutError("the move off the episode's start", guard_s)
                client.next_measurement(client.measure().stamp_s, guard_s)
    finally:
        rclpy.shutdown(context=context)
    return moved


def wait_until_served(domain_id: int, guard_s: float, arm: str = "PSM1") -> None:
    """Wait until the arm's console publishes ``measured_js`` (a listen-only client of its own context)."""
    import rclpy  # the ros extra
    from rclpy.context import Context

    from hardware_if.client.psm_client import PsmClient

    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        with PsmClient(arm, node_name=f"look_{os.getpid()}", listen_only=True, context=context) as client:
            client.wait_for_measurement(guard_s)
    finally:
        rclpy.shutdown(context=context)
