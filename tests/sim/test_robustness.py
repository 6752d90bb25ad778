"""Random actions at the ends of the randomization ranges, every three of them met at each combination of ends."""

from __future__ import annotations

import itertools
import re

import numpy as np
import pytest

from psm_control.errors import ConfigurationError
from sim.randomization import DEFAULT_RANGES, INTEGER_PARAMETERS, Randomizer
from sim.robustness import ALIASES, parse_vary, training_ranges
from sim.sweep import make_trials
from tests.sim.conftest import make_env


def test_same_seed_same_parameters() -> None:
    """The randomizer draws the same values from the same seed, and fixed values win."""
    randomizer = Randomizer()
    a = randomizer.sample(np.random.default_rng(4), {"tissue_density_kg_m3": 1050.0})
    b = randomizer.sample(np.random.default_rng(4), {"tissue_density_kg_m3": 1050.0})
    assert a == b and a["tissue_density_kg_m3"] == 1050.0
    assert set(a) == set(DEFAULT_RANGES)


def test_training_draws_a_multiple_as_a_sweep_does() -> None:
    """stiffness=0.3:3x: training's modulus lies below nominal as often as the sweep's (log-uniform), and
    drawing it so moves no other parameter's draw."""
    ranges = training_ranges(parse_vary("stiffness=0.3:3x,size=0.07:0.09"))
    assert ranges.log_uniform == {"tissue_youngs_modulus_kpa"} and ranges.disturbances == ()
    logged, flat = Randomizer(ranges.randomization, ranges.log_uniform), Randomizer(ranges.randomization)
    trained, plain = [], []
    for seed in range(2000):
        a, b = logged.sample(np.random.default_rng(seed)), flat.sample(np.random.default_rng(seed))
        assert {k: v for k, v in a.items() if k != "tissue_youngs_modulus_kpa"} == {
            k: v for k, v in b.items() if k != "tissue_youngs_modulus_kpa"
        }
        trained.append(a["tissue_youngs_modulus_kpa"] / 10.0)
        plain.append(b["tissue_youngs_modulus_kpa"] / 10.0)
    swept = [t.params["stiffness"] for t in make_trials(parse_vary("stiffness=0.3:3x"), 2000, seed=0)]
    assert min(trained) >= 0.3 and max(trained) <= 3.0
    assert np.mean(np.array(trained) < 1.0) == pytest.approx(np.mean(np.array(swept) < 1.0), abs=0.04)
    assert np.mean(np.array(plain) < 1.0) < 0.35  # uniform in kPa: 7 of 27 kPa lie below 10


def test_a_log_uniform_range_must_lie_above_zero() -> None:
    """Log-uniform draws of a range reaching 0, or of a whole-number parameter, are refused by name."""
    with pytest.raises(ConfigurationError, match="tissue_damping"):
        Randomizer({"tissue_damping": (0.0, 0.1)}, log_uniform={"tissue_damping"})
    with pytest.raises(ConfigurationError, match="action_latency_steps"):
        Randomizer({"action_latency_steps": (1.0, 3.0)}, log_uniform={"action_latency_steps"})


#: Every this many randomization parameters' ends (low, high) are met together in some episode of the extremes test.
COVERED_TOGETHER = 3


def covering_corners(
    names: list[str], strength: int, rng: np.random.Generator, candidates: int = 60
) -> list[dict[str, int]]:
    """Corners of the parameters' box (each name at its low end, 0, or high end, 1) such that every ``strength``
    of them meet in each of their 2**strength combinations of ends in at least one corner.

    Greedy: each corner is the one of ``candidates`` random corners that meets the most combinations not yet met
    (a covering array: 31 corners for the 19 ranges of the multisite task, where 200 random ones met every
    combination only with high probability). Written here: a greedy covering array is a few lines of set
    arithmetic.
    """
    groups = list(itertools.combinations(range(len(names)), strength))
    unmet = {(group, ends) for group in groups for ends in itertools.product((0, 1), repeat=strength)}
    corners = []
    while unmet:
        options = rng.integers(2, size=(candidates, len(names)))
        met = [{(g, tuple(int(option[i]) for i in g)) for g in groups} & unmet for option in options]
        best = int(np.argmax([len(m) for m in met]))
        unmet -= met[best]
        corners.append(dict(zip(names, (int(end) for end in options[best]), strict=True)))
    return corners


def test_covering_corners_meet_every_combination() -> None:
    """Every three of 19 parameters meet in all eight combinations of their ends, in far fewer corners than the
    200 random ones the extremes test ran before."""
    names = [f"p{i}" for i in range(19)]
    corners = covering_corners(names, COVERED_TOGETHER, np.random.default_rng(0))
    every_combination = set(itertools.product((0, 1), repeat=COVERED_TOGETHER))
    for group in itertools.combinations(names, COVERED_TOGETHER):
        assert {tuple(c[n] for n in group) for c in corners} == every_combination, group
    assert len(corners) <= 40


@pytest.mark.slow
def test_random_actions_at_randomization_extremes() -> None:
    """Random-action episodes at the ends of every range raise nothing and produce no NaN: every three of the
    ranges that have two ends meet at each combination of them in some episode (:func:`covering_corners`)."""
    rng = np.random.default_rng(2024)
    env = make_env("multisite")
    ranges = env.unwrapped.randomizer.ranges
    varied = [name for name, (low, high) in ranges.items() if low != high]
    corners = covering_corners(varied, COVERED_TOGETHER, rng)
    env.action_space.seed(0)
    unstable = 0
    try:
        for episode, corner in enumerate(corners):
            options = {name: float(bounds[corner.get(name, 0)]) for name, bounds in ranges.items()}
            obs, _ = env.reset(seed=episode, options=options)
            while True:
                action = env.action_space.sample()
                action[4] = -1.0 if rng.random() < 0.4 else action[4]  # close often, to exercise grasps
                obs, reward, terminated, truncated, info = env.step(action)
                assert all(np.all(np.isfinite(v)) for v in obs.values())
                assert np.isfinite(reward) and np.all(np.isfinite(info["force_n"]))
                unstable += int(info["sim_unstable"])
                if terminated or truncated:
                    break
    finally:
        env.close()
    assert unstable == 0


def test_every_sweep_parameter_has_an_allowed_range_holding_its_default() -> None:
    """Each --vary name has a stated allowed range around its default range; one end outside it is refused
    by name with the range, and an episode's value outside it is refused by the simulation too."""
    from sim.envs import MAX_EPISODE_STEPS
    from sim.robustness import allowed_range, nominal, sweep_parameters

    for name in sweep_parameters():
        low, high, _ = allowed_range(name)
        full = ALIASES.get(name, name)
        if full in DEFAULT_RANGES:
            assert low <= DEFAULT_RANGES[full][0] <= DEFAULT_RANGES[full][1] <= high, name
        if full not in INTEGER_PARAMETERS and (full not in DEFAULT_RANGES or nominal(full) == 0.0):
            parse_vary(f"{name}={low:g}:{low:g}")  # the allowed end itself is accepted
        with pytest.raises(
            ConfigurationError, match=re.escape(f"vary.{name}=") + ".*" + re.escape(f"[{low:.10g}, {high:.10g}")
        ):
            parse_vary(f"{name}={low:g}:{2 * high + 1:g}")
    assert allowed_range("latency")[1] == MAX_EPISODE_STEPS  # a later action is never applied
    with pytest.raises(ConfigurationError, match="observation_noise_m"):
        Randomizer().sample(np.random.default_rng(0), {"observation_noise_m": 1e308})
