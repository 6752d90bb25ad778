"""Faults without ROS: an invalid action in the simulation, a policy fault in a sim deploy, and recordings
that survive a crash (read without their footer)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import sim.envs
from hardware_if.client.deadman import Deadman
from hardware_if.deploy.options import DeployOptions
from hardware_if.deploy.report import EXIT_HOLD
from hardware_if.deploy.run import deploy
from hardware_if.recording.recorder import Recorder, read_recording
from hardware_if.recording.replay import load_recording, summarize_recording
from safety.config import SafetyConfig
from sim.evaluation import FAILURE_CLASSES, run_episode, summarize


def test_invalid_action_holds_and_keeps_the_jaw_closed() -> None:
    """A NaN or wrong-shaped action holds position with the jaw as it was: a closed jaw stays closed."""
    env = sim.envs.make("lift")
    try:
        env.reset(seed=0)
        closed = env.unwrapped.config.jaw_closed_rad
        for _ in range(4):
            env.step(np.array([0.0, 0.0, 0.0, 0.0, -1.0]))
        assert env.unwrapped.backend.measure().jaw == pytest.approx(closed, abs=0.05)
        tip = env.unwrapped.grasp_position()
        for bad in (np.full(5, np.nan), np.zeros(3)):
            _, _, _, _, info = env.step(bad)
            assert info["invalid_action"]
        assert env.unwrapped.backend.measure().jaw == pytest.approx(closed, abs=0.05)
        np.testing.assert_allclose(env.unwrapped.grasp_position(), tip, atol=1e-4)
    finally:
        env.close()


def test_invalid_actions_are_counted_and_classed() -> None:
    """An episode of invalid actions is counted in the result and the summary, and classed invalid_action."""
    env = sim.envs.make("lift")
    try:
        result = run_episode(env, lambda _obs: np.full(5, np.nan), lambda: None, seed=0)
    finally:
        env.close()
    assert result.invalid_actions == result.steps > 0
    assert result.failure_class == "invalid_action" and "invalid_action" in FAILURE_CLASSES
    summary = summarize([result], 1.0)
    assert summary["invalid_actions"] == result.steps and summary["failure_classes"]["invalid_action"] == 1


def _exits(_observation: object) -> object:
    raise SystemExit(0)


def test_sim_deploy_holds_on_a_policy_that_exits(tmp_path: Path) -> None:
    """A policy raising SystemExit(0) in a sim deploy is a hold (exit 4) recorded with its reason."""
    record = tmp_path / "run.mcap"
    options = DeployOptions(policy=f"{__name__}:_exits", target="sim", record=record)
    report = deploy(options, echo=lambda _line: None)
    assert report.exit_code == EXIT_HOLD and report.holds == 1
    assert "policy error: the policy raised SystemExit" in report.fault
    assert any("HOLD: policy error" in line for line in report.lines())
    holds = summarize_recording(load_recording(record)).holds
    assert holds and "SystemExit" in holds[0]


def test_recording_without_footer_is_read_and_marked_truncated(tmp_path: Path) -> None:
    """What was flushed before a crash is read back, and the recording says it was truncated."""
    path = tmp_path / "crash.mcap"
    recorder = Recorder(path)
    recorder.write("/deploy/meta", {"target": "sim", "dry_run": False})
    recorder.write("/deploy/event", {"kind": "episode_start", "episode": 0})
    recorder.write("/deploy/event", {"kind": "episode_end", "episode": 0, "success": True, "steps": 3})
    recorder.write("/deploy/event", {"kind": "episode_start", "episode": 1})  # not flushed: lost with the crash
    read = read_recording(path)  # the writer is still open: no summary, no footer
    assert read.truncated
    assert [payload.get("kind") for _, _, payload in read if payload.get("kind")] == ["episode_start", "episode_end"]
    summary = summarize_recording(load_recording(path))
    assert summary.truncated and len(summary.episodes) == 1
    assert summary.lines()[0].startswith("truncated recording")
    recorder.close()
    read = read_recording(path)
    assert not read.truncated and len(read.messages) == 4


def test_deadman_default_is_the_safety_config_timeout() -> None:
    """The client's deadman uses SafetyConfig.deadman_timeout_s, not a timeout of its own."""
    assert Deadman().timeout_s == SafetyConfig().deadman_timeout_s
