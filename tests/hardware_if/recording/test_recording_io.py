"""A recording that cannot be written: a real full file system, a write error, a vanished folder.

The full case uses a real 1 MiB tmpfs (mounting needs root; elsewhere it is skipped and says why), the
write error a real file-size limit (EFBIG). A file system cannot be remounted read-only under a file open
for writing (the kernel refuses, EBUSY), so that case is the write error's. Each must raise the hold
``recording failed: <path>: <os error>`` once, keep the file readable as far as it got, and still take
the hold when the file system has room for it.
"""

from __future__ import annotations

import contextlib
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from hardware_if.recording.checked_file import RecordingError
from hardware_if.recording.recorder import Recorder, read_recording
from tissue_retract.fault_setups import small_filesystem

PAYLOAD = {"q": [0.25] * 6, "force_n": [0.0, 0.0, 0.5], "text": "x" * 300}  # a measurement's fields, about as long
#: A tmpfs gives a file room a page at a time.
_PAGE_BYTES = 4096


@pytest.fixture
def tiny(tmp_path: Path) -> Iterator[Path]:
    """A 1 MiB tmpfs."""
    try:
        with small_filesystem(tmp_path / "tiny", 1024 * 1024) as folder:
            yield folder
    except Exception as e:  # not root: the mount is refused
        pytest.skip(f"needs a tmpfs mount: {e}")


def _fill(recorder: Recorder) -> RecordingError:
    for _ in range(100_000):
        try:
            recorder.write("/deploy/measured", PAYLOAD)
        except RecordingError as e:
            return e
    raise AssertionError("the file system never filled")


def test_full_file_system_is_a_hold_naming_the_file(tiny: Path) -> None:
    """ENOSPC: the hold names the file and the error; the torn end is cut and the hold still recorded."""
    path = tiny / "run.mcap"
    recorder = Recorder(path)
    error = _fill(recorder)
    assert str(error) == f"recording failed: {path}: No space left on device (ENOSPC)"
    assert error.kind == "recording failed" and error.data["path"] == str(path)
    recorder.write("/deploy/event", {"kind": "hold", "text": str(error)})
    recorder.close()
    recording = read_recording(path)
    assert recording.truncated
    measured = [m for m in recording if m[0] == "/deploy/measured"]
    assert len(measured) > 1000  # everything up to the last complete chunk
    # The hold is taken even when cutting the torn end frees nothing (a tear within the file's last page):
    # the room reserved when the file opened takes it.
    assert recording.messages[-1][2] == {"kind": "hold", "text": str(error)}
    assert not (tiny / ".run.mcap.reserve").exists()


def test_full_file_system_after_a_tear_within_a_page_still_takes_the_hold(tiny: Path) -> None:
    """The worst case for the hold: the disk fills with the file's last page partly used and nothing to free.

    The file system is filled, outside the recording, to leave less than a page; the next chunk tears
    within that page, so cutting it off gives nothing back: only the reserve makes room for the hold.
    """
    path = tiny / "run.mcap"
    recorder = Recorder(path)
    for _ in range(1000):  # small flushed chunks until the file's last page has no room for a hold record
        recorder.write("/deploy/measured", PAYLOAD)
        recorder.flush()
        if path.stat().st_size % _PAGE_BYTES > _PAGE_BYTES - 200:
            break
    assert path.stat().st_size % _PAGE_BYTES > _PAGE_BYTES - 200
    with (tiny / "other").open("wb") as other, contextlib.suppress(OSError):
        other.write(b"\0" * (2 * 1024 * 1024))  # everything the file system has left
    error = _fill(recorder)
    assert "No space left on device (ENOSPC)" in str(error)
    recorder.write("/deploy/event", {"kind": "hold", "text": str(error)})
    recorder.close()
    assert read_recording(path).messages[-1][2] == {"kind": "hold", "text": str(error)}


