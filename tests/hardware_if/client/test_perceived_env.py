"""PerceivedTask: the site the policy observes comes from the estimator on the endoscope's frame."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import sim.envs
from hardware_if.client.perceived_env import PerceivedTask
from policies.perception.frames import true_sites
from sim.endoscope import Endoscope, StereoFrame
from sim.evaluation import run_episode, summarize
from sim.tissue import SITE_NAMES

_SHIFT_M = np.array([0.001, -0.002, 0.002])


class ShiftedTruth:
    """An estimator double: the true sites moved by a fixed shift, and a record of the frames it was shown."""

    def __init__(self, env: Any, *, mark_sites: bool = False) -> None:
        self.env, self.mark_sites, self.endoscope = env, mark_sites, Endoscope(width=64, height=48)
        self.frames: list[StereoFrame] = []

    def world_sites(self, frame: StereoFrame, site: str | None = None) -> np.ndarray:
        self.frames.append(frame)
        return true_sites(self.env.unwrapped) + _SHIFT_M


def test_the_observed_site_is_the_estimate_and_its_error_is_recorded() -> None:
    """The observation's site is the estimator's for the episode's site; info carries its distance in mm."""
    env = sim.envs.make("multisite")
    estimator = ShiftedTruth(env)
    perceived = PerceivedTask(env, estimator)
    try:
        for seed in range(3):
            observation, info = perceived.reset(seed=seed)
            task: Any = env.unwrapped
            expected = true_sites(task)[SITE_NAMES.index(task.site)] + _SHIFT_M
            np.testing.assert_allclose(observation["observation"][8:11], expected, atol=1e-6)
            assert info["site_error_mm"] == pytest.approx(1000 * np.linalg.norm(_SHIFT_M), abs=1e-6)
        assert estimator.frames[0].left.shape == (48, 64, 3)  # rendered by the estimator's endoscope
        assert not np.array_equal(estimator.frames[0].left, estimator.frames[1].left)
    finally:
        perceived.close()


def test_the_appearance_is_seeded_by_the_episode() -> None:
    """The same episode seed shows the estimator the same images."""
    env = sim.envs.make("lift")
    estimator = ShiftedTruth(env)
    perceived = PerceivedTask(env, estimator)
    try:
        perceived.reset(seed=4)
        perceived.reset(seed=4)
    finally:
        perceived.close()
    np.testing.assert_array_equal(estimator.frames[0].left, estimator.frames[1].left)


def test_an_inked_estimator_inks_the_flap() -> None:
    """An estimator trained on inked sites gets frames of an inked flap."""
    env = sim.envs.make("lift")
    PerceivedTask(env, ShiftedTruth(env, mark_sites=True))
    try:
        assert env.unwrapped.config.tissue.mark_sites
    finally:
        env.close()


def test_evaluation_summaries_carry_the_site_error() -> None:
    """run_episode records site_error_mm and summarize gives its median, p95 and max."""
    env = sim.envs.make("lift")
    perceived = PerceivedTask(env, ShiftedTruth(env))
    try:
        results = [run_episode(perceived, lambda _: np.zeros(5), lambda: None, seed) for seed in (1, 2)]
    finally:
        perceived.close()
    summary = summarize(results, 1.0)
    assert summary["site_error_mm"]["median"] == pytest.approx(1000 * np.linalg.norm(_SHIFT_M), abs=1e-6)
    assert set(summary["site_error_mm"]) == {"median", "p95", "max"}
