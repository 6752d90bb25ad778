"""Safety limits of the filter: one rule per class, each returning its rows ``(G, h)``."""

from safety.limits.joint_acceleration import JointAccelerationLimit
from safety.limits.joint_position import JointPositionLimit
from safety.limits.joint_velocity import JointVelocityLimit
from safety.limits.limit import FilterState, Limit, LimitReport
from safety.limits.rcm_insertion import RcmInsertionLimit
from safety.limits.retraction_force import RetractionForceLimit, may_hold_tissue
from safety.limits.workspace_box import WorkspaceBoxLimit

__all__ = [
    "FilterState",
    "JointAccelerationLimit",
    "JointPositionLimit",
    "JointVelocityLimit",
    "Limit",
    "LimitReport",
    "RcmInsertionLimit",
    "RetractionForceLimit",
    "WorkspaceBoxLimit",
    "may_hold_tissue",
]
