"""The user-input layer: bounded regular UTF-8 files, strict YAML, output paths that never replace inputs."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from psm_control.errors import ConfigurationError, InputFileError
from psm_control.inputs import check_output_path, load_yaml, read_text


def test_devices_fifos_and_large_files_are_refused_without_reading(tmp_path: Path) -> None:
    """/dev/zero, a FIFO (opening it would block) and an oversized file are refused from their stat."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    big = tmp_path / "big"
    big.write_bytes(b"x" * 101)
    for path, words in ((Path("/dev/zero"), "regular file"), (fifo, "regular file"), (big, "at most 100")):
        with pytest.raises(InputFileError, match=words):
            read_text(path, "--config", max_bytes=100)


def test_only_utf8_text_is_read(tmp_path: Path) -> None:
    """UTF-8 (with or without a BOM) is read; UTF-16 and Latin-1 are refused by name."""
    good = tmp_path / "good"
    good.write_bytes("a: é\n".encode("utf-8-sig"))
    assert read_text(good, "f") == "a: é\n"
    for data, words in (("a: 1\n".encode("utf-16"), "UTF-16"), ("a: é\n".encode("latin-1"), "not UTF-8")):
        good.write_bytes(data)
        with pytest.raises(InputFileError, match=words):
            read_text(good, "f")


@pytest.mark.parametrize(
    ("text", "words"),
    [("a: 1\na: 2\n", "duplicate key 'a'"), ("x: &x [1]\ny: *x\n", "alias"), ("a: [\n", "valid YAML")],
)
def test_yaml_without_duplicates_or_aliases(text: str, words: str) -> None:
    """Duplicate keys, aliases (no alias bombs) and syntax errors are refused with the reason."""
    with pytest.raises(InputFileError, match=words):
        load_yaml(text, "--config", "c.yaml")
    assert load_yaml("a: {b: [1, 2]}\n", "--config", "c.yaml") == {"a": {"b": [1, 2]}}


def test_an_output_never_replaces_an_input(tmp_path: Path) -> None:
    """An output path equal to an input (also through a symlink) or a folder is refused; a new folder is made."""
    source = tmp_path / "policy.safetensors"
    source.write_bytes(b"x")
    link = tmp_path / "link.safetensors"
    link.symlink_to(source)
    for path in (source, link):
        with pytest.raises(ConfigurationError, match="other than the input"):
            check_output_path(path, "--json", (source,))
    with pytest.raises(ConfigurationError, match="not a folder"):
        check_output_path(tmp_path, "--json")
    made = check_output_path(tmp_path / "new" / "eval.json", "--json", (source,))
    assert made.parent.is_dir() and not made.exists()
