"""The force-limit watches on their own: excursions above the limit, and a retraction the limit stalls."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from safety.force_watch import FORCE_LIMIT_STALL, ForceLimitStallWatch, ForceLimitWatch

_PERIOD_S = 0.025
_WINDOW = 40  # ticks in the stall watch's 1 s window at 40 Hz


def test_each_excursion_has_its_start_duration_and_peak() -> None:
    """Two stretches above the limit are two excursions; the one still going on is reported open."""
    watch = ForceLimitWatch(1.0, _PERIOD_S)
    forces = [0.5, 1.2, 1.5, 0.9, 0.2, 1.1, 1.3]
    ended = [watch.update(np.array([0.0, 0.0, f]), i * _PERIOD_S) for i, f in enumerate(forces)]
    assert [e is not None for e in ended] == [False, False, False, True, False, False, False]
    first = watch.excursions[0]
    assert first.start_s == pytest.approx(_PERIOD_S) and first.duration_s == pytest.approx(2 * _PERIOD_S)
    assert first.peak_n == pytest.approx(1.5) and first.ratio == pytest.approx(1.5) and not first.open
    current = watch.all()[-1]
    assert current.open and current.peak_n == pytest.approx(1.3) and len(watch.all()) == 2
    assert watch.finish() is not None and len(watch.excursions) == 2 and not watch.above


def test_with_an_inexact_sensor_only_what_its_error_cannot_explain_is_an_excursion() -> None:
    """A dVRK's measured force is off by up to its error bound: 3 N over a 1 N limit with a 2.5 N bound could be
    a true 0.5 N, and is no excursion; 4 N is, and its excess and ratio are the least the true force had. The
    deploy's report says the limit was never exceeded beyond the bound, naming it."""
    from hardware_if.deploy.report import DeployReport

    watch = ForceLimitWatch(1.0, _PERIOD_S, error_n=2.5)
    for i, f in enumerate([3.0, 3.4, 4.0, 3.0]):
        watch.update(np.array([0.0, f, 0.0]), i * _PERIOD_S)
    (excursion,) = watch.all()
    assert excursion.duration_s == pytest.approx(_PERIOD_S) and excursion.peak_n == pytest.approx(4.0)
    assert excursion.excess_n == pytest.approx(0.5) and excursion.ratio == pytest.approx(1.5)
    assert excursion.to_event()["error_n"] == 2.5
    report = DeployReport("dvrk", False, Path("run.mcap"), force_limit_n=1.0, force_sensing_error_n=2.5)
    report.episodes.append({"episode": 0, "seed": 0, "steps": 1, "success": True, "peak_force_n": 4.0})
    assert "force limit 1 N: never exceeded beyond the force sensing's 2.50 N error bound" in "\n".join(report.lines())


def test_a_non_finite_force_counts_as_above_the_limit() -> None:
    """NaN is no evidence that the force is below the limit: it opens an excursion with an infinite peak."""
    watch = ForceLimitWatch(1.0, _PERIOD_S)
    watch.update(float("nan"), 0.0)
    assert watch.above and math.isinf(watch.all()[0].peak_n)


def _feed(
    watch: ForceLimitStallWatch, ticks: int, *, holding: bool = True, held_back: bool = True, allowed_m: float = 1e-4
) -> list[object]:
    """``ticks`` ticks, the force rising 1 mN a tick from 10 mN, the policy asking for 4 mm a tick."""
    return [
        watch.update(
            holding=holding,
            held_back=held_back,
            force_n=0.010 + 0.001 * i,
            asked_m=4e-3,
            allowed_m=allowed_m,
            stiffness_n_per_m=400.0,
            stamp_s=i * _PERIOD_S,
        )
        for i in range(ticks)
    ]


def test_a_crawl_held_back_for_a_second_is_one_stall_naming_the_load() -> None:
    """Held back on every tick at 4 mm/s: a stall at the window's end, once, with the last quarter's load."""
    watch = ForceLimitStallWatch(0.05, _PERIOD_S)
    seen = [s for s in _feed(watch, 3 * _WINDOW) if s is not None]
    assert len(seen) == 1 and seen[0] is watch.stall
    stall = watch.stall
    assert stall is not None
    # Loads 10..49 mN over the window; its last quarter is 40..49 mN, its first 10..19 mN.
    assert stall.static_load_n == pytest.approx(0.0445) and stall.load_rise_n == pytest.approx(0.030)
    assert stall.speed_m_s == pytest.approx(0.004) and stall.asked_speed_m_s == pytest.approx(0.16)
    assert stall.duration_s == pytest.approx(1.0) and stall.start_s == pytest.approx(0.0)
    event = stall.to_event()
    assert event["kind"] == FORCE_LIMIT_STALL
    assert "force limit 0.05 N stalls the retraction" in event["text"] and "0.045 N" in event["text"]
    assert "force_limit_n" in event["text"]  # says what to change
    watch.reset()
    assert watch.stall is None and sum(s is not None for s in _feed(watch, _WINDOW)) == 1


