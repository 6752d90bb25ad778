"""A command module's docstring as ``--help`` shows it: plain text, wrapped to the terminal.

The docstrings are written for the API pages (reST roles such as ``:mod:`x``` and double-backtick
literals); a terminal and the command reference show them as text. argparse's own formatters either keep
every line as written (long lines run off a terminal) or re-flow everything (lists and examples run
together), so paragraphs are wrapped here and indented blocks and list items keep their shape.
"""

from __future__ import annotations

import re
import shutil
import textwrap

__all__ = ["help_width", "plain_description"]

#: ``:role:`target``` (``~`` keeps only the last dotted part), as Sphinx renders it.
_ROLE = re.compile(r":[a-z]+:`(~?)([^`]+)`")
#: ``` ``literal`` ``` -> ```literal```.
_LITERAL = re.compile(r"``([^`]+)``")
#: A list item: ``- text`` or ``1. text``, its text's indent.
_ITEM = re.compile(r"^(\s*)([-*]|\d+\.)\s+")


def help_width() -> int:
    """The width argparse wraps option help to (the terminal's, or ``$COLUMNS``, less 2)."""
    return max(shutil.get_terminal_size().columns - 2, 40)


def _plain(text: str) -> str:
    text = _ROLE.sub(lambda m: m.group(2).rsplit(".", 1)[-1] if m.group(1) else m.group(2), text)
    return _LITERAL.sub(r"`\1`", text)


def _verbatim(line: str) -> bool:
    """An example or table line (indented 4 or more, not a list item): kept as written."""
    return len(line) - len(line.lstrip()) >= 4 and not _ITEM.match(line)


def _blocks(lines: list[str]) -> list[list[str]]:
    """Paragraphs and list items (each with its continuation lines); blank and verbatim lines on their own."""
    blocks: list[list[str]] = []
    for line in lines:
        joins = (
            blocks
            and line.strip()
            and not _ITEM.match(line)
            and not _verbatim(line)
            and blocks[-1][0].strip()
            and not _verbatim(blocks[-1][0])
        )
        if joins:
            blocks[-1].append(line)
        else:
            blocks.append([line])
    return blocks


def plain_description(doc: str | None, width: int | None = None) -> str:
    """``doc`` without reST markup, each paragraph and list item wrapped to ``width`` (default: the terminal's).

    Lines indented by 4 or more that are not list items (examples, tables) are kept as they are.
    """
    if not doc:
        return ""
    width = width or help_width()
    out: list[str] = []
    for block in _blocks(_plain(textwrap.dedent(doc).strip("\n")).splitlines()):
        first = block[0]
        if not first.strip():
            out.append("")
            continue
        if _verbatim(first):
            out.extend(block)
            continue
        indent = len(first) - len(first.lstrip())
        item = _ITEM.match(first)
        hanging = " " * (item.end() if item else indent)
        words = " ".join(line.strip() for line in block)
        out.extend(
            textwrap.wrap(
                words,
                width,
                initial_indent=" " * indent,
                subsequent_indent=hanging,
                break_on_hyphens=False,
                break_long_words=False,
            )
        )
    return "\n".join(out)
