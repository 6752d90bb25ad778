"""A calibration bounds only the motions it saw: its inertia is known up to the accelerations of its own logs.

A log of the same arm moving 1.3 times as fast (1.7 times the accelerations) is checked against a calibration
fitted on the slow one: its samples beyond the covered accelerations are counted, not judged, and the file names
the accelerations it covers.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from arm_logs import AMPLITUDE, CENTRE, RATE_HZ, arm_efforts
from bags import write_bag

from hardware_if.wrench.calibration import read_calibration
from tests.conftest import run_cli

SAMPLES = 3000


def _bag(path: Path, speed: float, phase: float) -> tuple[Path, np.ndarray]:
    """A bag of the arm's free-space log along the slow Lissajous motion run ``speed`` times as fast; and its
    accelerations."""
    t = np.arange(SAMPLES) / RATE_HZ
    w = speed * 2 * np.pi * np.array([0.13, 0.17, 0.11, 0.19, 0.23, 0.29])
    q = CENTRE + AMPLITUDE * np.sin(np.outer(t, w) + phase)
    qd = AMPLITUDE * w * np.cos(np.outer(t, w) + phase)
    qdd = -AMPLITUDE * w**2 * np.sin(np.outer(t, w) + phase)
    return write_bag(path, q, qd, arm_efforts(q, qd, qdd, noise=0.02), rate_hz=RATE_HZ), qdd


@pytest.fixture(scope="module")
def slow_fit(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    folder = tmp_path_factory.mktemp("covered")
    fit, fit_qdd = _bag(folder / "fit", 1.0, 0.0)
    held, _ = _bag(folder / "held", 1.0, 1.0)
    fast, fast_qdd = _bag(folder / "fast", 1.3, 2.0)
    out = folder / "wrench.json"
    done = run_cli("calibrate-wrench", "--from", str(fit), "--held-out", str(held), "--out", str(out))
    assert done.returncode == 0, done.stdout + done.stderr
    return {"calibration": out, "fit_qdd": fit_qdd, "fast": fast, "fast_qdd": fast_qdd}


def test_the_file_names_the_accelerations_it_was_fitted_on(slow_fit: dict[str, object]) -> None:
    """covered_acceleration is the fitted log's largest acceleration per joint (its filtered estimate: within
    10 % of the motion's own), and a deploy is told the regime in those numbers."""
    calibration = read_calibration(slow_fit["calibration"])
    covered = np.array(calibration.covered_acceleration, dtype=float)
    largest = np.abs(slow_fit["fit_qdd"]).max(axis=0)
    assert np.all(np.abs(covered - largest) <= 0.1 * largest), (covered, largest)
    assert calibration.covers(0.9 * largest) and not calibration.covers(1.5 * largest)
    assert "joint accelerations within those it was fitted on (" in calibration.regime_words()
    regime = calibration.sensing_regime()
    assert regime.error_outside_n == calibration.error_bound_n
    assert regime.covers(0.9 * largest) and not regime.covers(np.where(np.arange(6) == 2, 2 * largest, 0.0))


def test_a_faster_log_is_judged_only_within_the_covered_accelerations(
    slow_fit: dict[str, object], tmp_path: Path
) -> None:
    """--check on the fast log: the samples beyond the covered accelerations are outside the regime of
    error_bound_with_acceleration_n (counted, not judged), and exactly those."""
    report = tmp_path / "check.json"
    done = run_cli("calibrate-wrench", "--check", str(slow_fit["calibration"]), "--from", str(slow_fit["fast"]),
                   "--json", str(report))  # fmt: skip
    assert "Traceback" not in done.stderr
    figures = json.loads(report.read_text())
    calibration = read_calibration(slow_fit["calibration"])
    beyond = ~calibration.covers(slow_fit["fast_qdd"])
    assert 0 < beyond.sum() < len(beyond)
    # The check filters the log's velocities before differentiating: its accelerations are close to, not exactly,
    # the motion's; the count agrees within 5 % of the log.
    assert abs(figures["samples_beyond_covered_acceleration"] - int(beyond.sum())) <= 0.05 * len(beyond)
    name = "error_bound_with_acceleration_n"
    assert figures["outside_regime_samples"][name] >= figures["samples_beyond_covered_acceleration"]
    assert "joint accelerations within those fitted on" in figures["regime"][name]


def test_a_file_of_an_earlier_version_covers_every_acceleration(slow_fit: dict[str, object], tmp_path: Path) -> None:
    """Without covered_acceleration the bound holds at any acceleration, as the file said when it was written;
    a covered acceleration that is not a positive number is refused by name."""
    data = json.loads(Path(slow_fit["calibration"]).read_text())
    older = tmp_path / "older.json"
    older.write_text(json.dumps({k: v for k, v in data.items() if k != "covered_acceleration"}))
    calibration = read_calibration(older)
    assert calibration.covered_acceleration is None and calibration.covers(np.full(6, 1e6))
    assert "any acceleration" in calibration.regime_words()
    for bad in ([1.0] * 5, [1.0, 1.0, -1.0, 1.0, 1.0, 1.0], "fast"):
        broken = tmp_path / "broken.json"
        broken.write_text(json.dumps(data | {"covered_acceleration": bad}))
        with pytest.raises(Exception, match="covered_acceleration"):
            read_calibration(broken)
