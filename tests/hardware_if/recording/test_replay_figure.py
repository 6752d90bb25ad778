"""``replay --plot``: each episode on its own clock, the force limit drawn, units on every axis, holds named."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

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
