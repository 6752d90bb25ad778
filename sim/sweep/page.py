"""Report pages a person reads first: one self-contained HTML file (plots inlined) and its Markdown twin.

A page is built from a few kinds of block (a summary card, headings, paragraphs, lists, tables, figures,
a command line) and rendered twice, so the HTML and the Markdown always say the same thing. Numbers go
through :func:`quantity`, :func:`percent` and :func:`percent_interval`, which round them and give their
unit: a page never shows a raw Python value.
"""

from __future__ import annotations

import base64
import html
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from psm_control.outputs import write_atomic

__all__ = ["Page", "percent", "percent_interval", "quantity", "unit_of"]

_STYLE = """
body{font-family:system-ui,sans-serif;max-width:62em;margin:2em auto;padding:0 1em;color:#222;line-height:1.4}
h1{font-size:1.6em;margin-bottom:.3em}h2{font-size:1.25em;margin-top:1.6em;border-bottom:1px solid #ddd}
.card{display:grid;grid-template-columns:max-content 1fr;gap:.3em 1.2em;background:#f5f7fa;
border:1px solid #d8dee6;border-radius:6px;padding:1em 1.2em}
.card dt{font-weight:600}.card dd{margin:0}
.card dd.alert{color:#b00020;font-weight:600}
table{border-collapse:collapse;margin:.6em 0;font-variant-numeric:tabular-nums}
td,th{border:1px solid #ccc;padding:.25em .7em;text-align:right}th{background:#f0f0f0}
td:first-child,th:first-child{text-align:left}
figure{margin:1em 0}img{max-width:100%;height:auto}figcaption{font-size:.9em;color:#555}
code{background:#f0f0f0;padding:.1em .3em;border-radius:3px;word-break:break-all}
""".strip()


def quantity(value: float | None, unit: str = "", digits: int = 3) -> str:
    """``value`` to ``digits`` significant digits with its unit (``0.688 N``); ``n/a`` when missing."""
    if value is None or not math.isfinite(float(value)):
        return "n/a"
    text = f"{float(value):#.{digits}g}"  # '#' keeps trailing zeros: 0.300 N, not 0.3 N
    if "e" not in text:
        text = text.rstrip(".")
    return f"{text} {unit}".strip()


def percent(rate: float | None) -> str:
    """A fraction as a percentage with one decimal (``45.0 %``); ``n/a`` when missing."""
    if rate is None or not math.isfinite(float(rate)):
        return "n/a"
    return f"{100.0 * float(rate):.1f} %"


def percent_interval(low: float, high: float) -> str:
    """A 95 % interval of a fraction, in percent (``31.2 to 60.1 %``)."""
    return f"{100.0 * low:.1f} to {100.0 * high:.1f} %"


#: Unit of a setting by the suffix of its name (``force_limit_n`` is in N).
_SUFFIX_UNITS = {"_n": "N", "_m": "m", "_s": "s", "_hz": "Hz", "_rad": "rad", "_kg": "kg", "_m_s": "m/s"}


def unit_of(name: str) -> str:
    """The unit a setting's name states by its suffix (``force_limit_n`` -> ``N``), or ``""``."""
    matches = [suffix for suffix in _SUFFIX_UNITS if name.endswith(suffix)]
    return _SUFFIX_UNITS[max(matches, key=len)] if matches else ""


@dataclass(frozen=True)
class _Block:
    kind: str
    text: str = ""
    rows: tuple[tuple[str, ...], ...] = ()
    path: Path | None = None
    alert: frozenset[str] = frozenset()


