"""Hostile recordings through the real command line: a named error, no traceback, bounded memory, nothing written.

Each row of :data:`ROWS` builds one bad MCAP file (a deploy recording with a malformed message, a
decompression or record-count bomb, a rosbag2 bag the reader must not open) and runs the commands that read
it (``replay FILE``, ``replay FILE --plot OUT.png``, ``calibrate-wrench --from FILE --out F.json``) in a fresh
interpreter whose address space is limited to :data:`MEMORY_LIMIT_BYTES`, so a reader that decompresses or
keeps what it should not fails the test. Each must exit non-zero, name the file and say what is allowed (the
row's words), print no Python traceback and write no output. A new reader of recordings is covered by adding
its command to :data:`COMMANDS`; a new way to break a file, by adding a row.
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path
from typing import Any

import lz4.frame  # type: ignore[import-untyped]
import pytest
import zstandard
from mcap.data_stream import ReadDataStream, RecordBuilder
from mcap.records import Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Message, Schema
from mcap.writer import Writer

#: The children's address space [bytes]: ``replay --plot`` of a real recording runs in less than 1 GiB.
MEMORY_LIMIT_BYTES = 2 * 1024**3
#: The reader's limits (:mod:`hardware_if.recording.reader`), written out so the rows build the same files
#: whichever version of the reader is installed.
MAX_CHUNK_BYTES = 64 * 1024 * 1024
MAX_RECORDS = 4_000_000
_MAGIC = b"\x89MCAP0\r\n"
_TOPICS = ("/deploy/meta", "/deploy/measured", "/deploy/command", "/deploy/action", "/deploy/event", "/deploy/report")

Messages = list[tuple[str, Any]]


def _ticks(count: int) -> Messages:
    """A free-space dVRK deploy's ticks: measurements with efforts, and commands."""
    out: Messages = []
    for k in range(count):
        q = [0.1 * (k % 7) / 7, 0.05, 0.12, 0.0, 0.01 * (k % 5), 0.0]
        out.append(
            ("/deploy/measured", {"q": q, "qd": [0.1] * 6, "jaw": 0.6, "force_n": [0.0, 0.0, 0.1], "stamp_s": 0.01 * k,
                                  "effort": [0.01 * (k % 3), 0.2, -1.0, 0.0, 0.001 * k, 0.0]})
        )  # fmt: skip
        out.append(
            ("/deploy/command", {"q": q, "qd": [0.1] * 6, "jaw": 0.6, "stamp_s": 0.01 * k + 0.01, "sent": True,
                                 "safety_stop": False, "reason": "", "interventions": []})
        )  # fmt: skip
    return out


def _run_messages(ticks: int = 40) -> Messages:
    """A whole one-episode deploy's messages, as the recorder writes them."""
    return [
        ("/deploy/meta", {"policy": "scripted", "target": "dvrk", "task": "lift", "dry_run": False}),
        ("/deploy/event", {"kind": "episode_start", "episode": 0, "seed": 1}),
        *_ticks(ticks),
        ("/deploy/event", {"kind": "episode_end", "episode": 0, "success": True, "steps": 8, "peak_force_n": 0.1}),
        ("/deploy/report", {"target": "dvrk", "force_limit_n": 3.0, "episodes": []}),
    ]


def _recording(path: Path, messages: Messages, *, library: str = "tissue-retract") -> Path:
    """Write ``messages`` (JSON payloads, or raw bytes) as a deploy's recording, in 4 KiB zstd chunks."""
    with path.open("wb") as f:
        writer = Writer(f, chunk_size=4096)
        writer.start(profile="", library=library)
        schema = writer.register_schema(name="deploy", encoding="jsonschema", data=b'{"type":"object"}')
        channels = {t: writer.register_channel(topic=t, message_encoding="json", schema_id=schema) for t in _TOPICS}
        for k, (topic, payload) in enumerate(messages):
            data = payload if isinstance(payload, bytes) else json.dumps(payload).encode()
            writer.add_message(channels[topic], log_time=1_000_000 * k, data=data, publish_time=1_000_000 * k)
        writer.finish()
    return path


def _edited(edit: Callable[[Messages], None]) -> Callable[[Path], Path]:
    """A builder of the whole run's recording with ``edit`` applied to its messages."""

    def build(path: Path) -> Path:
        messages = _run_messages()
        edit(messages)
        return _recording(path, messages)

    return build


