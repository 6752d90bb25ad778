"""Property tests: no action, however bad, makes the chain send an unsafe command."""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from psm_control.commands import CartesianDelta, MeasuredState
from safety.chain import ControlChain
from safety.config import SafetyConfig

_CONFIG = SafetyConfig()
_CHAIN = ControlChain(_CONFIG)
_TICKS_PER_EXAMPLE = 1000
_TOLERANCE = 1e-6


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


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(actions=action_strategy, stale_from=st.integers(0, 1500), spikes=st.floats(0.0, 20.0))
def test_no_command_violates_a_hard_limit(actions: list, stale_from: int, spikes: float) -> None:
    """Under random, NaN, oscillating, force-spike and stale input every command meets every hard limit."""
    chain = _CHAIN
    spec = _CONFIG.spec
    dt = chain.control_period_s
    backend = KinematicBackend(chain.model.home(), dt)
    chain.reset(backend.measure())
    deltas = _actions(actions)
    previous = [chain.model.home()] * 3
    box_lo = np.asarray(_CONFIG.workspace_min_m) - 1e-3
    box_hi = np.asarray(_CONFIG.workspace_max_m) + 1e-3
    for k in range(_TICKS_PER_EXAMPLE):
        stale = stale_from <= k < stale_from + 100
        spike = spikes if k % 97 == 0 else 0.0
        measured = backend.measure(stale=stale, spike=spike)
        if k % 50 == 0:
            chain.set_target(deltas[(k // 50) % len(deltas)], measured)
        out = chain.tick(measured)
        q = out.command.q
        assert np.all(q >= spec.lower - _TOLERANCE) and np.all(q <= spec.upper + _TOLERANCE)
        assert q[2] >= spec.rcm.min_insertion_m - _TOLERANCE
        tip = chain.model.configuration(q).measured_pose()[:3, 3] if k % 10 == 0 else None
        if tip is not None:
            assert np.all(tip >= box_lo) and np.all(tip <= box_hi)
        if not out.safety_stop or not out.reason.startswith(("verifier", "internal")):
            v = (q - previous[-1]) / dt
            assert np.all(np.abs(v) <= _CONFIG.velocity * (1 + 1e-6) + 1e-6)
        previous = [*previous[1:], q.copy()]
        backend.q, backend.qd = q.copy(), out.command.qd.copy()
        backend.t += dt
        backend.force = np.zeros(3)
