"""The README stays a front page: short, and its command table names every bench target."""

from __future__ import annotations

from pathlib import Path

from tissue_retract.cli.bench import TARGETS

README = Path(__file__).resolve().parents[1] / "README.md"
#: What the front page may take; details belong on the documentation pages it links.
MAX_LINES = 250


def test_the_readme_is_at_most_a_front_page_long() -> None:
    """README.md has at most 250 lines."""
    lines = README.read_text().count("\n")
    assert lines <= MAX_LINES, f"README.md has {lines} lines; move detail to docs/"


def test_the_readme_command_table_names_every_bench_target() -> None:
    """The README's bench row lists every target ``bench --help`` lists."""
    row = next(line for line in README.read_text().splitlines() if line.startswith("| `bench "))
    names = row.split("`")[1].removeprefix("bench ").split("\\|")
    assert names == list(TARGETS), names
