"""A calibration bounds only the motions it saw: its inertia is known up to the accelerations of its own logs, and
its error_bound_n up to the fastest tip speed of its logs.

The fit is on a motion reaching 0.17 m/s (above the retraction speeds, 0.1 m/s); a log of the same arm moving 1.5
times as fast (2.25 times the accelerations) is checked against it: its samples beyond the covered accelerations are
not judged against error_bound_with_acceleration_n, its samples faster than the covered tip speed not against
error_bound_n; both are counted, and the file names what it covers. A deploy is told both, and does not trust the
force faster than the covered tip speed.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from arm_logs import AMPLITUDE, CENTRE, RATE_HZ, arm_efforts
from bags import write_bag

from hardware_if.wrench.calibration import RETRACTION_TIP_SPEED_M_S, read_calibration
from psm_control.robot import PsmModel
from safety.force_bound import INSIDE, OUTSIDE, UNTRUSTED
from tests.conftest import run_cli

SAMPLES = 3000


def _bag(path: Path, speed: float, phase: float) -> tuple[Path, np.ndarray, np.ndarray]:
    """A bag of the arm's free-space log along a Lissajous motion run ``speed`` times as fast as the slow one of
    the other tests; its accelerations and its tool-tip speeds."""
    t = np.arange(SAMPLES) / RATE_HZ
    w = speed * 2 * np.pi * np.array([0.13, 0.17, 0.11, 0.19, 0.23, 0.29])
    q = CENTRE + AMPLITUDE * np.sin(np.outer(t, w) + phase)
    qd = AMPLITUDE * w * np.cos(np.outer(t, w) + phase)
    qdd = -AMPLITUDE * w**2 * np.sin(np.outer(t, w) + phase)
    configuration = PsmModel().configuration()
    tip = np.zeros(SAMPLES)
    for k in range(SAMPLES):
        configuration.update(q[k])
        tip[k] = np.linalg.norm(configuration.base_jacobian()[:3] @ qd[k])
    return write_bag(path, q, qd, arm_efforts(q, qd, qdd, noise=0.02), rate_hz=RATE_HZ), qdd, tip


@pytest.fixture(scope="module")
def fit(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    folder = tmp_path_factory.mktemp("covered")
    fitted, fit_qdd, fit_tip = _bag(folder / "fit", 2.0, 0.0)
    held, _, _ = _bag(folder / "held", 2.0, 1.0)
    fast, fast_qdd, fast_tip = _bag(folder / "fast", 3.0, 2.0)
    out = folder / "wrench.json"
    done = run_cli("calibrate-wrench", "--from", str(fitted), "--held-out", str(held), "--out", str(out))
    assert done.returncode == 0, done.stdout + done.stderr
    return {
        "calibration": out,
        "fit_qdd": fit_qdd,
        "fit_tip": fit_tip,
        "fast": fast,
        "fast_qdd": fast_qdd,
        "fast_tip": fast_tip,
    }


def test_the_file_names_the_accelerations_it_was_fitted_on(fit: dict[str, object]) -> None:
    """covered_acceleration is the fitted log's largest acceleration per joint (its filtered estimate: within
    10 % of the motion's own), and a deploy is told the regime in those numbers."""
    calibration = read_calibration(fit["calibration"])
    covered = np.array(calibration.covered_acceleration, dtype=float)
    largest = np.abs(fit["fit_qdd"]).max(axis=0)
    assert np.all(np.abs(covered - largest) <= 0.1 * largest), (covered, largest)
    assert calibration.covers(0.9 * largest) and not calibration.covers(1.5 * largest)
    assert "joint accelerations within those it was fitted on (" in calibration.regime_words()
    regime = calibration.sensing_regime()
    assert regime.error_outside_n == calibration.error_bound_n
    assert regime.covers(0.9 * largest) and not regime.covers(np.where(np.arange(6) == 2, 2 * largest, 0.0))


def test_a_faster_log_is_judged_only_within_the_covered_accelerations(fit: dict[str, object], tmp_path: Path) -> None:
    """--check on the fast log: the samples beyond the covered accelerations are outside the regime of
    error_bound_with_acceleration_n (counted, not judged), and exactly those."""
    report = tmp_path / "check.json"
    done = run_cli("calibrate-wrench", "--check", str(fit["calibration"]), "--from", str(fit["fast"]),
                   "--json", str(report))  # fmt: skip
    assert "Traceback" not in done.stderr
    figures = json.loads(report.read_text())
    calibration = read_calibration(fit["calibration"])
    beyond = ~calibration.covers(fit["fast_qdd"])
    assert 0 < beyond.sum() < len(beyond)
    # The check filters the log's velocities before differentiating: its accelerations are close to, not exactly,
    # the motion's; the count agrees within 5 % of the log.
    assert abs(figures["samples_beyond_covered_acceleration"] - int(beyond.sum())) <= 0.05 * len(beyond)
    name = "error_bound_with_acceleration_n"
    assert figures["outside_regime_samples"][name] >= figures["samples_beyond_covered_acceleration"]
    assert "joint accelerations within those fitted on" in figures["regime"][name]


