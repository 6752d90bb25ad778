"""A policy deployed through the control chain, to the simulation or to a dVRK over ROS 2, and recorded.

:func:`~hardware_if.deploy.run.deploy` runs the episodes and records them; a fault anywhere is a hold.

Imports: :mod:`hardware_if.client` (the dVRK target), :mod:`hardware_if.recording`,
:mod:`hardware_if.wrench` and :mod:`hardware_if.common`. Never the console: the simulation target runs the
task in-process, and a rehearsal against ``sim-dvrk`` goes through the client as a deploy to a dVRK does.

``hardware_if.deploy`` was one module before the rooms: its names are kept here for user scripts. The
project imports them from the modules that define them.
"""

from hardware_if.deploy.run import (
    EXIT_HOLD,
    EXIT_INTERRUPTED,
    STOP_SIGNALS,
    DeployOptions,
    DeployReport,
    Interrupted,
    deploy,
)

__all__ = ["EXIT_HOLD", "EXIT_INTERRUPTED", "STOP_SIGNALS", "DeployOptions", "DeployReport", "Interrupted", "deploy"]
