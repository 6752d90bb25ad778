"""bench sensing says which console a log came from, and marks the bins too thin to compare."""

from __future__ import annotations

import json
from typing import Any

import pytest
from arm_logs import arm_bag, arm_csv

from hardware_if.wrench.bag_writer import write_joint_bag
from hardware_if.wrench.joint_logs import read_joint_log
from tests.conftest import run_cli


def _one_sample_at_20_cm(q: Any, qd: Any, effort: Any) -> None:
    """One sample of the 8-16 cm motion moved to 25 cm: a depth bin of one sample."""
    q[150, 2] = 0.25


@pytest.fixture(scope="module")
def compared(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """bench sensing on a bag as calibrate-wrench --record writes it, a bag whose metadata names sim-dvrk, and a
    WPI-layout CSV (a real PSM's)."""
    folder = tmp_path_factory.mktemp("logs")
    source = arm_bag(folder / "source", 300, 0.0, edit=_one_sample_at_20_cm)
    recorded = write_joint_bag(folder / "recorded", "PSM1", [read_joint_log(source)])
    named = arm_bag(folder / "named", 300, 0.5)
    metadata = named / "metadata.yaml"
    metadata.write_text(metadata.read_text().replace("custom_data: null", "custom_data:\n    console: sim-dvrk"))
    wpi = arm_csv(folder / "wpi.csv", 400, 1.0)
    out = folder / "out.json"
    result = run_cli(
        "bench", "sensing", "--from", str(recorded), str(named), str(wpi), "--draws", "1", "--json", str(out)
    )  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    return {"stdout": result.stdout, "logs": json.loads(out.read_text())["logs"], "paths": (recorded, named, wpi)}


def test_the_console_column_names_the_console_the_log_came_from(compared: dict[str, Any]) -> None:
    """A recorded bag is not called a real console (it does not say which served it), a bag whose metadata names
    sim-dvrk is called so, and the public WPI layout is a real PSM's."""
    recorded, named, wpi = (compared["logs"][str(p)] for p in compared["paths"])
    expected = ((recorded, "unknown", "logged console"), (named, "sim-dvrk", "sim-dvrk console"))
    for entry, console, column in (*expected, (wpi, "dvrk", "real console")):
        assert entry["console"]["columns"][0] == column
        assert entry["logged_by"]["console"] == console
    stdout = " ".join(compared["stdout"].split())
    assert f"{compared['paths'][0]}: console: unknown (not named: a rosbag2 bag does not say" in stdout
    assert "real console" not in stdout.split(str(compared["paths"][2]))[0]


def test_a_bin_of_fewer_than_50_samples_is_marked_thin(compared: dict[str, Any]) -> None:
    """Every bin is marked thin exactly when it has fewer than 50 samples, in the JSON and in the printed table;
    the one-sample depth bin is one of them."""
    rows = [
        row
        for entry in compared["logs"].values()
        for table in ("by_depth", "by_speed")
        for row in entry["console"][table]
    ]
    assert all(row["thin"] is (row["samples"] < 50) for row in rows)
    recorded = compared["logs"][str(compared["paths"][0])]["console"]["by_depth"]
    assert [row["samples"] for row in recorded if row["thin"]] == [1]
    printed = [line for line in compared["stdout"].splitlines() if line.startswith("  20-30 cm")]
    assert printed and all(line.rstrip().endswith("thin: fewer than 50 samples") for line in printed)
    assert not any("thin" in line for line in compared["stdout"].splitlines() if " 14-17 cm " in line)
