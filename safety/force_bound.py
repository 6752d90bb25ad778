"""What the force limit may take as the tissue force, with a sensor that is off by a known bound.

A dVRK PSM has no force sensor: its ``measured_cf`` is the motor currents through ``pinv(J^T)``, off by
newtons in free space (:mod:`sim.force_sensing` models it). The force limit keeps the *true* force
below its limit from two upper bounds, tick by tick, and uses the one that leaves more room:

* **measured**: the true force is within ``force_sensing_error_n`` of the measured one, so the filter keeps
  the measured force that far below the limit (the rows' margin). Usable when the error bound is below
  the limit; with an exact sensor (error 0) this is the filter as it always was.
* **travel**: from the moment the jaws closed, the held tissue cannot pull back harder than
  ``held_load_bound_n`` (its load at the grasp) plus ``tissue_stiffness_bound_n_per_m`` times the grasp
  point's travel since. The filter then limits that travel, as if the force were the bound's: no force
  measurement is used at all. The stiffness bound comes from the tissue's physical parameters
  (:func:`sim.force_sensing.tissue_bounds`: 2.64 x E t at the stiffest E and thickness of the range).

With an inexact sensor the tissue-stiffness estimate (:class:`safety.stiffness.StiffnessEstimator`) is not
used: its force increments would carry the sensing's pose- and motion-dependent error as stiffness. Both
bounds predict with the stiffness bound instead.

A limit below what the sensing resolves (error bound at or above the limit) is kept by the travel bound
alone, which stops a retraction after ``(limit - held load) / stiffness bound`` of travel:
:func:`sensing_warning` says so, with the numbers, at the start of every run.

A calibrated dVRK's error bound holds where its calibration saw the arm move (:class:`SensingRegime`): the
inertia it identified is known up to the joint accelerations of the logs it was fitted on, and its tight bound
was judged on held-out samples at retraction speeds only. On a tick whose commanded acceleration (the one the
calibration is given) is beyond those, or whose commanded tip speed is above the retraction speeds, the
measured force is trusted only to the calibration's wider bound, which takes the inertia as unknown up to the
chain's limits and was judged at every tip speed its logs reached. Faster than those, nothing judged the
force: it is not trusted at all (the travel bound keeps the limit while the jaws may hold tissue).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from safety.config import SafetyConfig
from safety.limits.retraction_force import CLOSED_JAW_RAD

__all__ = ["INSIDE", "OUTSIDE", "UNTRUSTED", "ForceBound", "ForceEstimate", "SensingRegime", "sensing_warning"]

#: How long an opened jaw may still hold tissue [s]: two policy steps at the tasks' 10 Hz.
RELEASE_S = 0.2
#: How long released tissue takes to settle back [s]: a grasp sooner counts the earlier grasp's travel.
RESETTLE_S = 1.0
#: Sources of a tick's force estimate.
MEASURED = "measured"
TRAVEL = "travel"
#: Where a tick is in a :class:`SensingRegime`.
INSIDE = "inside"
OUTSIDE = "outside"
UNTRUSTED = "untrusted"


class ForceEstimate(NamedTuple):
    """The force the filter takes for one tick.

    Attributes:
        force_n: The force the tool applies to the tissue (3,) [N], base axes.
        margin_n: How far the true force may exceed it [N]: the filter keeps this much below the limit.
        stiffness_n_per_m: The stiffness to predict a step's force with [N/m].
        source: ``measured`` or ``travel`` (see the module notes).
    """

    force_n: np.ndarray
    margin_n: float
    stiffness_n_per_m: float
    source: str


class SensingRegime(NamedTuple):
    """Where a force sensing's error bound holds (see the module notes).

    Attributes:
        covered_acceleration: Per joint, the largest acceleration magnitude the bound covers (6,) (rad/s^2;
            m/s^2 on the insertion; inf: no limit).
        error_outside_n: The error bound beyond them, and at tip speeds above ``retraction_tip_speed_m_s`` [N].
        retraction_tip_speed_m_s: The fastest tool-tip speed the bound covers [m/s] (inf: any).
        covered_tip_speed_m_s: The fastest tool-tip speed ``error_outside_n`` covers [m/s]; beyond it the force is
            not trusted (inf: any).
    """

    covered_acceleration: np.ndarray
    error_outside_n: float
    retraction_tip_speed_m_s: float = math.inf
    covered_tip_speed_m_s: float = math.inf

    def covers(self, qdd: np.ndarray) -> bool:
        """Whether the joint accelerations ``qdd`` (6,) are within the covered ones."""
        return bool(np.all(np.abs(np.asarray(qdd, dtype=float)) <= self.covered_acceleration))

    def where(self, qdd: np.ndarray | None, tip_speed_m_s: float | None) -> str:
        """Where a tick commanded with ``qdd`` at ``tip_speed_m_s`` [m/s] is (None: within the regime): :data:`INSIDE`,
        :data:`OUTSIDE` (beyond the covered accelerations or the retraction speeds: ``error_outside_n``) or
        :data:`UNTRUSTED` (faster than the covered tip speed, or a speed that is not a number)."""
        speed = 0.0 if tip_speed_m_s is None else float(tip_speed_m_s)
        if not speed <= self.covered_tip_speed_m_s:
            return UNTRUSTED
        if speed > self.retraction_tip_speed_m_s or (qdd is not None and not self.covers(qdd)):
            return OUTSIDE
        return INSIDE


class ForceBound:
    """Chooses, tick by tick, the bound on the true force that leaves the most room (see the module notes).

    The travel is counted from where the jaws closed, and the jaws may hold tissue from then until they
    have been open for :data:`RELEASE_S` (the simulation lets go at the end of the policy step in which
    the jaw opened; a real jaw while it opens). A grasp within :data:`RESETTLE_S` of a release counts its
    travel from the earlier grasp: the tissue it closes on may still be stretched by the earlier pull
    (measured in ``bench safety``: a policy that let go at 1.5 N and closed again 0.1 s later held 0.5 N
    at the new grasp, more than the held-load bound).

    Args:
        limit_n: The force limit [N].
        error_n: The force sensing's error bound [N] (0: exact).
        stiffness_bound_n_per_m: The tissue stiffness bound [N/m].
        held_load_bound_n: The held load at the grasp [N].
        period_s: The control period [s].
        regime: Where ``error_n`` holds (None: everywhere).
    """

    def __init__(
        self,
        limit_n: float,
        error_n: float,
        stiffness_bound_n_per_m: float,
        held_load_bound_n: float,
        period_s: float,
        regime: SensingRegime | None = None,
    ) -> None:
        self.limit_n = float(limit_n)
        self.error_n = float(error_n)
        self.stiffness_bound_n_per_m = float(stiffness_bound_n_per_m)
        self.held_load_bound_n = float(held_load_bound_n)
        self.period_s = float(period_s)
        self.regime = regime
        #: Ticks whose commanded acceleration or tip speed was beyond the regime (the wider bound taken), since
        #: construction.
        self.ticks_outside_regime = 0
        #: Ticks faster than any tip speed the regime covers (the force not trusted), since construction.
        self.ticks_untrusted = 0
        #: The error bound the last update trusted the measured force to [N].
        self.tick_error_n = self.error_n
        self.reset()

    @classmethod
    def from_config(cls, config: SafetyConfig) -> ForceBound:
        """The bound a safety configuration asks for."""
        return cls(
            config.effective_force_limit_n,
            config.force_sensing_error_n,
            config.tissue_stiffness_bound_n_per_m,
            config.held_load_bound_n,
            config.control_period_s,
        )

    @property
    def exact(self) -> bool:
        """The sensor is exact: the filter takes the measured force and the learned stiffness, as always."""
        return self.error_n == 0.0

    def reset(self) -> None:
        """A new episode: no grasp yet."""
        self._grasped_at: np.ndarray | None = None
        self._open_s = math.inf  # how long the jaws have been open
        #: The travel bound on the true force's magnitude at the last update [N]: the held-load bound plus the
        #: stiffness bound times the travel since the grasp. NaN while the jaws cannot hold tissue, and with an
        #: exact sensor. What ``bench safety`` holds the true force against, to check the tissue bounds.
        self.travel_bound_n = math.nan

    def update(
        self,
        jaw_rad: float,
        grasp_point_m: np.ndarray,
        measured_force_n: np.ndarray,
        learned_stiffness_n_per_m: float,
        commanded_qdd: np.ndarray | None = None,
        commanded_tip_speed_m_s: float | None = None,
    ) -> ForceEstimate:
        """The tick's estimate from the jaw, the grasp point (base frame) [m], the measured force [N], and the joint
        accelerations and tool-tip speed [m/s] the force was computed at (the last command's; None: within the
        regime). A force not trusted (:meth:`SensingRegime.where`) has an infinite margin: the filter then
        takes no contact from it, and the travel bound decides every tick the jaws may hold tissue."""
        if self.exact:
            return ForceEstimate(measured_force_n, 0.0, learned_stiffness_n_per_m, MEASURED)
        error_n = self.error_n
        if self.regime is not None:
            where = self.regime.where(commanded_qdd, commanded_tip_speed_m_s)
            if where == OUTSIDE:
                error_n = max(error_n, self.regime.error_outside_n)
                self.ticks_outside_regime += 1
            elif where == UNTRUSTED:
                error_n = math.inf
                self.ticks_untrusted += 1
        self.tick_error_n = error_n
        if jaw_rad < CLOSED_JAW_RAD:
            if self._grasped_at is None or self._open_s >= RESETTLE_S:
                self._grasped_at = np.array(grasp_point_m, dtype=float)
            self._open_s = 0.0
        else:
            self._open_s += self.period_s
        stiffness = self.stiffness_bound_n_per_m
        measured = ForceEstimate(measured_force_n, error_n, stiffness, MEASURED)
        if self._grasped_at is None or self._open_s >= RELEASE_S:
            self.travel_bound_n = math.nan
            return measured
        travel = stiffness * (np.asarray(grasp_point_m, dtype=float) - self._grasped_at)
        self.travel_bound_n = self.held_load_bound_n + math.sqrt(float(travel @ travel))
        measured_room = self.limit_n - error_n - math.sqrt(float(measured_force_n @ measured_force_n))
        travel_room = self.limit_n - self.travel_bound_n
        if measured_room >= travel_room:  # NaN in the measurement fails this: the travel bound needs none
            return measured
        return ForceEstimate(travel, self.held_load_bound_n, stiffness, TRAVEL)

    @property
    def holding(self) -> bool:
        """The jaws may hold tissue by the jaw alone: closed, or opened less than :data:`RELEASE_S` ago."""
        return not self.exact and self._grasped_at is not None and self._open_s < RELEASE_S

    def at_limit(self, limit_n: float) -> ForceBound:
        """The same bounds under another force limit [N] (a fresh episode)."""
        return ForceBound(
            limit_n, self.error_n, self.stiffness_bound_n_per_m, self.held_load_bound_n, self.period_s, self.regime
        )

    def travel_allowed_m(self) -> float:
        """How far the grasp point may travel from the grasp under the travel bound alone [m]."""
        return max(0.0, self.limit_n - self.held_load_bound_n) / self.stiffness_bound_n_per_m


def sensing_warning(
    config: SafetyConfig, sensing: str, *, calibrated: bool = False, limits_n: Sequence[float] | None = None
) -> str:
    """The run's warning when its force limit is below what the sensing resolves ('' when it is not).

    Args:
        config: The run's safety configuration.
        sensing: What the force comes from, for the message (``dvrk``, a calibration file, ...).
        calibrated: The force is calibrated already (then calibrating is not what the message advises).
        limits_n: The force limits a sweep runs (``tune-safety``'s grid) [N], in place of the configuration's
            one; the warning names those below the sensing's error bound and the travel each allows.
    """
    bound = ForceBound.from_config(config)
    if limits_n is not None and len(set(limits_n)) > 1:
        return _limits_warning(bound, sorted(set(limits_n)), sensing, calibrated)
    if limits_n is not None:
        bound = bound.at_limit(next(iter(limits_n)))
    if bound.exact or bound.error_n < bound.limit_n:
        return ""
    return (
        f"WARNING: force limit {bound.limit_n:g} N is below the force sensing's error bound "
        f"{bound.error_n:.2f} N ({sensing}): the measured force cannot tell the limit. The limit is kept "
        f"from the grasp point's travel since the grasp instead, assuming the held tissue is no stiffer than "
        f"{bound.stiffness_bound_n_per_m:g} N/m and loads the jaws by at most {bound.held_load_bound_n:.2f} N "
        f"when grasped: a retraction stops after {1000 * bound.travel_allowed_m():.1f} mm of travel. "
        f"What you can change: {'; '.join(_remedies(calibrated))}"
    )


def _limits_warning(bound: ForceBound, limits_n: list[float], sensing: str, calibrated: bool) -> str:
    """:func:`sensing_warning` for a sweep over several force limits ('' when the sensing resolves them all)."""
    below = [limit for limit in limits_n if not bound.exact and limit <= bound.error_n]
    if not below:
        return ""
    travels = [f"{1000 * bound.at_limit(limit).travel_allowed_m():.1f} mm at {limit:.3g} N" for limit in below]
    return (
        f"WARNING: {len(below)} of {len(limits_n)} force limits swept ({', '.join(f'{v:.3g}' for v in below)} N) "
        f"are below the force sensing's error bound {bound.error_n:.2f} N ({sensing}): under them the measured "
        "force cannot tell the limit. Each is kept from the grasp point's travel since the grasp instead, assuming "
        f"the held tissue is no stiffer than {bound.stiffness_bound_n_per_m:g} N/m and loads the jaws by at most "
        f"{bound.held_load_bound_n:.2f} N when grasped: a retraction stops after {', '.join(travels)} of travel. "
        f"They are swept and shown, and recommended only where the policy succeeds. What you can change: "
        f"{'; '.join(_remedies(calibrated))}"
    )


def _remedies(calibrated: bool) -> list[str]:
    """What a user can change when the sensing cannot tell the limit, for :func:`sensing_warning`."""
    return [
        *([] if calibrated else ["calibrate the force sensing (tissue-retract calibrate-wrench)"]),
        "declare the tissue's stiffness where it is known (tissue_stiffness_bound_n_per_m in a --safety-config "
        "file: 2.64 x the tissue's stiffest Young's modulus times its thickness; a sweep's --vary "
        "stiffness=LOW:HIGHx)",
        "or raise the limit if the tissue allows it",
    ]
