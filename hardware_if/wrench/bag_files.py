"""A rosbag2 bag's storage files, checked within stated bounds before ``rosbags`` opens them.

``rosbags`` decompresses an MCAP chunk whole, to whatever size its data gives (zstd) or without any bound
(lz4), decompresses a bag in rosbag2's ``file`` compression mode into a temporary folder whole, and each
message of the ``message`` mode whole. So before a bag is opened, :func:`check_bag_files` reads its
``metadata.yaml`` (a regular file of at most :data:`MAX_BAG_METADATA_BYTES`), refuses rosbag2's file and
message compression (``ros2 bag convert`` writes an uncompressed copy; the MCAP storage's own chunk
compression, ``--storage-preset-profile zstd_fast`` and the like, is read), and streams every MCAP storage
file through :class:`~hardware_if.recording.reader.McapMessages`, which checks each chunk's size before and
while it is decompressed and counts the records within the recordings' limits
(:mod:`hardware_if.recording.reader`). A ``.db3`` storage file is a regular file within the same size limit.
"""

from __future__ import annotations

from pathlib import Path, PurePath

from hardware_if.recording.reader import MAX_FILE_BYTES, McapMessages, RecordingFileError
from psm_control.inputs import check_regular_file, load_yaml, read_text

__all__ = ["MAX_BAG_METADATA_BYTES", "check_bag_files"]

#: Largest ``metadata.yaml`` of a bag read [bytes]: ``ros2 bag record`` writes a few kilobytes (one entry per
#: topic and storage file).
MAX_BAG_METADATA_BYTES = 1_000_000


def _storage_files(folder: Path, field: str) -> list[Path]:
    """The storage files a bag folder's metadata names, after its compression is checked."""
    metadata = folder / "metadata.yaml"
    document = load_yaml(read_text(metadata, field, MAX_BAG_METADATA_BYTES), field, metadata)
    info = document.get("rosbag2_bagfile_information") if isinstance(document, dict) else None
    names = info.get("relative_file_paths") if isinstance(info, dict) else None
    if not isinstance(info, dict) or not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise RecordingFileError(
            metadata, "a rosbag2 metadata.yaml whose rosbag2_bagfile_information lists relative_file_paths", field=field
        )
    mode = str(info.get("compression_mode") or "none").lower()
    if mode != "none":
        raise RecordingFileError(
            folder,
            f"a bag without rosbag2's {mode} compression (compression_mode: {mode}); its storage files are read "
            "as they are: write an uncompressed copy with ros2 bag convert (the MCAP storage's own chunk "
            "compression is read)",
            field=field,
        )
    return [folder / PurePath(name).name for name in names]


def check_bag_files(path: str | Path, *, field: str = "--from") -> None:
    """Check a bag (a folder with ``metadata.yaml``, or one ``.mcap``/``.db3`` storage file) before it is opened.

    Raises:
        InputFileError: A metadata or storage file that is not a regular file within its limit, rosbag2
            compression, or an MCAP storage file beyond the reader's limits
            (:class:`~hardware_if.recording.reader.RecordingFileError`, which names the chunk or the count).
    """
    path = Path(path)
    for storage in _storage_files(path, field) if path.is_dir() else [path]:
        if storage.suffix.lower() == ".mcap":
            for _ in McapMessages(storage, (), field=field, check_index=True):  # every record checked, none kept
                pass
        else:
            check_regular_file(storage, field, MAX_FILE_BYTES)
