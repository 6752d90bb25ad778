"""The reproduction in docs/: the full protocol, on one recorded commit of this history, and its page in Chromium.

The page and the README name the commit the runs trained on; these tests check that the record says what it
claims (its code trees are that commit's, that commit is in this checkout's history, every run and cell is
there) so that a hand-edited or partial ``results.json`` cannot pass for the paper's protocol.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

from policies.reproduce import CODE_DIRS, PAPER_TABLE1, PAPER_TABLE2
from tests.chromium import RAW_REPR, render

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
RESULTS = json.loads((DOCS / "results.json").read_text())


def _git(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, timeout=30, check=False)


def test_the_documented_reproduction_names_one_commit_of_this_history() -> None:
    """Every run trained on the same committed trees; they are the named commit's, an ancestor of HEAD."""
    commit, code = RESULTS["commit"], RESULTS["code"]
    assert commit is not None and code is not None, "the runs trained on different code"
    assert code["uncommitted_changes"] is False
    assert code["trees"] == {name: _git("rev-parse", f"{commit}:{name}").stdout.strip() for name in CODE_DIRS}
    assert _git("merge-base", "--is-ancestor", commit, "HEAD").returncode == 0
    for page in (ROOT / "README.md", DOCS / "learning.md"):
        assert f"commit {commit}" in page.read_text(), f"{page.name} does not name the reproduction's commit"


def test_the_documented_reproduction_is_the_full_protocol() -> None:
    """69 runs of 1,000 episodes: Table 1 (3 tasks x 5 algorithms) and Table 2 (25 / 50 / 100 demos on Task
    III for the four algorithms with demonstrations), seeds 1-3, every cell beside the paper's number."""
    runs = RESULTS["runs"]
    assert RESULTS["episodes_per_run"] == 1000 and len(runs) == 69
    assert all(r["episodes"] == 1000 and r["curve"][-1]["episode"] == 1000 for r in runs)
    table1 = {(c["task"], c["algo"]): c for c in RESULTS["cells"] if c["table"] == 1}
    table2 = {(c["algo"], c["demos"]): c for c in RESULTS["cells"] if c["table"] == 2}
    assert set(table1) == {(task, algo) for task in PAPER_TABLE1 for algo in PAPER_TABLE1[task]}
    assert set(table2) == {(algo, n) for algo in PAPER_TABLE2 for n in PAPER_TABLE2[algo]}
    for cell in [*table1.values(), *table2.values()]:
        assert cell["seeds"] == [1, 2, 3] and cell["paper_mean_pct"] is not None
        key = (cell["task"], cell["algo"], cell["demos"])
        by_seed = {r["seed"]: r["success_pct"] for r in runs if (r["task"], r["algo"], r["demos"]) == key}
        assert [by_seed[s] for s in cell["seeds"]] == cell["success_pct"]


def test_the_documented_reproduction_page_renders(tmp_path: Path) -> None:
    """docs/results.html opens in headless Chromium with both figures, both tables and no raw values."""
    text, layout = render(DOCS / "results.html", tmp_path / "results.png")
    assert RAW_REPR.search(text) is None, RAW_REPR.search(text)
    assert layout["overflow"] <= 0, "the page is wider than the window"
    assert len(layout["images"]) == 2 and all(layout["images"])
    assert layout["headings"] == [
        "Command",
        "Table 1: success % (100 demonstrations; ours / paper)",
        "Table 2: Task III success % by demonstrations (ours / paper)",
        "Ours against the paper, per cell",
        "Learning curves",
        "Every run",
    ]
    assert "code" not in layout["alerts"]
