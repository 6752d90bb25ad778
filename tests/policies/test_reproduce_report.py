"""The reproduction's report: each cell judged against the paper, results.json, the page in Chromium."""

from __future__ import annotations

import json
import os
from pathlib import Path

import matplotlib.image
import pytest

from policies.reproduce import (
    CODE_DIRS,
    PAPER_TABLE1,
    START_FILE,
    Run,
    RunOutcome,
    cells,
    code_identity,
    plan,
    reproduce,
)
from policies.toy_env import TOY_TASK_ID
from tests.chromium import RAW_REPR, render
from tests.policies.conftest import TINY, ToyReproduction


def _outcome(task: str, algo: str, seed: int, demos: int, success: float, code: dict | None = None) -> RunOutcome:
    return RunOutcome(Run(task, "x", algo, seed, demos, 1, 1, 1, Path(".")), success, code=code or {})


def test_a_cell_is_below_the_paper_under_its_mean_minus_its_interval() -> None:
    """Table 1 cells use the paper's interval; Table 2's take Table 1's Task III interval (the paper gives none)."""
    mean, ci = PAPER_TABLE1["III"]["dex"]  # 58 +- 8
    outcomes = [_outcome("III", "dex", s, 100, v) for s, v in ((1, 0.50), (2, 0.50), (3, 0.51))]
    outcomes += [_outcome("III", "dex", s, 25, v) for s, v in ((1, 0.22), (2, 0.21), (3, 0.20))]  # paper: 34
    found = {(c.table, c.demos): c for c in cells(outcomes)}
    assert set(found) == {(1, 100), (2, 25), (2, 100)}
    assert found[(1, 100)].meets_paper is True  # 50.3 >= 58 - 8
    assert found[(1, 100)].paper_ci_pct == ci and found[(1, 100)].paper_mean_pct == mean
    assert found[(2, 25)].paper_ci_pct == ci and found[(2, 25)].meets_paper is False  # 21 < 34 - 8
    assert found[(2, 25)].seeds == (1, 2, 3) and found[(2, 25)].success_pct == (22, 21, 20)


def test_runs_on_different_code_are_named_on_the_page(tmp_path: Path) -> None:
    """Finished runs read back from other code are not passed off as one version: results.json's code is null."""
    runs = plan(
        tmp_path / "runs", episodes=2, tasks={"toy": TOY_TASK_ID}, algos=("ddpg",), seeds=(1, 2), demos=0,
        eval_every=1, eval_episodes=1, overrides=TINY,
    )  # fmt: skip
    reproduce(tmp_path, runs, jobs=1)
    for run, (commit, tree) in zip(runs, (("0000000", "f" * 40), ("1111111", "e" * 40)), strict=True):
        record = json.loads((run.out_dir / "outcome.json").read_text())
        record["code"] = {"commit": commit, "trees": dict.fromkeys(CODE_DIRS, tree), "uncommitted_changes": False}
        (run.out_dir / "outcome.json").write_text(json.dumps(record))
    path, _ = reproduce(tmp_path, runs, jobs=1)
    results = json.loads((tmp_path / "results.json").read_text())
    assert results["code"] is None and results["commit"] is None
    assert [r["code"]["commit"] for r in results["runs"]] == ["0000000", "1111111"]
    assert "runs trained on 2 different versions of psm_control, safety, sim, policies" in path.read_text()


def test_a_run_resumed_on_other_code_says_so(tmp_path: Path) -> None:
    """A run that began on other code than it finished on is named, and results.json names no single code."""
    runs = plan(
        tmp_path / "runs", episodes=2, tasks={"toy": TOY_TASK_ID}, algos=("ddpg",), seeds=(1,), demos=0,
        eval_every=1, eval_episodes=1, overrides=TINY,
    )  # fmt: skip
    runs[0].out_dir.mkdir(parents=True)
    began = {"commit": "0000000", "trees": dict.fromkeys(CODE_DIRS, "f" * 40), "uncommitted_changes": False}
    (runs[0].out_dir / START_FILE).write_text(json.dumps(began))
    path, outcomes = reproduce(tmp_path, runs, jobs=1)
    assert outcomes[0].code["began_on_other_code"] == "0000000"
    assert json.loads((tmp_path / "results.json").read_text())["code"] is None
    text = path.read_text()
    assert "runs resumed on other code than they began on: toy-ddpg-d0-s1" in text


@pytest.mark.xdist_group("toy-reproduction")  # with the smoke test of the same reproduction
def test_results_json_and_the_page(toy_reproduction: ToyReproduction, tmp_path: Path) -> None:
    """results.json holds every cell beside the paper and every run's curve and code; the page renders in
    headless Chromium with both figures, rounded numbers and no raw values."""
    results = json.loads((toy_reproduction.out_dir / "results.json").read_text())
    here = code_identity()
    if here and not here["uncommitted_changes"]:
        assert results["code"] == here and results["commit"] == here["commit"]
    assert set(here.get("trees", {})) <= set(CODE_DIRS)
    assert [(c["table"], c["algo"], c["seeds"]) for c in results["cells"]] == [
        (1, "ddpg", [1, 2]),
        (1, "ddpgbc", [1, 2]),
    ]
    for cell in results["cells"]:
        assert cell["paper_mean_pct"] is None and cell["meets_paper"] is None  # the toy task is not in the paper
        assert 0 <= cell["mean_pct"] <= 100 and cell["ci95_pct"] >= 0
    assert len(results["runs"]) == 4
    assert all([p["episode"] for p in r["curve"]] == [1, 2] for r in results["runs"])
    assert all(r["wall_seconds"] > 0 and r["episodes"] == 2 for r in results["runs"])
    assert [m["cpus"] for m in results["machines"]] == [os.cpu_count()]
    # What tells two CPUs apart whose kernels may round differently, and the library versions.
    machine = results["machines"][0]
    assert {"cpu", "cpu_family", "cpu_model", "simd", "python", "torch"} <= set(machine)
    assert all(machine["packages"][name] for name in ("numpy", "pybullet", "pin")), machine

    screenshot = tmp_path / "page.png"
    text, layout = render(toy_reproduction.out_dir / "results.html", screenshot)
    assert RAW_REPR.search(text) is None, RAW_REPR.search(text)
    assert "tissue-retract reproduce --budget 2" in text
    assert layout["overflow"] <= 0, "the page is wider than the window"
    assert len(layout["images"]) == 2 and all(layout["images"])
    assert layout["card"] == "grid"
    assert layout["headings"] == [
        "Command",
        "Table 1: success % (2 demonstrations; ours / paper)",
        "Ours against the paper, per cell",
        "Learning curves",
        "Every run",
    ]
    pixels = matplotlib.image.imread(screenshot)[..., :3]
    assert pixels.shape[1] == 1100 and pixels.std() > 0.05
