"""Running episodes of a policy and summarising them: success, forces, events, failure classes.

The failure classes replace the paper's by-hand classification: an unsuccessful episode is labelled by
the most serious event it saw (``sim_unstable`` > ``safety_stop`` > ``invalid_action`` > ``tissue_damage``
> ``grip_loss`` > ``improper_grasp``), then ``force_limit_stall`` when the force limit held a retraction back
(the chain's stall warning), and ``timeout`` when none occurred. Success is scored at the final step, as in
the paper's evaluation.

The safety figures come from what the joints really did, step by step: ``joint_limit_violations``
counts steps with a joint outside the PSM's limits, ``workspace_violation_mm`` is the largest distance
of the tool tip outside the control chain's workspace box (about the RCM), ``min_insertion_margin_m``
the least insertion past the dVRK's 45 mm minimum, and ``safety_stops``/``interventions`` add up the
chain's stopped ticks and the constraints that changed a command (once per constraint and step).
"""

from __future__ import annotations

import functools
import math
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from psm_control.errors import ConfigurationError, TissueRetractError
from sim.success_interval import wilson_interval

__all__ = [
    "FAILURE_CLASSES",
    "EpisodeResult",
    "Policy",
    "PolicyError",
    "check_start_inside_workspace",
    "describe_exceedances",
    "describe_stalls",
    "failure_class",
    "force_limit_summary",
    "run_episode",
    "site_error_summary",
    "summarize",
]

FAILURE_CLASSES = (
    "none", "improper_grasp", "grip_loss", "tissue_damage", "safety_stop", "invalid_action", "force_limit_stall",
    "timeout", "sim_unstable",
)  # fmt: skip
_SEVERITY = ("sim_unstable", "safety_stop", "invalid_action", "tissue_damage", "grip_loss", "improper_grasp")

Policy = Callable[[dict[str, np.ndarray]], np.ndarray]


def failure_class(success: bool, event_steps: Mapping[str, int], *, stalled: bool) -> str:
    """An episode's failure class (one of :data:`FAILURE_CLASSES`; see the module's description).

    Args:
        success: The episode succeeded.
        event_steps: Steps on which each event of the severity order occurred (missing: none).
        stalled: The chain warned that the force limit stalled the retraction.
    """
    if success:
        return "none"
    return next((e for e in _SEVERITY if event_steps.get(e, 0)), "force_limit_stall" if stalled else "timeout")


class PolicyError(TissueRetractError):
    """The policy raised (anything, ``SystemExit`` included) during an episode: that episode's error.

    Attributes:
        seed: The episode's seed.
        step: The step at which the policy failed.
        cause: What the policy raised, as ``Type: message``.
    """

    def __init__(self, seed: int, step: int, error: BaseException) -> None:
        self.seed = seed
        self.step = step
        self.cause = f"{type(error).__name__}: {error}"
        super().__init__(f"the policy raised {self.cause} at step {step} of the episode with seed {seed}")


def _call_policy(function: Callable[[], Any], seed: int, step: int) -> Any:
    """Call a policy (or its reset); whatever it raises but Ctrl-C becomes a :class:`PolicyError`."""
    try:
        return function()
    except KeyboardInterrupt:
        raise
    except BaseException as e:
        raise PolicyError(seed, step, e) from e


@dataclass
class EpisodeResult:
    """One evaluated episode (the JSON ``episodes`` entries)."""

    seed: int
    success: bool
    steps: int
    peak_force_n: float  # the true tissue force; peak_measured_force_n is what the safety filter saw
    failure_class: str
    grip_losses: int
    tissue_damage: bool
    improper_grasps: int
    sim_unstable: bool
    final_exposure: float
    joint_limit_violations: int
    workspace_violation_mm: float
    min_insertion_margin_m: float
    safety_stops: int
    interventions: int
    invalid_actions: int = 0
    peak_measured_force_n: float = 0.0
    force_limit_n: float = float("nan")
    force_limit_exceeded: list[dict[str, Any]] = field(default_factory=list)
    force_limit_stall: list[dict[str, Any]] = field(default_factory=list)
    #: Distance of the site the policy observed at the start to the true site [mm] (None: the truth itself).
    site_error_mm: float | None = None
    #: Which of the shipped site estimators the default camera estimator took for the episode's flap
    #: (``pink`` or ``any-colour``; None: no such choice).
    site_estimator: str | None = None
    #: ``interventions`` by the constraint that changed the command (``joint_acceleration``, ...).
    intervention_kinds: dict[str, int] = field(default_factory=dict)
    #: The true force over the force bound's travel bound, at its largest (None: the travel bound was never
    #: in force: an exact sensor, or no grasp). Above 1, the tissue was stiffer or heavier than its bounds.
    peak_force_over_travel_bound: float | None = None

    @property
    def force_over_limit_s(self) -> float:
        """Time spent above the force limit [s]."""
        return float(sum(e["duration_s"] for e in self.force_limit_exceeded))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return asdict(self)


