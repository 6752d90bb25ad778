"""PyBullet imported without its build-time line.

PyBullet's C module writes ``pybullet build time: ...`` to the process's standard error (file descriptor
2, not Python's ``sys.stderr``) when it is imported. Every command printed it, ``--help`` included, and
every sweep worker printed it again inside the progress bar: noise that reads like a warning. The ``sim``
package imports PyBullet here first, with descriptors 1 and 2 pointed at ``/dev/null`` for the import
only; later ``import pybullet`` statements find it loaded and print nothing. C's stdio buffers are
flushed before the descriptors are restored, so nothing written meanwhile reaches them later.
"""

from __future__ import annotations

import contextlib
import ctypes
import importlib
import os
import sys
from collections.abc import Iterator
from types import ModuleType

__all__ = ["import_quietly", "pybullet"]

#: Standard output and standard error.
_DESCRIPTORS = (1, 2)


@contextlib.contextmanager
def _descriptors_silenced() -> Iterator[None]:
    """Discard what C code writes to stdout and stderr meanwhile (Python's own buffered output goes first)."""
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        saved = [os.dup(fd) for fd in _DESCRIPTORS]
    except OSError:  # a descriptor is closed (a detached process): nothing to keep clean
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            for fd in _DESCRIPTORS:
                os.dup2(null.fileno(), fd)
        yield
    finally:
        ctypes.CDLL(None).fflush(None)
        for fd, copy in zip(_DESCRIPTORS, saved, strict=True):
            os.dup2(copy, fd)
            os.close(copy)


def import_quietly(name: str) -> ModuleType:
    """Import the module ``name`` with whatever its C code prints meanwhile discarded."""
    if name in sys.modules:
        return sys.modules[name]
    with _descriptors_silenced():
        return importlib.import_module(name)


pybullet = import_quietly("pybullet")