def _set(topic: str, nth: int, change: Callable[[Any], Any]) -> Callable[[Messages], None]:
    """An edit: the ``nth`` message on ``topic`` replaced by ``change(payload)``."""

    def edit(messages: Messages) -> None:
        at = [k for k, (t, _) in enumerate(messages) if t == topic][nth]
        messages[at] = (topic, change(messages[at][1]))

    return edit


def _insert(topic: str, payload: Any) -> Callable[[Messages], None]:
    """An edit: one more message, before the report."""
    return lambda messages: messages.insert(len(messages) - 1, (topic, payload))


def _without(key: str) -> Callable[[dict[str, Any]], dict[str, Any]]:
    return lambda payload: {k: v for k, v in payload.items() if k != key}


def _with(key: str, value: Any) -> Callable[[dict[str, Any]], dict[str, Any]]:
    return lambda payload: {**payload, key: value}


def _empty_messages_chunk(
    count: int, compression: str, claimed: int | None = None, topic: str = "/deploy/measured"
) -> bytes:
    """A chunk record of ``count`` empty messages on ``topic``, compressed as it goes (never held whole)."""
    builder = RecordBuilder()
    Channel(id=1, schema_id=0, topic=topic, message_encoding="json", metadata={}).write(builder)
    channel = builder.end()
    Message(channel_id=1, sequence=0, log_time=0, publish_time=0, data=b"").write(builder)
    piece = builder.end() * 100_000
    size = len(channel) + len(piece) * (count // 100_000)
    if compression == "zstd":
        compressor = zstandard.ZstdCompressor().compressobj(size=size)
        parts = [compressor.compress(channel)] + [compressor.compress(piece) for _ in range(count // 100_000)]
        parts.append(compressor.flush())
    else:
        compressor = lz4.frame.LZ4FrameCompressor()
        parts = [compressor.begin(size), compressor.compress(channel)]
        parts += [compressor.compress(piece) for _ in range(count // 100_000)] + [compressor.flush()]
    Chunk(
        message_start_time=0, message_end_time=0, uncompressed_size=size if claimed is None else claimed,
        uncompressed_crc=0, compression=compression, data=b"".join(parts),
    ).write(builder)  # fmt: skip
    return builder.end()


def _mcap(path: Path, *chunks: bytes, library: str = "tissue-retract", profile: str = "") -> Path:
    """An MCAP file of a header, the given chunk records and a footer."""
    builder = RecordBuilder()
    Header(profile=profile, library=library).write(builder)
    head = builder.end()
    DataEnd(data_section_crc=0).write(builder)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
    path.write_bytes(_MAGIC + head + b"".join(chunks) + builder.end() + _MAGIC)
    return path


def _bomb(
    count: int, compression: str = "zstd", claimed: int | None = None, topic: str = "/deploy/measured", **header: str
) -> Callable[[Path], Path]:
    return lambda path: _mcap(path, _empty_messages_chunk(count, compression, claimed, topic), **header)


def _count_bomb(path: Path) -> Path:
    """Chunks each within the size limit, together more records than allowed (on a channel no reader decodes)."""
    per_chunk = (MAX_CHUNK_BYTES // 31) // 100_000 * 100_000
    chunk = _empty_messages_chunk(per_chunk, "zstd", topic="/scene/transforms")
    return _mcap(path, *[chunk] * (MAX_RECORDS // per_chunk + 1))


def _bag_with_hidden_chunk(path: Path) -> Path:
    """A ros2 bag whose chunk index points at a bomb hidden inside a record of an unknown kind, which a sequential
    reader skips and a reader that follows the index (rosbags) decompresses."""
    builder = RecordBuilder()
    Header(profile="ros2", library="rosbag2").write(builder)
    head = _MAGIC + builder.end()
    bomb = _empty_messages_chunk(10_000_000, "zstd", topic="/PSM1/measured_js")
    hidden = bytes([0x80]) + len(bomb).to_bytes(8, "little") + bomb  # opcode 0x80: a user record, skipped
    DataEnd(data_section_crc=0).write(builder)
    data_end = builder.end()
    chunk = Chunk.read(ReadDataStream(BytesIO(bomb[9:])))
    Schema(id=1, name="sensor_msgs/msg/JointState", encoding="ros2msg", data=b"").write(builder)
    Channel(id=1, schema_id=1, topic="/PSM1/measured_js", message_encoding="cdr", metadata={}).write(builder)
    ChunkIndex(
        message_start_time=0, message_end_time=0, chunk_start_offset=len(head) + 9, chunk_length=len(bomb),
        message_index_offsets={1: len(head) + 9 + len(bomb)}, message_index_length=31,  # one message on it, it says
        compression="zstd", compressed_size=len(chunk.data),
        uncompressed_size=chunk.uncompressed_size,
    ).write(builder)  # fmt: skip
    Footer(summary_start=len(head) + len(hidden) + len(data_end), summary_offset_start=0, summary_crc=0).write(builder)
    path.write_bytes(head + hidden + data_end + builder.end() + _MAGIC)
    return path


def _compressed_bag(path: Path) -> Path:
    """A rosbag2 folder in rosbag2's file compression mode (its one storage file zstd-compressed)."""
    folder = path.with_suffix("")
    folder.mkdir()
    (folder / "bag_0.mcap.zstd").write_bytes(zstandard.ZstdCompressor().compress(b"\0" * 1_000_000))
    info = {
        "version": 8, "storage_identifier": "mcap", "relative_file_paths": ["bag_0.mcap.zstd"],
        "duration": {"nanoseconds": 0}, "starting_time": {"nanoseconds_since_epoch": 0}, "message_count": 0,
        "topics_with_message_count": [], "compression_format": "zstd", "compression_mode": "FILE", "files": [],
    }  # fmt: skip
    (folder / "metadata.yaml").write_text(json.dumps({"rosbag2_bagfile_information": info}))
    return folder


REPLAY = ("replay",)
ALL = ("replay", "plot", "calibrate")


@dataclass(frozen=True)
class Row:
    """One hostile file: how it is built, the words its error must contain, the commands that read it."""

    name: str
    build: Callable[[Path], Path]
    words: tuple[str, ...]
    commands: tuple[str, ...] = ALL


ROWS = [
    Row("missing-q", _edited(_set("/deploy/measured", 0, _without("q"))),
        ("/deploy/measured message 0: q", "6 numbers", "missing")),
    Row("list-payload", _edited(_set("/deploy/measured", 3, lambda p: [p])),
        ("/deploy/measured message 3", "a JSON object", "list")),
    Row("list-meta", _edited(_set("/deploy/meta", 0, lambda p: [p])), ("/deploy/meta message 0", "a JSON object"),
        (*REPLAY, "plot")),
    Row("list-in-meta", _edited(_set("/deploy/meta", 0, _with("target", ["dvrk"]))),
        ("/deploy/meta message 0: target", "a string"), (*REPLAY, "plot")),
    Row("ragged-q", _edited(_set("/deploy/measured", 5, _with("q", [0.0] * 5))),
        ("/deploy/measured message 5: q", "6 numbers", "[0.0, 0.0, 0.0, 0.0, 0.0]")),
    Row("string-q", _edited(_set("/deploy/command", 2, _with("q", "0 0 0 0 0 0"))),
        ("/deploy/command message 2: q", "6 numbers"), (*REPLAY, "plot")),
    Row("string-in-q", _edited(_set("/deploy/measured", 2, _with("q", ["0", 0, 0, 0, 0, 0]))),
        ("/deploy/measured message 2: q", "6 numbers")),
    Row("huge-integer-q", _edited(_set("/deploy/measured", 1, _with("q", [10**400, 0, 0, 0, 0, 0]))),
        ("/deploy/measured message 1: q", "6 numbers")),
    Row("deep-json", _edited(_set("/deploy/measured", 4, lambda p: ("[" * 100_000 + "]" * 100_000).encode())),
        ("/deploy/measured message 4", "a JSON object", "RecursionError")),
    Row("missing-limit", _edited(_insert("/deploy/event", {"kind": "force_limit_exceeded", "episode": 0,
                                                           "peak_n": 3.5, "duration_s": 0.1})),
        ("/deploy/event message 2: limit_n", "a number", "missing"), REPLAY),
    Row("string-t-in-event", _edited(_insert("/deploy/event", {"kind": "hold", "text": "stale", "t": "soon"})),
        ("/deploy/event message 2: t", "absent"), (*REPLAY, "plot")),
    Row("string-peak-force", _edited(_set("/deploy/event", 1, _with("peak_force_n", "high"))),
        ("/deploy/event message 1: peak_force_n", "a number or null"), REPLAY),
    Row("string-force-limit", _edited(_set("/deploy/report", 0, _with("force_limit_n", "3 N"))),
        ("/deploy/report message 0: force_limit_n", "a number or null"), ("plot",)),
    Row("string-stamp", _edited(_set("/deploy/measured", 0, _with("stamp_s", "0.0"))),
        ("/deploy/measured message 0: stamp_s", "a number or null")),
    Row("zstd-bomb", _bomb(10_000_000), ("chunks of at most 67108864 bytes decompressed", "holds 310000045")),
    Row("zstd-bomb-lying", _bomb(10_000_000, claimed=1000), ("the size they state", "states 1000 bytes")),
    Row("lz4-bomb-lying", _bomb(10_000_000, "lz4", claimed=1000), ("the size they state", "states 1000 bytes")),
    Row("record-count-bomb", _count_bomb, (f"at most {MAX_RECORDS} records",)),
    Row("bag-zstd-bomb", _bomb(10_000_000, topic="/PSM1/measured_js", library="rosbag2", profile="ros2"),
        ("chunks of at most 67108864 bytes decompressed",), ("calibrate",)),
    Row("bag-index-to-hidden-chunk", _bag_with_hidden_chunk, ("an index that points at the file's own chunks",),
        ("calibrate",)),
    Row("bag-file-compression", _compressed_bag, ("rosbag2's file compression", "ros2 bag convert"), ("calibrate",)),
]  # fmt: skip


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT_BYTES, MEMORY_LIMIT_BYTES))


def _run_limited(*args: str) -> subprocess.CompletedProcess[str]:
    """``tissue-retract ARGS`` in a fresh interpreter within :data:`MEMORY_LIMIT_BYTES` of address space."""
    return subprocess.run(
        [sys.executable, "-m", "tissue_retract", *args],
        capture_output=True, text=True, timeout=600, check=False, preexec_fn=_limit_memory,
    )  # fmt: skip


def _argv(command: str, path: Path, out: Path) -> tuple[str, ...]:
    if command == "replay":
        return ("replay", str(path))
    if command == "plot":
        return ("replay", str(path), "--plot", str(out))
    return ("calibrate-wrench", "--from", str(path), "--out", str(out))


def test_the_rows_use_the_readers_limits() -> None:
    """The limits the rows are built against are the reader's."""
    from hardware_if.recording import reader

    assert (reader.MAX_CHUNK_BYTES, reader.MAX_RECORDS) == (MAX_CHUNK_BYTES, MAX_RECORDS)


def test_every_row_names_a_command() -> None:
    """Every row is read by at least one command, and every command reads some row."""
    assert all(row.commands and set(row.commands) <= set(ALL) for row in ROWS)
    assert {command for row in ROWS for command in row.commands} == set(ALL)


@pytest.mark.parametrize("row", ROWS, ids=[row.name for row in ROWS])
def test_a_hostile_recording_gets_a_named_error_in_bounded_memory(tmp_path: Path, row: Row) -> None:
    """Each command refuses the file: exit non-zero, the file and what is allowed named, no traceback, no output."""
    path = row.build(tmp_path / f"{row.name}.mcap")
    failures = []
    for command in row.commands:
        out = tmp_path / f"{command}.{'png' if command == 'plot' else 'json'}"
        result = _run_limited(*_argv(command, path, out))
        text = result.stdout + result.stderr
        missing = [w for w in (str(path), *row.words) if w not in text]
        if result.returncode == 0 or "Traceback" in text or missing or out.exists():
            failures.append(
                f"{command}: exit {result.returncode}, missing {missing}, output {out.exists()}: {text[-600:]}"
            )
    assert not failures, "\n".join(failures)


def test_a_recording_without_its_footer_still_reads(tmp_path: Path) -> None:
    """A killed deploy's file (the end of its last chunk and the footer cut off) is summarised and said truncated."""
    path = _recording(tmp_path / "whole.mcap", _run_messages(200))
    data = path.read_bytes()
    cut = tmp_path / "killed.mcap"
    cut.write_bytes(data[: len(data) // 2])
    result = _run_limited("replay", str(cut))
    assert result.returncode == 0, result.stderr
    assert "truncated recording" in result.stdout
    assert "commands:" in result.stdout and "0 computed" not in result.stdout