@dataclass
class Page:
    """A report page under construction.

    Args:
        title: The page's heading and HTML title.
    """

    title: str
    blocks: list[_Block] = field(default_factory=list)

    def card(self, rows: Sequence[tuple[str, str]], alert: Sequence[str] = ()) -> None:
        """The summary card: label/value pairs; labels in ``alert`` are shown as warnings."""
        self.blocks.append(_Block("card", rows=tuple(rows), alert=frozenset(alert)))

    def heading(self, text: str) -> None:
        """A section heading."""
        self.blocks.append(_Block("heading", text))

    def paragraph(self, text: str) -> None:
        """A paragraph of plain text."""
        self.blocks.append(_Block("paragraph", text))

    def items(self, items: Sequence[str]) -> None:
        """A bulleted list."""
        self.blocks.append(_Block("items", rows=tuple((item,) for item in items)))

    def table(self, header: Sequence[str], rows: Sequence[Sequence[str]]) -> None:
        """A table of already formatted cells."""
        self.blocks.append(_Block("table", rows=(tuple(header), *(tuple(row) for row in rows))))

    def figure(self, path: Path, caption: str) -> None:
        """A PNG written beside the page (inlined in the HTML, linked from the Markdown)."""
        self.blocks.append(_Block("figure", caption, path=path))

    def command(self, text: str) -> None:
        """A command line, shown verbatim."""
        self.blocks.append(_Block("command", text))

    def html(self) -> str:
        """The page as one self-contained HTML document."""
        out = [f"<h1>{html.escape(self.title)}</h1>"]
        for block in self.blocks:
            out.append(_html_block(block))
        return (
            "<!doctype html>\n<html lang='en'><head><meta charset='utf-8'>"
            f"<title>{html.escape(self.title)}</title><style>{_STYLE}</style></head><body>\n"
            + "\n".join(out)
            + "\n</body></html>\n"
        )

    def markdown(self) -> str:
        """The page as Markdown (figures linked by file name)."""
        out = [f"# {self.title}", ""]
        for block in self.blocks:
            out += [*_markdown_block(block), ""]
        return "\n".join(out)

    def write(self, out_dir: Path, stem: str = "report") -> dict[str, Path]:
        """Write ``<stem>.html`` and ``<stem>.md`` into ``out_dir``; returns their paths."""
        paths = {"report_html": out_dir / f"{stem}.html", "report_md": out_dir / f"{stem}.md"}
        write_atomic(paths["report_html"], self.html(), "--out")
        write_atomic(paths["report_md"], self.markdown(), "--out")
        return paths


def _html_block(block: _Block) -> str:
    e = html.escape
    if block.kind == "card":
        cells = "".join(
            f"<dt>{e(label)}</dt><dd{' class=alert' if label in block.alert else ''}>{e(value)}</dd>"
            for label, value in block.rows
        )
        return f"<dl class='card'>{cells}</dl>"
    if block.kind == "heading":
        return f"<h2>{e(block.text)}</h2>"
    if block.kind == "paragraph":
        return f"<p>{e(block.text)}</p>"
    if block.kind == "items":
        return "<ul>" + "".join(f"<li>{e(row[0])}</li>" for row in block.rows) + "</ul>"
    if block.kind == "table":
        header, *rows = block.rows
        head = "<tr>" + "".join(f"<th>{e(c)}</th>" for c in header) + "</tr>"
        body = "".join("<tr>" + "".join(f"<td>{e(c)}</td>" for c in row) + "</tr>" for row in rows)
        return f"<table><thead>{head}</thead><tbody>{body}</tbody></table>"
    if block.kind == "figure" and block.path is not None:
        data = base64.b64encode(block.path.read_bytes()).decode("ascii")
        return (
            f"<figure><img alt='{e(block.text)}' src='data:image/png;base64,{data}'>"
            f"<figcaption>{e(block.text)}</figcaption></figure>"
        )
    return f"<p><code>{e(block.text)}</code></p>"


def _markdown_block(block: _Block) -> list[str]:
    if block.kind == "card":
        return [f"- **{label}**: {value}" for label, value in block.rows]
    if block.kind == "heading":
        return [f"## {block.text}"]
    if block.kind == "paragraph":
        return [block.text]
    if block.kind == "items":
        return [f"- {row[0]}" for row in block.rows]
    if block.kind == "table":
        header, *rows = block.rows
        return [
            "| " + " | ".join(header) + " |",
            "|" + "---|" * len(header),
            *("| " + " | ".join(row) + " |" for row in rows),
        ]
    if block.kind == "figure" and block.path is not None:
        return [f"![{block.text}]({block.path.name})"]
    return [f"`{block.text}`"]
