"""The recording's file: every byte is written or the write fails with the file's name, and a failure leaves
a file that reads as far as it got.

The MCAP writer writes whole groups of records (a chunk and its index, the header) in one ``write`` call and
ignores how much was written. :class:`CheckedFile` writes all of each call or raises, and remembers where
the last complete call ended (:attr:`CheckedFile.good`): after a full disk, a write error or a folder
turned read-only, :meth:`CheckedFile.rewind` cuts the torn group off (which also gives back its space), and
:meth:`CheckedFile.append` can still add a few records there (the hold that stopped the run). A file that is
removed, or whose folder vanishes, while it is written would otherwise swallow every later write without
an error: :meth:`CheckedFile.flush` checks that the path still names the open file.

Cutting the torn end off does not always give back room for the hold: a file system hands a file its
space a page at a time, and a write that tore within the file's last page frees nothing. So the file keeps
room for its last records from the start: a hidden file beside it (``.<name>.reserve``) of
:data:`RESERVE_BYTES`, allocated when the recording opens (a disk without that much room is a hold before
anything moves) and removed when a write fails (its room then takes the hold and the report) or the file
closes. A killed run leaves it behind; it holds no data. A process's own file-size limit (``ulimit -f``,
``RLIMIT_FSIZE``) is a bound no reserve file can help with: the file stops taking data
:data:`RESERVE_BYTES` short of it, with the error the system would give there (EFBIG), so the room for the
hold is below the limit wherever the last chunk happened to end.

Every such error becomes :class:`RecordingError`, a hold (``recording failed: <path>: <os error>``).
"""

from __future__ import annotations

import contextlib
import errno
import os
import resource
from pathlib import Path

from hardware_if.common.errors import HoldError

__all__ = ["RESERVE_BYTES", "CheckedFile", "RecordingError", "describe_os_error"]

#: Room kept for the records written after a failure [bytes]. The hold comes first and takes well under
#: a kilobyte; the run's report follows if it fits (it lists every episode, a few hundred bytes each).
RESERVE_BYTES = 64 * 1024


def describe_os_error(error: OSError) -> str:
    """``No space left on device (ENOSPC)``: the system's words and the error's name."""
    name = errno.errorcode.get(error.errno or 0, "")
    text = error.strerror or str(error)
    return f"{text} ({name})" if name else text


class RecordingError(HoldError):
    """The recording could not be written: the run holds (exit 4) and says which file and why.

    Attributes:
        path: The recording.
        reason: What the system said.
    """

    def __init__(self, path: Path, reason: str) -> None:
        self.path = path
        self.reason = reason
        super().__init__("recording failed", f"{path}: {reason}", {"path": str(path), "error": reason})


class CheckedFile:
    """A write-only file for the MCAP writer that writes all or raises (see the module docstring).

    Args:
        path: The file, created or emptied.

    Raises:
        OSError: It cannot be opened, or its file system has no room for :data:`RESERVE_BYTES`.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.reserve = path.with_name(f".{path.name}.reserve")
        self._reserve()
        try:
            self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        except OSError:
            self.release_reserve()
            raise
        stat = os.fstat(self._fd)
        self._identity = (stat.st_dev, stat.st_ino)
        self._position = 0
        self.good = 0
        soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
        #: Bytes of data the file takes before it fails as at the process's file-size limit (None: no limit).
        self._data_limit = None if soft == resource.RLIM_INFINITY else max(0, soft - RESERVE_BYTES)
        self._after_failure = False

    def _reserve(self) -> None:
        """Allocate :data:`RESERVE_BYTES` beside the file (blocks, not a sparse file: the room is taken now)."""
        fd = os.open(self.reserve, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        try:
            os.posix_fallocate(fd, 0, RESERVE_BYTES)
        except OSError:
            self.release_reserve()
            raise
        finally:
            os.close(fd)

    def release_reserve(self) -> None:
        """Give the reserved room back to the file system (safe to call twice, or with the folder gone)."""
        with contextlib.suppress(OSError):
            self.reserve.unlink()

    def write(self, data: bytes | bytearray | memoryview) -> int:
        """Write all of ``data`` at the end; the end of a complete write becomes :attr:`good`.

        Raises:
            OSError: The system refused part of it (the file then ends in a torn write until :meth:`rewind`).
        """
        view = memoryview(data)
        if self._data_limit is not None and not self._after_failure and self._position + len(view) > self._data_limit:
            raise OSError(errno.EFBIG, os.strerror(errno.EFBIG), str(self.path))
        while view:
            written = os.write(self._fd, view)
            if written <= 0:  # a regular file never says 0 without an error; do not loop on it
                raise OSError(errno.EIO, os.strerror(errno.EIO), str(self.path))
            view = view[written:]
            self._position += written
        self.good = self._position
        return len(data)

    def tell(self) -> int:
        """Bytes written so far."""
        return self._position

    def flush(self) -> None:
        """Check that the path still names this file (every write is already the system's).

        Raises:
            FileNotFoundError: The file, or its folder, was removed or replaced.
        """
        try:
            stat = os.stat(self.path)
            same = (stat.st_dev, stat.st_ino) == self._identity
        except FileNotFoundError:
            same = False
        if not same:
            raise FileNotFoundError(errno.ENOENT, "the recording file was removed or replaced", str(self.path))

    def rewind(self) -> None:
        """Cut the file back to :attr:`good`, the end of the last complete write (errors ignored)."""
        with contextlib.suppress(OSError):
            os.ftruncate(self._fd, self.good)
            os.lseek(self._fd, self.good, os.SEEK_SET)
            self._position = self.good

    def append(self, data: bytes) -> bool:
        """Add whole records after a failure: True when written, False (and nothing added) when not."""
        self._after_failure = True  # into the room kept below a file-size limit
        self.rewind()
        try:
            self.write(data)
        except OSError:
            self.rewind()
            return False
        return True

    def close(self) -> None:
        """Close the file and give back its reserve (safe to call twice)."""
        self.release_reserve()
        if self._fd >= 0:
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = -1
