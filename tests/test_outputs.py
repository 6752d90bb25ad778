"""The result writer and the output check: whole files or none, never a device, a full disk named by its path.

A full disk is the real one a process meets: a child process with a small ``RLIMIT_FSIZE`` (and SIGXFSZ
ignored, as Python does anyway), where every write past the limit fails with ``EFBIG``, as a full disk fails
with ``ENOSPC``. Nothing is monkeypatched.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from psm_control.errors import OutputFileError
from psm_control.inputs import check_output_path
from psm_control.outputs import atomic_path, special_file_kind, write_atomic

#: Runs its argument with the process's file-size limit at ``LIMIT`` bytes: writes past it fail with EFBIG.
_LIMITED = textwrap.dedent(
    """
    import resource, signal, sys
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    limit = int(sys.argv[1])
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, resource.RLIM_INFINITY))
    exec(sys.argv[2])
    """
)


def _limited(limit: int, code: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", _LIMITED, str(limit), textwrap.dedent(code)],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
        cwd=cwd,
    )


def test_a_write_past_the_disk_names_the_path_and_leaves_no_file(tmp_path: Path) -> None:
    """A write the system refuses raises naming the path and the reason; no new, empty or partial file is left."""
    code = """
        from psm_control.errors import OutputWriteError
        from psm_control.outputs import write_atomic
        for name in ("new.json", "old.json"):
            try:
                write_atomic(name, "x" * 100_000, "--json")
            except OutputWriteError as e:
                print(e)
    """
    (tmp_path / "old.json").write_text("the earlier result\n")
    done = _limited(4096, code, tmp_path)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines == [
        f"could not write --json {name!r}: File too large (EFBIG); nothing was written there"
        for name in ("new.json", "old.json")
    ]
    assert sorted(os.listdir(tmp_path)) == ["old.json"]
    assert (tmp_path / "old.json").read_text() == "the earlier result\n"


def test_the_target_is_checked_again_before_the_rename(tmp_path: Path) -> None:
    """A FIFO that appears at the target while it is written is refused, not replaced; no temporary file is left."""
    target = tmp_path / "out.json"

    def write_while_a_fifo_appears() -> None:
        with atomic_path(target, "--json") as temporary:
            temporary.write_text("{}\n")
            os.mkfifo(target)

    with pytest.raises(OutputFileError, match="FIFO"):
        write_while_a_fifo_appears()
    assert special_file_kind(target) == "FIFO"
    assert os.listdir(tmp_path) == ["out.json"]


def test_a_result_is_written_whole_with_the_usual_permissions(tmp_path: Path) -> None:
    """write_atomic replaces a regular file with the new content, readable as any file the user makes."""
    target = tmp_path / "out.json"
    target.write_text("old\n")
    write_atomic(target, "new\n")
    assert target.read_text() == "new\n"
    assert target.stat().st_mode & 0o777 == 0o666 & ~_umask()
    assert os.listdir(tmp_path) == ["out.json"]


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def test_check_output_path_refuses_by_kind_input_and_recording(tmp_path: Path) -> None:
    """Devices, FIFOs, folders, links to them, an input (also by a hard link) and an existing recording: refused."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    link = tmp_path / "link.json"
    link.symlink_to(fifo)
    source = tmp_path / "input.yaml"
    source.write_text("a: 1\n")
    hard = tmp_path / "hard.json"
    os.link(source, hard)
    cases = {
        "/dev/null": "character device",
        str(fifo): "this is a FIFO",
        str(link): "symlink to a FIFO",
        str(tmp_path): "this is a folder",
        str(hard): "other than the input",
    }
    for path, words in cases.items():
        with pytest.raises(OutputFileError, match=words):
            check_output_path(path, "--json", (source,))
    kept = tmp_path / "run.mcap"
    kept.write_bytes(b"earlier\n")
    with pytest.raises(OutputFileError, match="--force"):
        check_output_path(kept, "--record", existing="a new file (--force replaces it)")
    assert check_output_path(kept, "--record") == kept  # with --force: replaced
    dangling = tmp_path / "dangling.json"
    dangling.symlink_to(tmp_path / "nowhere")
    assert check_output_path(dangling, "--json") == dangling  # the rename replaces the link, not its target
