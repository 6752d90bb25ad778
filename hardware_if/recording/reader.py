"""Reading an MCAP file record by record within stated bounds, as a deploy wrote it or as a kill left it.

Every MCAP file a command reads (a deploy's recording for ``replay`` and ``calibrate-wrench --from``, a
``ros2 bag`` MCAP file checked before ``rosbags`` opens it) is streamed through :class:`McapMessages`:
its records are read in file order, one at a time, and refused with a :class:`RecordingFileError`
naming the file, the byte or message and what is allowed as soon as one of the limits below is passed,
so a small file that would decompress to gigabytes or hold millions of messages costs a fraction of a
second and a chunk's worth of memory. A file without its footer (a killed deploy) reads as far as its
last complete record and says so (:attr:`McapMessages.truncated`).

The limits come from what a real recording needs. ``deploy --target sim --record`` of MultiSite measured
about 350 bytes per ``/deploy/measured`` and ``/deploy/command`` message (one each per control tick), 650 per
``/deploy/action``, 500 per ``/scene/transforms`` and 2,800 per ``/scene/task`` (per policy step, 20 Hz on a
dVRK), and 650 bytes per episode in the report. An hour on a dVRK at 100 Hz is so about 0.94 million
messages and 0.6 GB before compression (1.2 million and 0.7 GB in the simulation, which streams its
scene every tick); the limits allow about four such hours.

Why not :class:`mcap.stream_reader.StreamReader`: it decompresses a chunk to whatever size the chunk
claims (zstd) or without any bound (lz4), builds a list of every record in the chunk before yielding the
first (ten million empty messages in one 28 kB chunk took 4.4 GB), and skips records it does not know
without a way to count them. Here each record's length is checked against what is left of the file and
the limits before it is read, a chunk's ``uncompressed_size`` is checked before it is decompressed and the
decompression stops one byte past it, and the chunk's records are parsed one by one. The records'
layouts are MCAP's (``mcap.records``, the specification's opcodes).
"""

from __future__ import annotations

import stat
import struct
from collections.abc import Collection, Iterator
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path

import lz4.frame  # type: ignore[import-untyped]
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Header

from psm_control.errors import InputFileError

__all__ = [
    "MAX_CHUNK_BYTES",
    "MAX_FILE_BYTES",
    "MAX_RECORDS",
    "MAX_UNCOMPRESSED_BYTES",
    "McapMessage",
    "McapMessages",
    "RecordingFileError",
    "read_header",
]

#: Largest record, and largest chunk once decompressed [bytes]. The recorder ends a chunk past 256 KiB, so
#: its chunks hold 256 KiB and one message (the largest, an hour-long run's report, about 1 MB); tools that
#: rewrite MCAP files (the ``mcap`` CLI, ``ros2 bag convert``) write chunks of a few MiB. A chunk is held
#: in memory once while its records are read.
MAX_CHUNK_BYTES = 64 * 1024 * 1024
#: Largest file [bytes], and most bytes decompressed over the whole file: about four hours at 100 Hz
#: (an hour is about 0.6 GB before compression, 0.15 GB as the recorder's zstd chunks keep it).
MAX_FILE_BYTES = MAX_UNCOMPRESSED_BYTES = 4 * 1024**3
#: Most records of any kind (messages, channels, chunks and their indexes): about four hours at 100 Hz
#: (an hour is about 0.94 million messages on a dVRK, 1.2 million in the simulation; the other records
#: add about 2 %). Reading a record costs a few microseconds, so this bounds the time as well.
MAX_RECORDS = 4_000_000

_MAGIC = b"\x89MCAP0\r\n"
_COMPRESSIONS = ("", "zstd", "lz4")
_RECORD_HEAD = struct.Struct("<BQ")  # opcode, length of what follows
_MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time [ns], publish time [ns]
_CHANNEL_ID = struct.Struct("<H")  # a message's first field
_MESSAGE = int(Opcode.MESSAGE)


class RecordingFileError(InputFileError):
    """An MCAP file (a recording, a bag) that cannot be read as one: the file, where in it, what is allowed.

    Attributes:
        path: The file, as given.
        allowed: What is allowed, and what the file has there.
        topic: The channel of the offending message, or None.
        index: The message's index on its channel (from 0), or None.
        key: The offending field of the message, or None.
    """

    def __init__(
        self,
        path: object,
        allowed: str,
        *,
        field: str = "recording",
        topic: str | None = None,
        index: int | None = None,
        key: str | None = None,
    ) -> None:
        self.topic = topic
        self.index = index
        self.key = key
        super().__init__(field, path, allowed)


