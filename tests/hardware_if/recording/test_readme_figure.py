"""The README's figure is what ``replay --plot`` draws today, of the run ``make run`` records."""

from __future__ import annotations

import re
from pathlib import Path

from PIL import Image

from hardware_if.recording.replay_figure import LAYOUT_KEY
from tests.conftest import run_cli

ROOT = Path(__file__).resolve().parents[3]
FIGURE = ROOT / "docs" / "make-run.png"


def _text(path: Path) -> dict[str, str]:
    with Image.open(path) as image:
        return dict(getattr(image, "text", {}))


def test_the_readme_figure_has_the_panels_replay_draws_and_shows_make_run(tmp_path: Path) -> None:
    """A sim deploy's recording plotted now has the same panels as docs/make-run.png, whose title names make
    run's policy, task and target; the README and the docs page show that file and name the command."""
    record, plot = tmp_path / "run.mcap", tmp_path / "run.png"
    deploy = run_cli(
        "deploy",
        "--policy",
        "scripted",
        "--target",
        "sim",
        "--task",
        "lift",
        "--episodes",
        "1",
        "--record",
        str(record),
    )
    assert deploy.returncode == 0, deploy.stderr
    replay = run_cli("replay", str(record), "--plot", str(plot))
    assert replay.returncode == 0, replay.stderr
    drawn, kept = _text(plot), _text(FIGURE)
    assert drawn[LAYOUT_KEY] and kept.get(LAYOUT_KEY) == drawn[LAYOUT_KEY], (kept, drawn)
    makefile = (ROOT / "Makefile").read_text()
    run = re.search(r"deploy --policy (\S+) --target (\S+) --task (\S+)", makefile)
    assert run is not None
    policy, target, task = run.groups()
    assert kept["Title"].startswith(f"{policy} on ") and kept["Title"].endswith(f"deploy to {target}"), kept
    assert task.lower() in kept["Title"].replace("-", "").lower(), kept
    for page in (ROOT / "README.md", ROOT / "docs" / "index.md"):
        assert "make-run.png" in page.read_text()
    assert "replay runs/make-run.mcap --plot" in (ROOT / "docs" / "index.md").read_text()
