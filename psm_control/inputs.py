"""Reading what users hand in: bounded, regular, UTF-8 files, and YAML without duplicate keys or aliases.

Every file a user names (a safety configuration, demonstrations, a checkpoint) goes through here before
it is parsed, so that a device (``/dev/zero``), a FIFO, a huge file, a UTF-16 file or a YAML alias bomb
gets a :class:`~psm_control.errors.InputFileError` naming the file and what is allowed, instead of a hang,
unbounded memory or a traceback. Output paths are checked here too, before any work starts: their
folder is created, and an output never replaces a device, a FIFO, a folder, one of the run's inputs, or an
existing recording without the user's word (:func:`check_output_path`).
"""

from __future__ import annotations

import contextlib
import os
import stat
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import yaml

from psm_control.errors import ConfigurationError, InputFileError, OutputFileError

__all__ = [
    "MAX_CONFIG_BYTES",
    "check_output_path",
    "check_regular_file",
    "given_as",
    "load_yaml",
    "read_text",
]

#: Largest configuration file read [bytes]; the full SafetyConfig is about 1 kB.
MAX_CONFIG_BYTES = 1_000_000


@contextlib.contextmanager
def given_as(field: str, default: str) -> Iterator[None]:
    """Name the refusals of a reader that calls its file ``default`` (``--from`` for the joint logs,
    ``--wrench-calibration`` for calibrations) after the option the file was given as, ``field``."""
    try:
        yield
    except ConfigurationError as e:
        if e.field != default:
            raise
        raise e.for_field(field) from e


def check_regular_file(path: str | Path, field: str, max_bytes: int) -> Path:
    """The path of an existing regular file of at most ``max_bytes``, checked without opening it.

    ``stat`` first: opening a FIFO blocks and a device such as ``/dev/zero`` never ends.

    Raises:
        InputFileError: Missing, not a regular file, or too large.
    """
    path = Path(path)
    try:
        info = path.stat()
    except OSError as e:
        raise InputFileError(field, path, f"an existing, readable file ({e.strerror or e})") from e
    if not stat.S_ISREG(info.st_mode):
        raise InputFileError(field, path, "a regular file (not a folder, device or FIFO)")
    if info.st_size > max_bytes:
        raise InputFileError(field, path, f"a file of at most {max_bytes} bytes (it has {info.st_size})")
    return path


def read_text(path: str | Path, field: str, max_bytes: int = MAX_CONFIG_BYTES) -> str:
    """The UTF-8 text of a regular file of at most ``max_bytes`` (a UTF-8 byte-order mark is allowed).

    Raises:
        InputFileError: Not a regular file, too large, or not UTF-8 (UTF-16/32 named when recognised).
    """
    path = check_regular_file(path, field, max_bytes)
    try:
        with path.open("rb") as handle:
            raw = handle.read(max_bytes + 1)
    except OSError as e:
        raise InputFileError(field, path, f"a readable file ({e.strerror or e})") from e
    if len(raw) > max_bytes:  # grew after the stat
        raise InputFileError(field, path, f"a file of at most {max_bytes} bytes")
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise InputFileError(field, path, "UTF-8 text (this file is UTF-16: save it as UTF-8)")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise InputFileError(field, path, f"UTF-8 text (byte {e.start} is not UTF-8)") from e


class _StrictLoader(yaml.SafeLoader):
    """A safe YAML loader that refuses aliases (no alias bombs) and duplicate mapping keys."""

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise yaml.constructor.ConstructorError(
                None, None, f"alias *{event.anchor} found: aliases are not allowed", event.start_mark
            )
        return super().compose_node(parent, index)

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r}: each setting at most once", key_node.start_mark
                )
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def load_yaml(text: str, field: str, path: str | Path) -> Any:
    """Parse YAML with the safe loader, refusing aliases and duplicate keys.

    Raises:
        InputFileError: Invalid YAML, an alias or a duplicate key (with its line).
    """
    try:
        return yaml.load(text, Loader=_StrictLoader)
    except yaml.YAMLError as e:
        raise InputFileError(field, path, f"valid YAML without aliases or duplicate keys ({e})") from e
    except RecursionError as e:
        raise InputFileError(field, path, "YAML nested at most a few hundred levels") from e


def check_output_path(
    path: str | Path,
    field: str,
    inputs: Iterable[str | Path | None] = (),
    *,
    existing: str | None = None,
) -> Path:
    """Check an output path before any work starts, and make its folder.

    Refused: an existing path that is not a regular file (a folder, a device such as ``/dev/null``, a FIFO,
    a socket, or a symlink to one), one of the run's ``inputs`` (the same file by path or inode), and, when
    ``existing`` says what is allowed instead, any existing path (a recording the user did not ask to
    replace). An existing regular result file is otherwise replaced when the command is done
    (:func:`psm_control.outputs.write_atomic`).

    Args:
        path: The output, as given.
        field: The option that named it (``--json``).
        inputs: The run's input files (None entries are skipped).
        existing: What is allowed when ``path`` exists, e.g. ``"a new file (--force replaces it)"``; None
            lets an existing regular file be replaced.

    Raises:
        OutputFileError: Naming ``field``, the path and what is allowed.
    """
    from psm_control.outputs import special_file_kind  # the writer's own test, re-run before its rename

    path = Path(path)
    kind = special_file_kind(path)
    if kind is not None:
        allowed = "a new path" if existing is not None else "a new or regular file"
        raise OutputFileError(field, str(path), f"{allowed}, not a folder, device, FIFO or socket (this is a {kind})")
    for given in inputs:
        if given is None:
            continue
        source = Path(given)
        try:
            same = source.exists() and path.exists() and os.path.samefile(source, path)
        except OSError:
            same = False
        if same or path.resolve() == source.resolve():
            raise OutputFileError(field, str(path), f"a path other than the input {str(given)!r}")
    if existing is not None and os.path.lexists(path):
        raise OutputFileError(field, str(path), f"{existing} (this file exists)")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputFileError(field, str(path), f"a path whose folder can be created ({e.strerror or e})") from e
    if not os.access(path.parent, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise OutputFileError(field, str(path), "a writable path")
    return path
