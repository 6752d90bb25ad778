"""The old path of :mod:`hardware_if.console.sim_dvrk`, kept for user scripts; the project imports from there."""

from hardware_if.console.sim_dvrk import HOMING_SETTLE_S, OPERATING_STATE_REPUBLISH_S, SimulatedPsm

__all__ = ["HOMING_SETTLE_S", "OPERATING_STATE_REPUBLISH_S", "SimulatedPsm"]