def test_a_disk_without_room_for_the_reserve_holds_at_the_start(tiny: Path) -> None:
    """A disk already full: the recording refuses to open (a hold before anything moves), naming the file."""
    with (tiny / "other").open("wb") as other, contextlib.suppress(OSError):
        other.write(b"\0" * (2 * 1024 * 1024))
    with pytest.raises(RecordingError, match=r"recording failed: .*run.mcap: No space left on device \(ENOSPC\)"):
        Recorder(tiny / "run.mcap")
    assert not (tiny / "run.mcap").exists() and not (tiny / ".run.mcap.reserve").exists()


def test_file_size_limit_is_a_hold(tmp_path: Path) -> None:
    """Another write error (EFBIG past the process's file-size limit, in a child): the same hold, file kept."""
    path = tmp_path / "run.mcap"
    script = f"""
import resource, signal
from hardware_if.recording.recorder import Recorder
from hardware_if.recording.checked_file import RecordingError
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, (300_000, 300_000))
recorder = Recorder({str(path)!r})
try:
    for _ in range(100_000):
        recorder.write("/deploy/measured", {PAYLOAD!r})
except RecordingError as e:
    print(e)
    recorder.write("/deploy/event", {{"kind": "hold", "text": str(e)}})
recorder.close()
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.stdout.strip() == f"recording failed: {path}: File too large (EFBIG)", done.stderr
    recording = read_recording(path)
    assert recording.truncated and recording.messages[-1][2]["kind"] == "hold"


def test_the_hold_fits_below_a_file_size_limit_wherever_the_last_write_ended(tmp_path: Path) -> None:
    """A write that ended 100 bytes short of the file-size limit still leaves room for the hold after it."""
    path = tmp_path / "run.bin"
    script = f"""
import resource, signal
from hardware_if.recording.checked_file import CheckedFile
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
limit = 300_000
resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
checked = CheckedFile(__import__("pathlib").Path({str(path)!r}))
try:
    checked.write(bytes(limit - 100))
    checked.write(bytes(10_000))
except OSError as e:
    print(e.errno == __import__("errno").EFBIG, checked.append(bytes(1000)))
checked.close()
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.stdout.split() == ["True", "True"], done.stdout + done.stderr


def test_vanished_folder_is_a_hold(tmp_path: Path) -> None:
    """The recording's folder removed mid-run: the next flush holds instead of writing into nowhere."""
    path = tmp_path / "runs" / "run.mcap"
    recorder = Recorder(path)
    recorder.write("/deploy/measured", PAYLOAD)
    shutil.rmtree(path.parent)
    with pytest.raises(RecordingError, match=r"the recording file was removed or replaced \(ENOENT\)"):
        recorder.flush()
    recorder.close()  # nothing more to say, and no second error


def test_unwritable_start_is_a_hold(tmp_path: Path) -> None:
    """A recording that cannot even be created is the same hold, before anything is commanded."""
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(RecordingError, match=r"recording failed: .*run.mcap: File exists \(EEXIST\)"):
        Recorder(blocker / "run.mcap")


def test_deploy_onto_a_full_file_system_holds_with_exit_4(tiny: Path) -> None:
    """``deploy --record`` on a 1 MiB tmpfs: ``HOLD: recording failed: <path>: ...``, exit 4, hold in the file."""
    path = tiny / "run.mcap"
    command = [sys.executable, "-m", "tissue_retract", "deploy", "--policy", "scripted", "--target", "sim"]
    # A generous policy budget: on a loaded machine a slow step would hold first, for another reason.
    done = subprocess.run(
        [*command, "--episodes", "40", "--record", str(path), "--policy-budget", "600"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 4, done.stdout + done.stderr
    assert f"HOLD: recording failed: {path}: No space left on device (ENOSPC)" in done.stdout
    assert "Traceback" not in done.stdout + done.stderr
    replay = subprocess.run(
        [sys.executable, "-m", "tissue_retract", "replay", str(path)], capture_output=True, text=True, timeout=120
    )
    assert replay.returncode == 0, replay.stderr
    assert "truncated recording" in replay.stdout and "hold: recording failed" in replay.stdout, replay.stdout