@pytest.mark.parametrize(
    ("why", "kwargs"),
    [
        ("the retraction still gets on (40 mm/s)", {"allowed_m": 1e-3}),
        ("no tissue in the jaws", {"holding": False}),
        ("the force limit did not cut the motion", {"held_back": False}),
    ],
)
def test_no_stall_without_all_its_signs(why: str, kwargs: dict[str, object]) -> None:
    """A stall needs tissue held, the limit cutting the motion and a crawl, all for the whole window."""
    watch = ForceLimitStallWatch(0.05, _PERIOD_S)
    assert all(s is None for s in _feed(watch, 3 * _WINDOW, **kwargs)), why  # type: ignore[arg-type]


def test_ticks_the_limit_lets_through_do_not_end_a_stall_but_many_do() -> None:
    """Up to a tenth of the window's ticks may pass unhindered (a relaxing force); a fifth may not."""
    for free_every, stalls in ((10, True), (5, False)):
        watch = ForceLimitStallWatch(0.05, _PERIOD_S)
        for i in range(3 * _WINDOW):
            watch.update(
                holding=True,
                held_back=i % free_every != 0,
                force_n=0.02,
                asked_m=4e-3,
                allowed_m=1e-4,
                stiffness_n_per_m=400.0,
                stamp_s=i * _PERIOD_S,
            )
        assert (watch.stall is not None) is stalls, free_every


def test_non_finite_motion_or_force_is_no_evidence_of_a_stall() -> None:
    """NaN forces are not counted as held-back ticks, and NaN motion never reads as a crawl."""
    watch = ForceLimitStallWatch(0.05, _PERIOD_S)
    for i in range(3 * _WINDOW):
        watch.update(
            holding=True, held_back=True, force_n=math.nan, asked_m=4e-3, allowed_m=1e-4,
            stiffness_n_per_m=400.0, stamp_s=i * _PERIOD_S,
        )  # fmt: skip
    assert watch.stall is None
    for i in range(3 * _WINDOW):
        watch.update(
            holding=True, held_back=True, force_n=0.02, asked_m=4e-3, allowed_m=math.nan,
            stiffness_n_per_m=400.0, stamp_s=i * _PERIOD_S,
        )  # fmt: skip
    assert watch.stall is None


def test_a_stall_is_found_on_the_tick_a_whole_window_sum_finds_it() -> None:
    """The window's motion kept as it slides reports each stall on the same tick as summing the window anew.

    Random motion around the crawl threshold, NaN now and then, over many windows and episodes: the watch
    must agree, tick for tick, with the plain definition (the window full, enough held-back ticks, no NaN
    motion, the motion summed over the window at most the crawl distance).
    """
    rng = np.random.default_rng(7)
    watch = ForceLimitStallWatch(1.0, _PERIOD_S)
    crawl_per_tick_m = watch._stall_distance_m / _WINDOW
    found = 0
    for _ in range(40):
        watch.reset()
        window: list[tuple[bool, float]] = []
        for i in range(6 * _WINDOW):
            allowed = float(rng.uniform(0.55, 1.6)) * crawl_per_tick_m if rng.random() > 0.01 else math.nan
            held_back = bool(rng.random() < 0.97)
            window = [*window, (held_back, allowed)][-_WINDOW:]
            expected = (
                len(window) == _WINDOW
                and sum(h for h, _ in window) >= watch._needed
                and sum(a for _, a in window) <= watch._stall_distance_m
            )
            was = watch.stall
            stall = watch.update(
                holding=True, held_back=held_back, force_n=0.9, asked_m=4e-3, allowed_m=allowed,
                stiffness_n_per_m=400.0, stamp_s=i * _PERIOD_S,
            )  # fmt: skip
            assert (stall is not None) == (was is None and expected), (i, window)
            if stall is not None:
                found += 1
                break
    assert 5 <= found <= 35  # the draws put some episodes on each side of the threshold
