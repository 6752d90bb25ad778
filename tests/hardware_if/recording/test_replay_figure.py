"""``replay --plot``: each episode on its own clock, the force limit drawn with the sensing's error band, the
travel bound and the force-limit events, units on every axis, holds named."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from hardware_if.deploy.options import DeployOptions
from hardware_if.deploy.run import deploy
from hardware_if.recording.replay import Recording, load_recording
from hardware_if.recording.replay_figure import draw_recording, episode_spans
from tissue_retract.faults import AT_VARIABLE

#: Steps of a Task I episode and the policy period of the simulation [s].
_STEPS, _POLICY_PERIOD_S = 50, 0.05


@pytest.fixture(scope="module")
def held_run(tmp_path_factory: pytest.TempPathFactory) -> Recording:
    """A simulated deploy of two Task I episodes whose policy raises at episode 1, step 20: a hold."""
    folder = tmp_path_factory.mktemp("replay")
    config = folder / "safety.toml"
    config.write_text("force_limit_n = 0.08\n")
    command = [sys.executable, "-m", "tissue_retract", "deploy", "--policy", "tissue_retract.faults:Raises"]
    command += ["--target", "sim", "--task", "lift", "--episodes", "2", "--safety-config", str(config)]
    command += ["--record", str(folder / "run.mcap"), "--policy-budget", "600"]  # the hold is the policy's error
    env = dict(os.environ, **{AT_VARIABLE: "1:20"})
    subprocess.run(command, env=env, capture_output=True, text=True, timeout=600, check=False)
    return load_recording(folder / "run.mcap")


def test_episodes_lie_end_to_end_on_their_own_clocks(held_run: Recording) -> None:
    """Episode 0 spans its 50 simulated steps (2.5 s) from 0; episode 1 starts where it ends, labelled."""
    spans = episode_spans(held_run)
    assert [s.label.split(":")[0] for s in spans] == ["episode 0 (seed 0)", "episode 1 (seed 1)"]
    assert spans[1].label.endswith(": no end")
    assert spans[0].offset_s == 0.0
    assert spans[0].duration_s == pytest.approx((_STEPS - 1) * _POLICY_PERIOD_S, abs=_POLICY_PERIOD_S)
    assert spans[1].offset_s == pytest.approx(spans[0].duration_s)
    assert spans[1].duration_s < spans[0].duration_s  # held at step 20


def test_the_figure_has_units_the_force_limit_and_the_hold(held_run: Recording) -> None:
    """Every panel's axis states its unit, the force limit is a labelled line, the hold a labelled marker."""
    figure = draw_recording(held_run)
    force, jaw, error, events = figure.axes
    assert "[N]" in force.get_ylabel() and "[rad]" in jaw.get_ylabel() and "[mm]" in error.get_ylabel()
    assert "[s]" in events.get_xlabel()
    limits = [line for line in force.get_lines() if line.get_label() == "force limit 0.08 N"]
    assert limits and set(limits[0].get_ydata()) == {0.08}
    texts = [t.get_text() for t in force.texts]
    assert any(t.startswith("HOLD: policy error") for t in texts), texts
    assert any(t.startswith("episode 1 (seed 1)") for t in texts), texts
    assert "sent (0.5)" not in [line.get_label() for ax in figure.axes for line in ax.get_lines()]


@pytest.fixture(scope="module")
def calibrated_run(tmp_path_factory: pytest.TempPathFactory) -> Recording:
    """A simulated deploy of one Task I episode under the dvrk-calibrated sensing preset (7.2 N error bound)."""
    record = tmp_path_factory.mktemp("calibrated") / "run.mcap"
    deploy(DeployOptions(policy="scripted", target="sim", record=record, force_sensing="dvrk-calibrated"), echo=print)
    return load_recording(record)


def test_the_force_panel_draws_the_sensing_error_band_the_limit_and_the_travel_bound(calibrated_run: Recording) -> None:
    """Beside the measured force: a band of +-the recorded sensing error around it, the force limit, and the
    travel bound the chain recorded per tick while it held tissue; the legend names each, and the band does not
    set the scale (the limit stays in view)."""
    force = draw_recording(calibrated_run).axes[0]
    bands = [c for c in force.collections if c.get_label().startswith("sensing error \u00b17.21 N")]
    assert len(bands) == 1, [c.get_label() for c in force.collections]
    measured = np.linalg.norm(calibrated_run.force_n, axis=1)
    vertices = bands[0].get_paths()[0].vertices
    assert vertices[:, 1].max() == pytest.approx(measured.max() + 7.2125, rel=1e-6)
    lines = {line.get_label(): line for line in force.get_lines()}
    assert set(lines["force limit 3 N"].get_ydata()) == {3.0}
    travel = np.asarray(lines["travel bound (held load + stiffness x travel)"].get_ydata(), dtype=float)
    assert np.isfinite(travel).any() and np.nanmin(travel) > 0.0
    recorded = calibrated_run.travel_bound_n[np.isfinite(calibrated_run.travel_bound_n)]
    np.testing.assert_array_equal(travel[np.isfinite(travel)], recorded[: np.isfinite(travel).sum()])
    assert np.isfinite(travel).sum() >= len(recorded) - 1  # the recording's last command follows its last measurement
    legend = [text.get_text() for text in force.get_legend().get_texts()]
    assert {"measured |force|", "force limit 3 N", "travel bound (held load + stiffness x travel)"} <= set(legend)
    assert 3.0 < force.get_ylim()[1] < 3.0 + 7.2125


def _exceeded(start_s: float, peak_n: float, t: float) -> dict[str, float | str]:
    """A ``force_limit_exceeded`` event of 0.05 s above a 1 N limit, logged at recording time ``t`` [s]."""
    return {
        "kind": "force_limit_exceeded",
        "start_s": start_s,
        "duration_s": 0.05,
        "peak_n": peak_n,
        "limit_n": 1.0,
        "t": t,
    }


def test_force_limit_events_are_marked_where_they_happened() -> None:
    """An excursion above the limit is marked at its start and peak, a stall at the load it held, each named
    once in the legend however many there are."""
    t = np.arange(100) * 0.01
    rec = Recording(
        meta={"target": "dvrk", "sensing": {"force_sensing": "dvrk", "force_sensing_error_n": 0.0}},
        report={"force_limit_n": 1.0},
        events=[
            {"kind": "episode_start", "episode": 0, "seed": 0, "t": 0.0},
            _exceeded(start_s=0.3, peak_n=1.4, t=0.36),
            _exceeded(start_s=0.5, peak_n=1.2, t=0.53),
            {"kind": "force_limit_stall", "static_load_n": 0.9, "speed_m_s": 0.01, "limit_n": 1.0, "t": 0.705},
        ],
        measured_t=t,
        measured_q=np.zeros((100, 6)),
        force_n=np.zeros((100, 3)),
        measured_stamp_s=t,
        measured_jaw=np.zeros(100),
    )
    force = draw_recording(rec).axes[0]
    marks = [line for line in force.get_lines() if line.get_marker() in ("v", "s")]
    assert [(float(m.get_xdata()[0]), float(m.get_ydata()[0]), m.get_marker()) for m in marks] == [
        pytest.approx((0.3, 1.4, "v")),
        pytest.approx((0.5, 1.2, "v")),
        pytest.approx((0.7, 0.9, "s")),
    ]
    labels = [m.get_label() for m in marks if not m.get_label().startswith("_")]
    assert labels == ["force limit exceeded", "force limit stalled the retraction"]
    assert not [c for c in force.collections if c.get_label().startswith("sensing error")]  # exact: no band
