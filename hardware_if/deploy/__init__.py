"""A policy deployed through the control chain, to the simulation or to a dVRK over ROS 2, and recorded.

:func:`~hardware_if.deploy.run.deploy` runs the episodes (:mod:`~hardware_if.deploy.sim_target`,
:mod:`~hardware_if.deploy.dvrk_target` and its :mod:`~hardware_if.deploy.dvrk_episode`) with what
:class:`~hardware_if.deploy.options.DeployOptions` asks, the policy's steps checked
(:mod:`~hardware_if.deploy.policy`), and says what happened in a
:class:`~hardware_if.deploy.report.DeployReport`; a fault anywhere is a hold, a stop signal stops between
two ticks (:mod:`~hardware_if.deploy.stopping`).

Imports: :mod:`hardware_if.client` (the dVRK target), :mod:`hardware_if.recording`,
:mod:`hardware_if.wrench` and :mod:`hardware_if.common`. Never the console: the simulation target runs the
task in-process, and a rehearsal against ``sim-dvrk`` goes through the client as a deploy to a dVRK does.

``hardware_if.deploy`` was one module before the rooms: its names are kept here for user scripts. The
project imports them from the modules that define them.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from hardware_if.deploy.options import DeployOptions
    from hardware_if.deploy.report import EXIT_FORCE_LIMIT, EXIT_HOLD, DeployReport
    from hardware_if.deploy.run import deploy
    from hardware_if.deploy.stopping import EXIT_INTERRUPTED, STOP_SIGNALS, Interrupted

__all__ = [
    "EXIT_FORCE_LIMIT",
    "EXIT_HOLD",
    "EXIT_INTERRUPTED",
    "STOP_SIGNALS",
    "DeployOptions",
    "DeployReport",
    "Interrupted",
    "deploy",
]

#: The module that defines each name. A name is imported on first use: importing one of the room's modules
#: (the options a command checks) runs this package first, and the runner loads the simulation and the policies.
_DEFINED_IN = {
    "DeployOptions": "options",
    "EXIT_FORCE_LIMIT": "report",
    "EXIT_HOLD": "report",
    "DeployReport": "report",
    "deploy": "run",
    "EXIT_INTERRUPTED": "stopping",
    "STOP_SIGNALS": "stopping",
    "Interrupted": "stopping",
}


def __getattr__(name: str) -> Any:
    """One of the room's names, from the module that defines it (PEP 562: only for a name not yet set)."""
    if name not in _DEFINED_IN:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_DEFINED_IN[name]}"), name)
