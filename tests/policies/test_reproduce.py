"""The paper's evaluation protocol, run end to end on the toy task."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from policies.errors import ReproductionError
from policies.reproduce import OUTCOME_FILE, PAPER_TABLE1, Run, RunOutcome, plan, reproduce, table_blocks
from policies.toy_env import TOY_TASK_ID
from tests.policies.conftest import TINY, ToyReproduction


def test_plan_covers_table1_and_the_demo_ablation(tmp_path: Path) -> None:
    """The plan has 5 algorithms x 3 tasks x 3 seeds, plus 25 and 50 demos on Task III for the four demo users."""
    runs = plan(tmp_path)
    assert len(runs) == 5 * 3 * 3 + 4 * 2 * 3
    assert len({r.out_dir for r in runs}) == len(runs)
    assert {r.demos for r in runs if r.task != "III"} == {100}


def test_tables_put_ours_beside_the_papers() -> None:
    """Table 1 shows mean +- 95 % CI over seeds next to the paper's number; Table 2 appears with an ablation."""

    def outcome(algo: str, seed: int, demos: int, success: float) -> RunOutcome:
        run = Run("III", "x", algo, seed, demos, 1, 1, 1, Path("."))
        return RunOutcome(run, success)

    outcomes = [outcome("col", s, 100, v) for s, v in ((1, 0.7), (2, 0.8), (3, 0.9))]
    outcomes += [outcome("col", s, 25, 0.5) for s in (1, 2, 3)]
    text = str(table_blocks(outcomes))
    paper = PAPER_TABLE1["III"]["col"]
    assert f"80 +- 25 / {paper[0]:g} +- {paper[1]:g}" in text
    assert "Table 2" in text and "50 +- 0 / 50" in text


@pytest.mark.xdist_group("toy-reproduction")  # with the report's tests of the same reproduction
def test_reproduce_smoke_on_the_toy_task(toy_reproduction: ToyReproduction) -> None:
    """reproduce trains runs in parallel processes and writes results.md with the tables and the curves."""
    runs, outcomes, ended = toy_reproduction.runs, toy_reproduction.outcomes, toy_reproduction.ended
    assert len(outcomes) == 4 and all(len(o.curve) == 2 for o in outcomes)
    assert sorted(o.run.out_dir.name for o in ended) == sorted(r.out_dir.name for r in runs)  # each, as it ended
    text = toy_reproduction.results_md.read_text()
    assert "| toy |" in text and "Table 1" in text
    assert (toy_reproduction.out_dir / "results-curves.png").stat().st_size > 1000


def test_reproduce_reads_finished_runs_instead_of_training_them_again(tmp_path: Path) -> None:
    """A run with an outcome.json is not retrained: a reproduction spread over sittings resumes run by run."""
    runs = plan(
        tmp_path, episodes=2, tasks={"toy": TOY_TASK_ID}, algos=("ddpg",), seeds=(1,), demos=0,
        eval_every=1, eval_episodes=1, overrides=TINY,
    )  # fmt: skip
    _, first = reproduce(tmp_path, runs, jobs=1)
    record = json.loads((runs[0].out_dir / OUTCOME_FILE).read_text())
    assert record["success"] == first[0].success and record["curve"] == [list(p) for p in first[0].curve]
    policy = runs[0].out_dir / "policy.safetensors"
    written = policy.stat().st_mtime_ns
    _, again = reproduce(tmp_path, runs, jobs=1)
    assert policy.stat().st_mtime_ns == written
    assert again[0].wall_seconds == first[0].wall_seconds and again[0].curve == first[0].curve


def test_a_failed_run_does_not_stop_the_others(tmp_path: Path) -> None:
    """Every other run still finishes and keeps its outcome; the error names the failed run afterwards."""
    runs = plan(
        tmp_path, episodes=2, tasks={"toy": TOY_TASK_ID}, algos=("ddpg",), seeds=(1, 2, 3), demos=0,
        eval_every=1, eval_episodes=1, overrides=TINY,
    )  # fmt: skip
    broken = runs[0].out_dir
    broken.mkdir(parents=True)
    (broken / OUTCOME_FILE).write_text("{ not json")
    with pytest.raises(ReproductionError, match=broken.name) as raised:
        reproduce(tmp_path, runs, jobs=1)  # in turn, the broken one first: the others run only if it does not stop
    assert [name for name, _ in raised.value.failures] == [broken.name]
    assert all((run.out_dir / OUTCOME_FILE).exists() for run in runs[1:])