def test_a_file_of_an_earlier_version_covers_every_acceleration(fit: dict[str, object], tmp_path: Path) -> None:
    """Without covered_acceleration the bound holds at any acceleration, as the file said when it was written;
    a covered acceleration that is not a positive number is refused by name."""
    data = json.loads(Path(fit["calibration"]).read_text())
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


def test_the_file_names_the_fastest_tip_speed_it_was_fitted_on(fit: dict[str, object]) -> None:
    """covered_tip_speed_m_s is the fitted log's fastest tip speed; the deploy's regime takes the tight bound up to
    the retraction speeds, error_bound_n up to that speed, and no bound beyond."""
    calibration = read_calibration(fit["calibration"])
    fastest = float(np.max(fit["fit_tip"]))
    assert fastest > 1.5 * RETRACTION_TIP_SPEED_M_S
    assert calibration.covered_tip_speed_m_s == pytest.approx(fastest, rel=1e-6)
    assert calibration.bounded_tip_speed_m_s == calibration.covered_tip_speed_m_s
    regime = calibration.sensing_regime()
    assert regime.error_outside_n == calibration.error_bound_n
    assert regime.where(None, 0.9 * RETRACTION_TIP_SPEED_M_S) == INSIDE
    assert regime.where(None, 0.5 * (RETRACTION_TIP_SPEED_M_S + fastest)) == OUTSIDE
    assert regime.where(None, 1.01 * fastest) == UNTRUSTED
    assert f"tip speeds up to {RETRACTION_TIP_SPEED_M_S:g} m/s" in calibration.regime_words()


def test_a_faster_log_is_judged_up_to_the_fastest_tip_speed_fitted_on(fit: dict[str, object], tmp_path: Path) -> None:
    """--check on the faster log: error_bound_n is judged on its samples up to the covered tip speed, including
    those above the retraction speeds, and holds there; the faster samples are counted outside its regime."""
    report = tmp_path / "check.json"
    done = run_cli("calibrate-wrench", "--check", str(fit["calibration"]), "--from", str(fit["fast"]),
                   "--json", str(report))  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    figures = json.loads(report.read_text())
    calibration = read_calibration(fit["calibration"])
    tip = np.asarray(fit["fast_tip"])
    covered = float(calibration.covered_tip_speed_m_s or 0.0)
    inside, between = int(np.sum(tip <= covered)), int(np.sum((tip > RETRACTION_TIP_SPEED_M_S) & (tip <= covered)))
    assert between > 100 and inside < len(tip)
    assert figures["regime_samples"]["error_bound_n"] == inside
    assert figures["outside_regime_samples"]["error_bound_n"] == len(tip) - inside
    assert f"tip speed <= {covered:.3g} m/s" in figures["regime"]["error_bound_n"]
    assert figures["bound_held"] is True and figures["exceeding_samples"]["error_bound_n"] == 0


def test_a_file_of_an_earlier_version_bounds_only_the_retraction_speeds(fit: dict[str, object], tmp_path: Path) -> None:
    """Without covered_tip_speed_m_s, error_bound_n was judged only up to the retraction speeds: a deploy trusts it
    only there; a covered tip speed that is not a positive number is refused by name."""
    data = json.loads(Path(fit["calibration"]).read_text())
    older = tmp_path / "older.json"
    older.write_text(json.dumps({k: v for k, v in data.items() if k != "covered_tip_speed_m_s"}))
    calibration = read_calibration(older)
    assert calibration.covered_tip_speed_m_s is None
    assert calibration.bounded_tip_speed_m_s == RETRACTION_TIP_SPEED_M_S
    assert calibration.sensing_regime().where(None, 1.5 * RETRACTION_TIP_SPEED_M_S) == UNTRUSTED
    for bad in (-0.1, 0.0, "fast", float("inf")):
        broken = tmp_path / "broken.json"
        broken.write_text(json.dumps(data | {"covered_tip_speed_m_s": bad}))
        with pytest.raises(Exception, match="covered_tip_speed_m_s"):
            read_calibration(broken)
