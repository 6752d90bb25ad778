"""The hook between the simulated dVRK and the PyBullet task scenes (tissue physics, tissue force).

``tissue-retract sim-dvrk --task ID`` asks :func:`task_arm_model` for an
:class:`~hardware_if.arm_model.ArmModel` that steps a task's scene and reports the tissue force.
"""

from __future__ import annotations

from hardware_if.arm_model import ArmModel
from psm_control.errors import NotBuiltError

__all__ = ["task_arm_model"]


def task_arm_model(task: str) -> ArmModel:
    """The arm model of a simulated task scene.

    Raises:
        NotBuiltError: The PyBullet task scenes are not wired to the simulated dVRK in this version.
    """
    raise NotBuiltError(
        f"--task {task!r}: serving a task's tissue scene is not available in this version yet; "
        "run sim-dvrk without --task for the kinematic arm (the dVRK's own KINEMATIC simulation)"
    )
