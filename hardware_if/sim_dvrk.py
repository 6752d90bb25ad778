"""The old path of the simulated console, kept for user scripts; the project imports from its room.

Its names now live in :mod:`hardware_if.console.sim_dvrk` and :mod:`hardware_if.console.console_arm`.
"""

from hardware_if.console.console_arm import HOMING_SETTLE_S, OPERATING_STATE_REPUBLISH_S
from hardware_if.console.sim_dvrk import SimulatedPsm

__all__ = ["HOMING_SETTLE_S", "OPERATING_STATE_REPUBLISH_S", "SimulatedPsm"]
