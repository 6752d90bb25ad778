"""Joint logs written as a rosbag2 bag of ``/<ARM>/measured_js``, as ``ros2 bag record`` writes it.

``calibrate-wrench --record`` keeps its excitation this way, so that the fit can be repeated offline
(``calibrate-wrench --from BAG``) and the log read by any rosbag2 tool. The writer is rosbags' own (MCAP
storage), the library :mod:`~hardware_if.wrench.joint_logs` reads bags with; no ROS install is needed.

A bag is written whole or not at all: into a hidden folder beside it (``.<name>.XXXX.partial``), renamed into
place when complete; a write the system refuses (a full disk, a file-size limit) removes the hidden folder
and raises :class:`~psm_control.errors.OutputWriteError` naming the bag. :func:`reserve_bag_space` takes the
bag's room on the disk before the excitations that fill it are run, and gives it to the bag when it is written.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hardware_if.wrench.joint_logs import JOINT_NAMES, JointLog
from psm_control.errors import OutputFileError, OutputWriteError
from psm_control.outputs import describe_os_error, special_file_kind

__all__ = ["BYTES_PER_SAMPLE", "BagSpace", "reserve_bag_space", "write_joint_bag"]

_MSGTYPE = "sensor_msgs/msg/JointState"
#: Gap between two logs written into one bag [s].
_GAP_S = 1.0
#: Room one sample takes in a bag [bytes]: 316 measured (a 6-joint JointState in MCAP), with a margin.
BYTES_PER_SAMPLE = 400
#: Room for the bag's metadata, summary and index beyond its samples [bytes].
_OVERHEAD_BYTES = 256 * 1024


@dataclass
class BagSpace:
    """The hidden folder a bag is written in, and the room reserved for it there.

    Attributes:
        path: The bag's folder, where it goes when complete.
        staging: The hidden folder beside it that the bag is written in.
        reserved_bytes: The room taken by :func:`reserve_bag_space`.
    """

    path: Path
    staging: Path
    reserved_bytes: int = 0

    @property
    def reserve(self) -> Path:
        """The file that holds the room until the bag is written."""
        return self.staging / "reserve"

    def release(self) -> None:
        """Give the reserved room back (to the bag about to be written)."""
        with contextlib.suppress(OSError):
            self.reserve.unlink()

    def discard(self) -> None:
        """Remove the hidden folder and whatever is in it."""
        shutil.rmtree(self.staging, ignore_errors=True)


def _staging(path: Path, field: str) -> BagSpace:
    kind = special_file_kind(path)
    if kind is not None or os.path.lexists(path):
        what = f"this {kind} exists" if kind else "this file exists"
        raise OutputFileError(field, path, f"a bag folder that does not exist yet (ros2 bag record's -o; {what})")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent))
    except OSError as e:
        raise OutputFileError(field, path, f"a bag whose folder can be made ({describe_os_error(e)})") from e
    return BagSpace(path, staging)


def reserve_bag_space(path: str | Path, samples: int, field: str = "--record") -> BagSpace:
    """Check that a bag of ``samples`` joint samples can be written at ``path``, and take its room now.

    The room is allocated (blocks, not a sparse file) in the bag's hidden folder, so a disk that cannot take
    the bag fails here, before the arm moves, and a disk that fills meanwhile cannot take it from the bag.

    Raises:
        OutputFileError: ``path`` exists, or its folder cannot be made or written.
        OutputWriteError: The disk (or the process's file-size limit, or a quota) has no room for the bag.
    """
    space = _staging(Path(path), field)
    size = int(samples) * BYTES_PER_SAMPLE + _OVERHEAD_BYTES
    try:
        fd = os.open(space.reserve, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        try:
            os.posix_fallocate(fd, 0, size)
        finally:
            os.close(fd)
    except OSError as e:
        space.discard()
        reason = f"{describe_os_error(e)}; a bag of {samples} samples takes about {math.ceil(size / 1e6)} MB"
        raise OutputWriteError(field, space.path, reason) from e
    space.reserved_bytes = size
    return space


def write_joint_bag(
    path: str | Path,
    arm: str,
    logs: Sequence[JointLog],
    start_s: float = 0.0,
    space: BagSpace | None = None,
    field: str = "--record",
    console: str | None = None,
) -> Path:
    """Write ``logs`` one after the other as ``/<arm>/measured_js`` into a new MCAP bag folder ``path``.

    Args:
        path: The bag's folder (must not exist, as ``ros2 bag record -o`` wants it).
        arm: The arm's namespace.
        logs: The joint logs, in time order; each sample's stamp is ``start_s`` plus its time, the logs
            ``_GAP_S`` apart.
        start_s: The first sample's stamp [s].
        space: The room :func:`reserve_bag_space` took for it; None: a hidden folder is made now.
        field: The option that named the bag, for the errors.
        console: The console that served the arm (``sim-dvrk``, ``dvrk``), kept in the bag's metadata as
            ``custom_data: console`` so a reader can tell a real arm's log from a simulated one; None: not said.

    Raises:
        OutputFileError: ``path`` exists (when ``space`` is None).
        OutputWriteError: The bag could not be written (nothing is left at ``path``).
    """
    from rosbags.rosbag2 import StoragePlugin, Writer, WriterError  # rosbags: imported where bags are written
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    space = space or _staging(path, field)
    space.release()
    typestore = get_typestore(Stores.ROS2_JAZZY)
    types = typestore.types
    offset = float(start_s)
    written = space.staging / path.name
    try:
        with Writer(written, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            if console is not None:
                writer.set_custom_data("console", console)
            connection = writer.add_connection(f"/{arm}/measured_js", _MSGTYPE, typestore=typestore)
            for log in logs:
                for k in range(len(log.t_s)):
                    stamp_s = offset + float(log.t_s[k])
                    nanoseconds = round(stamp_s * 1e9)
                    stamp = types["builtin_interfaces/msg/Time"](
                        sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000
                    )
                    message = types["sensor_msgs/msg/JointState"](
                        header=types["std_msgs/msg/Header"](stamp=stamp, frame_id=""),
                        name=list(JOINT_NAMES),
                        position=np.asarray(log.q[k], dtype=np.float64),
                        velocity=np.asarray(log.qd[k], dtype=np.float64),
                        effort=np.asarray(log.effort[k], dtype=np.float64),
                    )
                    writer.write(connection, nanoseconds, typestore.serialize_cdr(message, _MSGTYPE))
                if len(log.t_s):
                    offset += float(log.t_s[-1]) + _GAP_S
        for name in os.listdir(written):
            fd = os.open(written / name, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
        os.rename(written, path)  # fails, rather than merging, if something appeared at path meanwhile
    except OSError as e:
        raise OutputWriteError(field, path, describe_os_error(e)) from e
    except WriterError as e:
        cause = e.__cause__ or e.__context__
        reason = describe_os_error(cause) if isinstance(cause, OSError) else str(e)
        raise OutputWriteError(field, path, reason) from e
    finally:
        space.discard()
    return path
