"""The retraction-force limit in the loop: an aggressive pulling policy with and without the safety filter."""

from __future__ import annotations

from policies.resolve import resolve_policy
from safety.config import SafetyConfig
from sim.evaluation import run_episode, summarize
from tests.sim.conftest import make_env

# Well inside the flap's grip capacity (friction 0.45-0.6 x 4 N pinch): unfiltered pulls exceed it.
_FORCE_LIMIT_N = 1.0
_EPISODES = 10


def _peak_forces(safety: bool) -> dict[str, float]:
    env = make_env("target", safety=safety, safety_config=SafetyConfig(force_limit_n=_FORCE_LIMIT_N))
    try:
        policy, reset = resolve_policy("sim.pulling:AggressivePull", env)
        results = [run_episode(env, policy, reset, seed) for seed in range(4200, 4200 + _EPISODES)]
    finally:
        env.close()
    return summarize(results, elapsed_s=1.0)


def test_force_limit_holds_against_aggressive_pulls() -> None:
    """With the filter on, peak force stays within F_max + 10 %; the same pulls without it exceed F_max."""
    filtered = _peak_forces(safety=True)
    unfiltered = _peak_forces(safety=False)
    assert filtered["peak_force_n"] <= 1.1 * _FORCE_LIMIT_N
    assert filtered["joint_limit_violations"] == 0 and filtered["workspace_violation_mm"] <= 1.0
    assert filtered["min_insertion_margin_m"] > 0.0
    assert filtered["interventions"] > 0
    assert unfiltered["peak_force_n"] > _FORCE_LIMIT_N