def run_episode(
    env: Any, policy: Policy, reset: Callable[[], None], seed: int, options: dict[str, Any] | None = None
) -> EpisodeResult:
    """Run one episode to its end and classify it (``options`` go to ``env.reset``).

    Raises:
        PolicyError: The policy (or its reset) raised; the episode has no result.
        ConfigurationError: The control chain's workspace box does not contain the task's start pose.
    """
    model = env.unwrapped.model
    minimum_insertion = model.spec.rcm.min_insertion_m
    observation, info = env.reset(seed=seed, options=options)
    check_start_inside_workspace(env, float(info["workspace_violation_m"]))
    site_error_mm = float(info["site_error_mm"]) if "site_error_mm" in info else None
    site_estimator = str(info["site_estimator"]) if "site_estimator" in info else None
    _call_policy(reset, seed, 0)
    counts = dict.fromkeys(_SEVERITY, 0)
    peak, steps, violations, stops, interventions = 0.0, 0, 0, 0, 0
    kinds: dict[str, int] = {}
    margin = float(info["insertion_m"]) - minimum_insertion
    outside_m = float(info["workspace_violation_m"])
    while True:
        action = _call_policy(functools.partial(policy, observation), seed, steps)
        observation, _, terminated, truncated, info = env.step(action)
        steps += 1
        peak = max(peak, float(info["force_peak_n"]))
        for event in _SEVERITY:
            counts[event] += int(bool(info[event]))
        q = np.asarray(info["q"])
        violations += int(np.any(q < model.lower - 1e-9) or np.any(q > model.upper + 1e-9))
        margin = min(margin, float(info["insertion_m"]) - minimum_insertion)
        outside_m = max(outside_m, float(info["workspace_violation_m"]))
        stops += int(info["safety_stops"])
        interventions += len(info["interventions"])
        for kind in info["interventions"]:
            kinds[str(kind)] = kinds.get(str(kind), 0) + 1
        if terminated or truncated:
            break
    success = bool(info["is_success"]) and not counts["sim_unstable"]
    failure = failure_class(success, counts, stalled=bool(info["force_limit_stall"]))
    return EpisodeResult(
        seed=seed,
        success=success,
        steps=steps,
        peak_force_n=peak,
        failure_class=failure,
        grip_losses=counts["grip_loss"],
        tissue_damage=counts["tissue_damage"] > 0,
        improper_grasps=counts["improper_grasp"],
        sim_unstable=counts["sim_unstable"] > 0,
        final_exposure=float(info["exposure"]),
        joint_limit_violations=violations,
        workspace_violation_mm=1000.0 * outside_m,
        min_insertion_margin_m=margin,
        safety_stops=stops,
        interventions=interventions,
        invalid_actions=counts["invalid_action"],
        peak_measured_force_n=float(info["measured_force_peak_n"]),
        force_limit_n=float(info["force_limit_n"]),
        force_limit_exceeded=list(info["force_limit_exceeded"]),
        force_limit_stall=list(info["force_limit_stall"]),
        site_error_mm=site_error_mm,
        site_estimator=site_estimator,
        intervention_kinds=dict(sorted(kinds.items())),
        peak_force_over_travel_bound=info["force_over_travel_bound_peak"],
    )


def check_start_inside_workspace(env: Any, outside_m: float) -> None:
    """Refuse a workspace box that excludes the tool tip's start pose: every command would be refused."""
    controller = getattr(env.unwrapped, "controller", None)
    config = getattr(controller, "config", None)
    if config is None or outside_m <= config.workspace_tolerance_m:
        return
    raise ConfigurationError(
        "workspace_min_m/workspace_max_m",
        f"{list(config.workspace_min_m)}/{list(config.workspace_max_m)}",
        f"a box containing the task's start tool-tip position (it lies {1000 * outside_m:.1f} mm outside; "
        "the default box is (-0.07, -0.07, -0.20) to (0.07, 0.07, -0.05) m about the RCM)",
    )


def summarize(results: Sequence[EpisodeResult], elapsed_s: float) -> dict[str, Any]:
    """The JSON ``summary``: success rate with its 95 % Wilson interval (``ci95``: [low, high]), forces, events."""
    n = len(results)
    if n == 0:
        raise ConfigurationError("episodes", 0, "at least one episode")
    successes = sum(bool(r.success) for r in results)
    steps = sum(r.steps for r in results)
    return {
        "success_rate": successes / n,
        "successes": successes,
        "ci95": list(wilson_interval(successes, n)),
        "episodes": n,
        "peak_force_n": float(max(r.peak_force_n for r in results)),
        "mean_peak_force_n": float(np.mean([r.peak_force_n for r in results])),
        "peak_measured_force_n": float(max(r.peak_measured_force_n for r in results)),
        "grip_losses": int(sum(r.grip_losses for r in results)),
        "tissue_damage": int(sum(r.tissue_damage for r in results)),
        "sim_unstable": int(sum(r.sim_unstable for r in results)),
        "env_steps_per_s": float(steps / elapsed_s) if elapsed_s > 0 else 0.0,
        "failure_classes": {c: sum(r.failure_class == c for r in results) for c in FAILURE_CLASSES},
        "joint_limit_violations": int(sum(r.joint_limit_violations for r in results)),
        "workspace_violation_mm": float(max(r.workspace_violation_mm for r in results)),
        "min_insertion_margin_m": float(min(r.min_insertion_margin_m for r in results)),
        "safety_stops": int(sum(r.safety_stops for r in results)),
        "invalid_actions": int(sum(r.invalid_actions for r in results)),
        "interventions": int(sum(r.interventions for r in results)),
        **force_limit_summary([r.to_dict() for r in results]),
        **site_error_summary(results),
    }


