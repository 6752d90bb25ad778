"""The robustness report as a reader sees it: rendered by headless Chromium, every number rounded with its unit."""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib.image

from sim.sweep import EpisodeStore, make_trials, parse_ranges, run_trials
from sim.sweep.page import Page, percent, percent_interval, quantity
from sim.sweep.report import write_report
from tests.chromium import RAW_REPR, render

WORKER = "tests.sweep.workers:toy_episode"


def test_numbers_are_rounded_with_their_units() -> None:
    """quantity, percent and percent_interval round and carry units; missing values read n/a."""
    assert quantity(3.141289745173306, "N") == "3.14 N"
    assert quantity(0.3, "N") == "0.300 N"
    assert quantity(3.0, "N", digits=1) == "3 N"
    assert quantity(0.000123456, "m") == "0.000123 m"
    assert quantity(None, "N") == quantity(float("nan"), "N") == "n/a"
    assert percent(0.4567) == "45.7 %"
    assert percent_interval(0.3123, 0.6011) == "31.2 to 60.1 %"


def test_markdown_and_html_say_the_same(tmp_path: Path) -> None:
    """Every text of a page appears, escaped, in its HTML and in its Markdown."""
    page = Page("A <title>")
    page.card([("success", "45.0 %")], alert=["success"])
    page.items(["one", "two"])
    page.table(["a", "b"], [["1 N", "2 N"]])
    page.command("tissue-retract robustness --vary 'stiffness=0.3:3x'")
    files = page.write(tmp_path)
    text, markdown = files["report_html"].read_text(), files["report_md"].read_text()
    assert "<h1>A &lt;title&gt;</h1>" in text and "class=alert>45.0 %" in text
    assert "<ul><li>one</li><li>two</li></ul>" in text
    for fragment in ("45.0 %", "- one", "| 1 N | 2 N |", "stiffness=0.3:3x"):
        assert fragment in markdown


def _report(tmp_path: Path) -> Path:
    ranges = parse_ranges("stiffness=0.3:3x")
    records = run_trials(
        make_trials(ranges, 60, seed=4), WORKER, store=EpisodeStore(tmp_path / "e.jsonl"), jobs=2, show_progress=False
    )
    context = {"policy": "toy", "task": "Toy-v0", "safety filter": "on"}
    files = write_report(
        tmp_path,
        records,
        ranges,
        title="Robustness of toy on Toy-v0",
        context=context,
        force_limit_n=2.0,
        command="tissue-retract robustness --policy toy --task toy --vary stiffness=0.3:3x",
    )
    return files["report_html"]


def test_report_renders_in_chromium_with_no_raw_values(tmp_path: Path) -> None:
    """Headless Chromium shows the card, every section and plot, no raw repr, nothing wider than the page."""
    screenshot = tmp_path / "report.png"
    text, layout = render(_report(tmp_path), screenshot)
    assert RAW_REPR.search(text) is None, RAW_REPR.search(text)
    assert "worst peak force" in text and re.search(r"\d\.\d+ N, \d\.\d\d x the 2\.00 N limit", text)
    assert "tissue-retract robustness --policy toy" in text
    assert layout["overflow"] <= 0, "the page is wider than the window"
    assert len(layout["images"]) == 3 and all(layout["images"])
    assert layout["card"] == "grid"
    assert layout["headings"] == [
        "Command",
        "Terms",
        "Success and peak force against stiffness=0.3:3x",
        "Failure classes against stiffness",
        "Peak force",
    ]
    assert layout["alerts"] == ["worst peak force"]  # the toy's forces reach 4.5 N against the 2 N limit
    pixels = matplotlib.image.imread(screenshot)[..., :3]
    assert pixels.shape[1] == 1100 and pixels.shape[0] > 900  # a full page, taller than one window
    assert pixels.std() > 0.05  # rendered, not blank