@dataclass(frozen=True)
class McapMessage:
    """One message: its channel's topic, its index on that channel (from 0), log time [ns] and raw data."""

    topic: str
    index: int
    log_time_ns: int
    data: bytes


def _check_file(path: Path, field: str) -> int:
    """The size of a regular file of at most :data:`MAX_FILE_BYTES`, checked before it is opened."""
    try:
        info = path.stat()
    except OSError as e:
        raise RecordingFileError(path, f"an existing, readable MCAP file ({e.strerror or e})", field=field) from e
    if not stat.S_ISREG(info.st_mode):
        raise RecordingFileError(path, "a regular MCAP file (not a folder, device or FIFO)", field=field)
    if info.st_size > MAX_FILE_BYTES:
        raise RecordingFileError(
            path, f"an MCAP file of at most {MAX_FILE_BYTES} bytes (it has {info.st_size})", field=field
        )
    return info.st_size


def _decompress(chunk: Chunk) -> bytes:
    """The chunk's records, at most ``uncompressed_size`` bytes (one more byte is read to see a lie)."""
    wanted = chunk.uncompressed_size + 1
    if chunk.compression == "":
        return chunk.data[:wanted]
    if chunk.compression == "lz4":
        return bytes(lz4.frame.LZ4FrameDecompressor().decompress(chunk.data, max_length=wanted))
    reader = zstandard.ZstdDecompressor().stream_reader(chunk.data, read_across_frames=True)
    parts, got = [], 0
    while got < wanted:
        part = reader.read(wanted - got)
        if not part:
            break
        parts.append(part)
        got += len(part)
    return b"".join(parts)