def site_error_summary(results: Sequence[EpisodeResult]) -> dict[str, Any]:
    """``site_error_mm`` (median, p95, max over the episodes) where the observed site was an estimate."""
    errors = [r.site_error_mm for r in results if r.site_error_mm is not None]
    if not errors:
        return {}
    values = np.asarray(errors)
    summary: dict[str, Any] = {
        "site_error_mm": {
            "median": float(np.median(values)),
            "p95": float(np.percentile(values, 95)),
            "max": float(values.max()),
        }
    }
    chosen = [r.site_estimator for r in results if r.site_estimator is not None]
    if chosen:  # how often the default estimator took each shipped one
        summary["site_estimator"] = {name: chosen.count(name) for name in sorted(set(chosen))}
    return summary


def force_limit_summary(episodes: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """How often, how long and how far the force went past its limit, where it held a retraction back, and how
    near the true force came to the travel bound (:mod:`safety.force_bound`) while that was in force.

    The records are :meth:`EpisodeResult.to_dict` entries, as evaluate keeps them and sweeps store them
    (a record from before the force was watched counts as none).
    """
    limits = [float(r.get("force_limit_n", math.nan)) for r in episodes]
    ratios = [float(r["peak_force_n"]) / limit for r, limit in zip(episodes, limits, strict=True) if limit > 0]
    excursions = [r.get("force_limit_exceeded") or () for r in episodes]
    stalls = [e for r in episodes for e in r.get("force_limit_stall") or ()]
    loads = [float(e["static_load_n"]) for e in stalls]
    load_ratios = [float(e["static_load_n"]) / float(e["limit_n"]) for e in stalls]
    travel = [
        float(r["peak_force_over_travel_bound"]) for r in episodes if r.get("peak_force_over_travel_bound") is not None
    ]
    return {
        "force_limit_n": max(limits, default=math.nan),
        "force_limit_exceeded": sum(len(e) for e in excursions),
        "episodes_over_force_limit": sum(bool(e) for e in excursions),
        "force_over_limit_s": float(sum(float(x["duration_s"]) for e in excursions for x in e)),
        "worst_peak_to_limit": max(ratios, default=math.nan),
        "force_limit_stalls": len(stalls),
        "stall_force_sources": dict(sorted(Counter(str(e.get("force_source", "measured")) for e in stalls).items())),
        "stall_static_load_n": float(np.median(loads)) if loads else math.nan,
        "stall_static_load_to_limit": max(load_ratios, default=math.nan),
        # None: the travel bound was never in force (an exact sensor, or nothing grasped).
        "worst_force_over_travel_bound": max(travel, default=None),
    }


def describe_exceedances(summary: dict[str, Any]) -> str:
    """``force_limit_exceeded`` of a summary in words: how often, in how many episodes, how long, how far."""
    count = summary["force_limit_exceeded"]
    if not count:
        return "never"
    return (
        f"{count} x in {summary['episodes_over_force_limit']} episode(s), {summary['force_over_limit_s']:.2f} s "
        f"in all, peak {summary['worst_peak_to_limit']:.2f} x the limit"
    )


def describe_stalls(summary: dict[str, Any]) -> str:
    """``force_limit_stall`` of a summary in words: in how many episodes, and what holding the tissue cost."""
    count = summary["force_limit_stalls"]
    if not count:
        return "never"
    sources = summary.get("stall_force_sources") or {}
    if sources and set(sources) == {"travel"}:
        what = "the travel bound on the held tissue's force, not a measured force (the sensing cannot tell the limit)"
    elif sources and "travel" in sources:
        what = (
            f"the held tissue's force, measured in {sources.get('measured', 0)} and bounded by its travel in "
            f"{sources['travel']} (the sensing cannot tell the limit there)"
        )
    else:
        what = "the measured force on the held tissue"
    return (
        f"in {count} episode(s): {what} was {summary['stall_static_load_n']:.3f} N (median), "
        f"up to {summary['stall_static_load_to_limit']:.2f} x the limit"
    )


def timed(function: Callable[[], Any]) -> tuple[Any, float]:
    """Call ``function`` and return its result with the wall time it took [s]."""
    start = time.perf_counter()
    result = function()
    return result, time.perf_counter() - start
