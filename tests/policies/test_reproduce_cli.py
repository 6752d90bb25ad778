"""`tissue-retract reproduce` runs as a user types it, at a tiny budget."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from tests.conftest import run_cli

#: One run (DDPG on Task I, seed 1) of four episodes, evaluated twice, in one process.
ONE_RUN = ("--budget", "4", "--tasks", "I", "--algos", "ddpg", "--seeds", "1", "--no-ablation")
ONE_RUN += ("--eval-every", "2", "--eval-episodes", "2", "--jobs", "1")


@pytest.fixture(scope="module")
def local_reproduction(tmp_path_factory: pytest.TempPathFactory) -> tuple[subprocess.CompletedProcess[str], Path]:
    """``tissue-retract reproduce`` of :data:`ONE_RUN` on the local pool, and its output folder (read-only)."""
    out = tmp_path_factory.mktemp("reproduce-local")
    return run_cli("reproduce", *ONE_RUN, "--out", str(out)), out


# With the Ray test, which compares the Ray backend's records with this same local reproduction.
@pytest.mark.xdist_group("ray")
def test_reproduce_writes_tables_beside_the_paper(
    local_reproduction: tuple[subprocess.CompletedProcess[str], Path],
) -> None:
    """A one-run reproduction writes results.md with the paper's number beside ours, and the curves."""
    result, out = local_reproduction
    assert result.returncode == 0, result.stderr
    text = (out / "results.md").read_text()
    assert "83 +- 0.7" in text  # the paper's DDPG on Task I, beside ours
    assert (out / "results-curves.png").stat().st_size > 1000


def test_unknown_algorithm_is_refused() -> None:
    """An algorithm outside the five is refused with the valid names."""
    result = run_cli("reproduce", "--algos", "ppo")
    assert result.returncode == 1
    assert "ddpgbc" in result.stderr


def _run_records(out: Path) -> dict[str, dict[str, object]]:
    """Each run's outcome.json without what depends on the machine's speed or the hour."""
    records = {}
    for path in sorted(out.glob("runs/*/outcome.json")):
        record = json.loads(path.read_text())
        for key in ("wall_seconds", "steps_per_second", "finished"):
            record.pop(key)
        records[path.parent.name] = record
    return records


@pytest.mark.slow
@pytest.mark.xdist_group("ray")  # one local Ray cluster at a time: these run on one worker
def test_ray_backend_gives_the_local_pools_records(
    local_reproduction: tuple[subprocess.CompletedProcess[str], Path], tmp_path: Path
) -> None:
    """reproduce --backend ray (a local cluster on 127.0.0.1) trains the same runs to the same records."""
    local, local_out = local_reproduction
    assert local.returncode == 0, local.stderr
    ray = run_cli("reproduce", *ONE_RUN, "--backend", "ray", "--out", str(tmp_path / "ray"))
    assert ray.returncode == 0, ray.stderr
    assert "(ray)" in ray.stdout
    local_records, ray_records = _run_records(local_out), _run_records(tmp_path / "ray")
    assert list(local_records) == ["I-ddpg-d100-s1"]
    assert local_records == ray_records