class McapMessages:
    """The messages of an MCAP file on the given topics, read in file order within the module's limits.

    Iterate once for :class:`McapMessage` items; :attr:`truncated` and :attr:`records` hold after the end.
    Messages on other topics (the 3-D scene, another arm) are counted and skipped, not decoded.

    Args:
        path: The file.
        topics: The topics whose messages are wanted (None: every topic).
        field: How the command names the file in errors (``recording``, ``--from``).
        check_index: Also check that the summary a seeking reader follows (the footer at the file's end, its
            chunk indexes) points at the records read here, so that reader decompresses only the chunks
            checked here (for ``rosbags``, which reads a bag through its index).

    Raises:
        RecordingFileError: (while iterating) Not a regular file within :data:`MAX_FILE_BYTES`, not MCAP, a
            malformed record, a compression other than none, zstd or lz4, or a limit passed.
    """

    def __init__(
        self,
        path: str | Path,
        topics: Collection[str] | None = None,
        *,
        field: str = "recording",
        check_index: bool = False,
    ) -> None:
        self.path = Path(path)
        self.check_index = check_index
        self._chunk_at: dict[int, tuple[str, int, int]] = {}  # checked chunks: offset -> compression and sizes
        self._summary_at = 0  # where the summary section starts (the record after the data end), 0: none yet
        self._summary_offsets_at = 0  # the first summary offset record
        self.topics = None if topics is None else frozenset(topics)
        self.field = field
        #: True when the file ends without its footer (the writer did not finish: a crash or a kill).
        self.truncated = False
        #: Records read (messages, channels, chunks, indexes).
        self.records = 0
        self._uncompressed = 0
        self._channels: dict[int, str | None] = {}
        self._counts: dict[str, int] = {}

    def _error(self, allowed: str) -> RecordingFileError:
        return RecordingFileError(self.path, allowed, field=self.field)

    def _count(self) -> None:
        self.records += 1
        if self.records > MAX_RECORDS:
            raise self._error(
                f"an MCAP file of at most {MAX_RECORDS} records (about four hours at 100 Hz); this one has more"
            )

    def __iter__(self) -> Iterator[McapMessage]:
        size = _check_file(self.path, self.field)
        try:
            with self.path.open("rb") as f:
                yield from self._records(f, size)
                if self.check_index and self.truncated and size >= 2 * len(_MAGIC):
                    f.seek(size - len(_MAGIC))
                    if f.read(len(_MAGIC)) == _MAGIC:  # a footer at the end that a seeking reader would follow
                        raise self._error("an MCAP file whose records reach its footer; they end before it")
        except OSError as e:
            raise self._error(f"a readable MCAP file ({e.strerror or e})") from e

    def _records(self, f: object, size: int) -> Iterator[McapMessage]:
        read = f.read  # type: ignore[attr-defined]
        if read(len(_MAGIC)) != _MAGIC:
            raise self._error("an MCAP file (it does not start with MCAP's magic bytes)")
        offset = len(_MAGIC)
        while True:
            if size - offset < _RECORD_HEAD.size:  # a clean end without a footer, or a torn record header
                self.truncated = True
                return
            opcode, length = _RECORD_HEAD.unpack(read(_RECORD_HEAD.size))
            start = offset
            offset += _RECORD_HEAD.size
            if length > MAX_CHUNK_BYTES:
                raise self._error(
                    f"records of at most {MAX_CHUNK_BYTES} bytes; the record at byte {start} claims {length}"
                )
            if length > size - offset:  # the record the writer was writing when it was killed
                self.truncated = True
                return
            body = read(length)
            if len(body) < length:  # the file shrank while it was read
                self.truncated = True
                return
            offset += length
            self._count()
            if start == len(_MAGIC) and opcode != Opcode.HEADER:
                raise self._error(f"an MCAP file that starts with a header record (opcode {opcode:#04x} found)")
            if opcode == Opcode.FOOTER:
                if self.check_index:
                    self._check_footer(body, start, offset, size, read(len(_MAGIC)))
                return
            if opcode == Opcode.CHUNK:
                yield from self._chunk(body, start)
            elif self.check_index and opcode in (Opcode.DATA_END, Opcode.CHUNK_INDEX, Opcode.SUMMARY_OFFSET):
                self._check_summary_record(opcode, body, start, offset)
            else:
                yield from self._record(opcode, body, start)

    def _chunk(self, body: bytes, start: int) -> Iterator[McapMessage]:
        try:
            chunk = Chunk.read(ReadDataStream(BytesIO(body)))
        except (McapError, struct.error, UnicodeDecodeError, ValueError) as e:
            raise self._error(f"well-formed records; the chunk at byte {start} is not ({e})") from e
        if chunk.compression not in _COMPRESSIONS:
            raise self._error(
                f"chunks compressed with zstd, lz4 or not at all; the chunk at byte {start} uses {chunk.compression!r}"
            )
        if chunk.uncompressed_size > MAX_CHUNK_BYTES:
            raise self._error(
                f"chunks of at most {MAX_CHUNK_BYTES} bytes decompressed; the chunk at byte {start} "
                f"holds {chunk.uncompressed_size}"
            )
        if self._uncompressed + chunk.uncompressed_size > MAX_UNCOMPRESSED_BYTES:
            raise self._error(
                f"at most {MAX_UNCOMPRESSED_BYTES} bytes decompressed in all (about four hours at 100 Hz); "
                f"the chunk at byte {start} passes that"
            )
        try:
            data = _decompress(chunk)
        except (zstandard.ZstdError, RuntimeError, ValueError, OSError) as e:
            raise self._error(f"chunks that decompress; the chunk at byte {start} does not ({e})") from e
        if len(data) != chunk.uncompressed_size:
            held = "more" if len(data) > chunk.uncompressed_size else str(len(data))
            raise self._error(
                f"chunks that decompress to the size they state; the chunk at byte {start} states "
                f"{chunk.uncompressed_size} bytes and holds {held}"
            )
        self._uncompressed += len(data)
        if self.check_index:
            self._chunk_at[start] = (chunk.compression, len(chunk.data), chunk.uncompressed_size)
        view = memoryview(data)
        end = len(data)
        offset = 0
        topic_of = self._channels.get
        while offset < end:
            if end - offset < _RECORD_HEAD.size:
                raise self._error(f"whole records in chunks; the chunk at byte {start} ends inside one")
            opcode, length = _RECORD_HEAD.unpack_from(data, offset)
            offset += _RECORD_HEAD.size
            if length > end - offset:
                raise self._error(f"whole records in chunks; a record in the chunk at byte {start} runs past its end")
            self._count()
            # A message on a topic not asked for (most of a long recording's: the scene's, another arm's) is
            # skipped here as _record skips it, without a call per record: four times faster over such records.
            if (
                opcode == _MESSAGE
                and length >= _MESSAGE_HEAD.size
                and topic_of(_CHANNEL_ID.unpack_from(data, offset)[0]) is None
            ):
                offset += length
                continue
            yield from self._record(opcode, view[offset : offset + length], start)
            offset += length

    def _check_summary_record(self, opcode: int, body: bytes, start: int, end: int) -> None:
        """Where the summary starts, and that each chunk index names a chunk checked here, as it was."""
        if opcode == Opcode.DATA_END:
            self._summary_at = end
        elif opcode == Opcode.SUMMARY_OFFSET:
            self._summary_offsets_at = self._summary_offsets_at or start
        else:
            try:  # ChunkIndex's fields by hand: its map of message index offsets is skipped, not built
                chunk_at = struct.unpack_from("<Q", body, 16)[0]
                (skip,) = struct.unpack_from("<I", body, 32)
                (length,) = struct.unpack_from("<I", body, 44 + skip)
                compression = bytes(body[48 + skip : 48 + skip + length]).decode()
                compressed, uncompressed = struct.unpack_from("<QQ", body, 48 + skip + length)
            except (struct.error, UnicodeDecodeError) as e:
                raise self._error(f"well-formed records; the chunk index at byte {start} is not ({e})") from e
            if self._chunk_at.get(chunk_at) != (compression, compressed, uncompressed):
                raise self._error(
                    f"an index that points at the file's own chunks; the chunk index at byte {start} names a "
                    f"chunk at byte {chunk_at} that is not there as it says"
                )

    def _check_footer(self, body: bytes, start: int, end: int, size: int, magic: bytes) -> None:
        """The footer a seeking reader finds at the file's end is this one, and points at this summary."""
        try:
            summary_at, offsets_at = struct.unpack_from("<QQ", body)
        except struct.error as e:
            raise self._error(f"well-formed records; the footer at byte {start} is not ({e})") from e
        if end + len(_MAGIC) != size or magic != _MAGIC:
            raise self._error(
                f"an MCAP file that ends with its footer; {size - end} bytes follow the one at byte {start}"
            )
        if summary_at not in (0, self._summary_at) or offsets_at not in (0, self._summary_offsets_at):
            raise self._error(
                f"a footer that points at the file's own summary; the one at byte {start} points at bytes "
                f"{summary_at} and {offsets_at}"
            )

    def _record(self, opcode: int, body: bytes | memoryview, start: int) -> Iterator[McapMessage]:
        if opcode == Opcode.MESSAGE:
            if len(body) < _MESSAGE_HEAD.size:
                raise self._error(f"well-formed messages; the one in the record at byte {start} is short")
            channel, _, log_time_ns, _ = _MESSAGE_HEAD.unpack_from(body)
            topic = self._channels.get(channel)
            if topic is None:
                return  # a topic not asked for (or a channel never declared, which MCAP readers skip too)
            index = self._counts.get(topic, 0)
            self._counts[topic] = index + 1
            yield McapMessage(topic, index, log_time_ns, bytes(body[_MESSAGE_HEAD.size :]))
        elif opcode == Opcode.CHANNEL:
            try:
                channel = Channel.read(ReadDataStream(BytesIO(body)))
            except (McapError, struct.error, UnicodeDecodeError, ValueError) as e:
                raise self._error(f"well-formed records; a channel in the record at byte {start} is not ({e})") from e
            wanted = self.topics is None or channel.topic in self.topics
            self._channels[channel.id] = channel.topic if wanted else None  # ids are 16 bits: at most 65,536


def read_header(path: str | Path, *, field: str = "recording") -> Header:
    """The header record of an MCAP file (its profile and the library that wrote it).

    Raises:
        RecordingFileError: Not a regular MCAP file within :data:`MAX_FILE_BYTES`, or no header.
    """
    path = Path(path)
    size = _check_file(path, field)
    try:
        with path.open("rb") as f:
            head = f.read(len(_MAGIC) + _RECORD_HEAD.size)
            opcode, length = _RECORD_HEAD.unpack_from(head, len(_MAGIC)) if head.startswith(_MAGIC) else (0, 0)
            body = f.read(length) if opcode == Opcode.HEADER and length <= min(MAX_CHUNK_BYTES, size) else b""
    except (OSError, struct.error) as e:
        raise RecordingFileError(path, f"a readable MCAP file ({e})", field=field) from e
    if not body:
        raise RecordingFileError(path, "an MCAP file that starts with MCAP's magic bytes and a header", field=field)
    try:
        return Header.read(ReadDataStream(BytesIO(body)))
    except (McapError, struct.error, UnicodeDecodeError, ValueError) as e:
        raise RecordingFileError(path, f"an MCAP file with a readable header ({e})", field=field) from e
