"""MkDocs hooks: the pages that are generated at build time, so that they cannot drift from the code.

- ``commands.md``: the command reference, each command's ``--help`` from the argument parsers of
  :mod:`tissue_retract.cli` (its marker line is replaced by the generated text).
- ``api/<package>/<module>.md``: one page per module of the six packages, filled in by mkdocstrings
  from the docstrings, listed under "Python API" in the navigation as the folders lie: a package's
  modules, then a section per sub-package (``sim.envs``, ``hardware_if.console``, ...).
- "More": every ``docs/*.md`` page that ``nav`` in ``mkdocs.yml`` does not list, so a page added to
  ``docs/`` shows in the site without editing anything else.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.structure.files import File, Files

#: The packages whose modules get an API page, bottom layer first (as in pyproject.toml).
PACKAGES = ("psm_control", "safety", "sim", "policies", "hardware_if", "tissue_retract")

#: The line of ``commands.md`` that the generated reference replaces.
COMMANDS_MARKER = "<!-- generated: command reference -->"

#: Width of the generated ``--help`` text, fixed so the page does not depend on the terminal.
HELP_COLUMNS = 80

ROOT = Path(__file__).resolve().parents[2]


def _modules(package: str) -> list[str]:
    """Dotted names of the package and its modules, sorted, private ones (``_x``) left out."""
    names = []
    for path in sorted((ROOT / package).rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        if any(part.startswith("_") for part in parts):
            continue
        names.append(".".join(parts))
    return sorted(names)


def _api_path(module: str) -> str:
    return "api/" + module.replace(".", "/") + ".md"


def _api_section(package: str, names: list[str]) -> list[dict[str, Any]]:
    """The navigation of ``package``: its own page and its modules' pages, then a section per sub-package."""
    depth = package.count(".") + 1
    children = sorted({".".join(name.split(".")[: depth + 1]) for name in names if name.startswith(f"{package}.")})
    pages = [{package: _api_path(package)}] if package in names else []
    sections = []
    for child in children:
        if any(name.startswith(f"{child}.") for name in names):
            sections.append({child: _api_section(child, names)})
        else:
            pages.append({child: _api_path(child)})
    return pages + sections


def _api_nav() -> list[dict[str, Any]]:
    return [{package: _api_section(package, _modules(package))} for package in PACKAGES]


def _listed(nav: Any) -> set[str]:
    """Every page path the navigation names."""
    if isinstance(nav, str):
        return {nav}
    if isinstance(nav, dict):
        return set().union(*(_listed(value) for value in nav.values()))
    if isinstance(nav, list):
        return set().union(*(_listed(item) for item in nav)) if nav else set()
    return set()


def on_config(config: MkDocsConfig) -> MkDocsConfig:
    """Add the API pages and a "More" section of the unlisted ``docs/*.md`` pages to the navigation."""
    nav = list(config.nav or [])
    listed = _listed(nav)
    docs = Path(config.docs_dir)
    more = [page.name for page in sorted(docs.glob("*.md")) if page.name not in listed]
    if more:
        nav.append({"More": more})
    nav.append({"Python API": _api_nav()})
    config.nav = nav
    return config


def on_files(files: Files, config: MkDocsConfig) -> Files:
    """Generate one API page per module (a mkdocstrings block each)."""
    for package in PACKAGES:
        for module in _modules(package):
            content = f"# `{module}`\n\n::: {module}\n"
            files.append(File.generated(config, _api_path(module), content=content))
    return files


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _fit(text: str, width: int = HELP_COLUMNS) -> str:
    """Lines of ``text`` wider than the page, broken at spaces: argparse aligns a long command's usage under
    its name and cannot break inside one option group, so its lines can run past the page."""
    import textwrap

    lines = []
    for line in text.splitlines():
        if len(line) <= width:
            lines.append(line)
            continue
        indent = min(len(line) - len(line.lstrip()), 8)
        lines.extend(
            textwrap.wrap(
                line.strip(),
                width,
                initial_indent=" " * indent,
                subsequent_indent=" " * (indent + 2),
                break_on_hyphens=False,
            )
        )
    return "\n".join(lines)


def _command_help(path: list[str]) -> str:
    """The ``--help`` text of ``tissue-retract PATH...``, built as the command line builds it."""
    from tissue_retract.cli import build_parser

    parser = build_parser(path)
    for name in path:
        parser = _subparsers(parser)[name]
    return parser.format_help()


def _command_paths() -> list[list[str]]:
    from tissue_retract.cli import SUBCOMMANDS, build_parser

    paths: list[list[str]] = []
    for name in SUBCOMMANDS:
        paths.append([name])
        children = _subparsers(_subparsers(build_parser([name]))[name])
        paths.extend([name, child] for child in children)
    return paths


def command_reference() -> str:
    """Markdown of every command's help, one section per command and subcommand."""
    os.environ["COLUMNS"] = str(HELP_COLUMNS)
    sections = []
    for path in _command_paths():
        title = "tissue-retract " + " ".join(path)
        level = "##" if len(path) == 1 else "###"
        sections.append(f"{level} `{title}`\n\n```text\n{_fit(_command_help(path).rstrip())}\n```\n")
    return "\n".join(sections)


def on_page_markdown(markdown: str, page: Any, config: MkDocsConfig, files: Files) -> str:
    """Replace the marker of ``commands.md`` with the generated command reference."""
    if COMMANDS_MARKER in markdown:
        return markdown.replace(COMMANDS_MARKER, command_reference())
    return markdown
