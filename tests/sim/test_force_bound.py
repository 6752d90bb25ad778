"""The force limit is a bound: after a grasp, no action sequence takes the force past 1.1 x the limit.

A limit below what the retraction costs is kept by not lifting, and said: a ``force_limit_stall``.

Hypothesis draws the limit (the nerve preset's 0.4 N up to 3 N), the flap's modulus and any sequence of
full-range motions with the jaw closed; the scripted expert makes the grasp first so that every example
pulls on held tissue. The peak is over every control tick of the real PyBullet episode.

Not covered, and measured: a jaw that lets go and closes again on the flap while it still swings from
the release grips moving tissue, which the tool's motion does not cause and the filter cannot prevent
(one tick at 1.07 N against a 0.4 N limit, with the tool still).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings, target
from hypothesis import strategies as st

import sim.envs
from hardware_if.deploy.options import DeployOptions
from hardware_if.deploy.run import deploy
from hardware_if.recording.replay import load_recording, summarize_recording
from policies.resolve import resolve_policy
from safety.config import SafetyConfig
from safety.force_watch import STALL_SPEED_M_S
from sim.evaluation import describe_stalls, force_limit_summary, run_episode
from sim.expert import ScriptedExpert

_BOUND = 1.10
_MOTION = st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4)
_ENVS: dict[float, object] = {}


def _env(limit_n: float):  # one environment per limit for the whole module: building one takes seconds
    if limit_n not in _ENVS:
        _ENVS[limit_n] = sim.envs.make("lift", safety_config=SafetyConfig(force_limit_n=limit_n))
    return _ENVS[limit_n]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    limit_n=st.sampled_from([0.4, 1.0, 3.0]),
    modulus_kpa=st.floats(3.0, 30.0),
    seed=st.integers(0, 10_000),
    motions=st.lists(_MOTION, min_size=10, max_size=25),
)
def test_no_action_sequence_takes_the_force_past_the_bound(
    limit_n: float, modulus_kpa: float, seed: int, motions: list[list[float]]
) -> None:
    """Peak force over every tick after the expert's grasp <= 1.1 x the limit, whatever the motions."""
    env: Any = _env(limit_n)
    observation, _ = env.reset(seed=seed, options={"tissue_youngs_modulus_kpa": modulus_kpa})
    expert = ScriptedExpert(env)
    expert.reset()
    for _ in range(sim.envs.MAX_EPISODE_STEPS):
        if env.unwrapped.scene.grasp.holding:
            break
        observation, *_ = env.step(expert(observation))
    assume(env.unwrapped.scene.grasp.holding)
    peak = 0.0
    for motion in motions:
        _, _, _, _, info = env.step(np.array([*motion, -1.0]))  # the jaw stays closed
        peak = max(peak, info["force_peak_n"])
    target(peak / limit_n)  # steer the search towards the largest peak
    assert peak <= _BOUND * limit_n, (peak, limit_n, info["force_limit_exceeded"])


def teardown_module() -> None:
    for env in _ENVS.values():
        env.close()  # type: ignore[attr-defined]


_BELOW_LIFT_N = 0.05  # holding the Lift task's flap at its goal costs about 0.09 N (expert, 3 N limit)


def test_a_limit_below_what_the_retraction_costs_is_said_and_kept() -> None:
    """At 0.05 N the expert's retraction stalls: one ``force_limit_stall`` naming the load, the bound kept."""
    env: Any = _env(_BELOW_LIFT_N)
    result = run_episode(env, *resolve_policy("scripted", env), seed=900)
    assert not result.success and result.peak_force_n <= _BOUND * _BELOW_LIFT_N
    (stall,) = result.force_limit_stall
    assert 0.0 < stall["static_load_n"] < _BELOW_LIFT_N and stall["speed_m_s"] < STALL_SPEED_M_S
    assert f"{stall['static_load_n']:.3f} N" in stall["text"]
    summary = force_limit_summary([result.to_dict()])
    assert summary["force_limit_stalls"] == 1 and describe_stalls(summary).startswith("in 1 episode(s)")


def test_a_retraction_the_limit_does_not_hold_back_is_not_called_a_stall() -> None:
    """The expert at the generic preset's 3 N and the nerve preset's 0.4 N: no stall, every retraction done."""
    for limit_n in (3.0, 0.4):
        env: Any = _env(limit_n)
        policy, reset = resolve_policy("scripted", env)
        results = [run_episode(env, policy, reset, seed) for seed in (900, 901, 902)]
        assert all(r.success and not r.force_limit_stall for r in results), (limit_n, results)


def test_deploy_warns_of_the_stall_and_the_recording_keeps_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A sim deploy says the stall on stderr as it happens, counts it, records it, and replay lists it."""
    record = tmp_path / "stall.mcap"
    options = DeployOptions(
        policy="scripted", target="sim", task="lift", record=record, seed=900,
        safety_config=SafetyConfig(force_limit_n=_BELOW_LIFT_N),
    )  # fmt: skip
    report = deploy(options, echo=lambda _line: None)
    assert report.exit_code == 0 and report.force_limit_stalls == 1
    assert "WARNING: force limit 0.05 N stalls the retraction" in capsys.readouterr().err
    assert any("stalled the retraction in 1 episode(s)" in line for line in report.lines())
    summary = summarize_recording(load_recording(record))
    assert len(summary.force_limit_stalls) == 1 and summary.force_limit_stalls[0]["episode"] == 0
    assert "force limit stalled the retraction: 1 x" in "\n".join(summary.lines())
