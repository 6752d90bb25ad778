"""Writing what a command hands back: whole files, in place of regular files only, named on failure.

Every result file (a ``--json`` report, a calibration, a figure, a demonstration file) is written here:
into a temporary file beside the target (``.NAME.XXXX.tmp<suffix>``), synced to the disk, and renamed over
the target. A crash leaves the old file or the new one, never half of one. Right before the rename the
target is checked again: a device, a FIFO, a socket or a folder that appeared there since the command's
first check (:func:`psm_control.inputs.check_output_path`) is refused, not replaced by a regular file.

A write the system refuses (``ENOSPC`` a full disk, ``EFBIG`` a file larger than the process may write,
``EDQUOT`` a quota, ``EIO``) removes the temporary file, leaves the target as it was and raises
:class:`~psm_control.errors.OutputWriteError` naming the path and the system's reason.

Recordings are not written here: they are written as they go, so that a crash loses seconds, not the run.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path

from psm_control.errors import OutputFileError, OutputWriteError

__all__ = ["atomic_path", "describe_os_error", "special_file_kind", "write_atomic"]

#: Names of the kinds of files an output never replaces, by ``stat`` type test.
_KINDS = (
    (stat.S_ISDIR, "folder"),
    (stat.S_ISCHR, "character device"),
    (stat.S_ISBLK, "block device"),
    (stat.S_ISFIFO, "FIFO"),
    (stat.S_ISSOCK, "socket"),
)


def describe_os_error(error: OSError) -> str:
    """``No space left on device (ENOSPC)``: the system's words and the error's name."""
    name = errno.errorcode.get(error.errno or 0, "")
    text = error.strerror or str(error)
    return f"{text} ({name})" if name else text


def special_file_kind(path: str | Path) -> str | None:
    """What ``path`` is when it exists and is not a regular file (``"FIFO"``, ``"symlink to a folder"``), else None.

    A symlink is followed (a write through it would reach its target); a dangling symlink is None, as a new
    path: the rename replaces the link, not what it pointed to.
    """
    path = Path(path)
    try:
        info = path.stat()
    except (FileNotFoundError, NotADirectoryError):  # a new path (a folder that is a file fails when made)
        return None
    except OSError as e:  # a loop of symlinks, a path through a file
        return f"path that cannot be followed ({describe_os_error(e)})"
    if stat.S_ISREG(info.st_mode):
        return None
    kind = next((name for test, name in _KINDS if test(info.st_mode)), "special file")
    return f"symlink to a {kind}" if path.is_symlink() else kind


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: str | Path, field: str = "output") -> Iterator[Path]:
    """A temporary path beside ``path`` to write by name; renamed over ``path`` when the block ends.

    For writers that take a file name and pick the format from its suffix (matplotlib, imageio, numpy):
    the temporary name ends with the target's suffix. The file is synced before the rename.

    Args:
        path: The target; its folder must exist.
        field: The option that named it, for the errors.

    Raises:
        OutputFileError: The target became a device, FIFO, socket or folder before the rename.
        OutputWriteError: Writing, syncing or renaming failed (the target is left as it was).
    """
    path = Path(path)
    try:
        fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=f".tmp{path.suffix}")
    except OSError as e:
        raise OutputWriteError(field, path, describe_os_error(e)) from e
    os.close(fd)
    temporary = Path(name)
    try:
        yield temporary
        os.chmod(temporary, 0o666 & ~_umask())  # mkstemp's 0600 would make every result private
        fd = os.open(temporary, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        kind = special_file_kind(path)
        if kind is not None:
            raise OutputFileError(field, path, f"a regular file or a new path (this is a {kind})")
        os.replace(temporary, path)
    except OSError as e:
        raise OutputWriteError(field, path, describe_os_error(e)) from e
    finally:
        with contextlib.suppress(OSError):
            temporary.unlink()


def write_atomic(path: str | Path, data: str | bytes, field: str = "output") -> Path:
    """Write ``data`` (text as UTF-8) to ``path`` whole, or raise and leave ``path`` as it was.

    Raises:
        OutputFileError: The target became a device, FIFO, socket or folder before the rename.
        OutputWriteError: The system refused the write (full disk, file-size limit, quota), naming the path.
    """
    raw = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    path = Path(path)
    with atomic_path(path, field) as temporary, temporary.open("wb") as handle:
        handle.write(raw)
        handle.flush()
    return path
