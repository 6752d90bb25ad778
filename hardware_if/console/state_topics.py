"""The simulated console's periodic state topics: what one tick publishes of the arm, for its subscribers.

:class:`StateTopics` publishes ``measured_js`` (with joint efforts), ``setpoint_js``, ``measured_cp``/
``setpoint_cp`` and their ``local/`` versions, ``measured_cv``, ``local/measured_cv``, ``body/`` and
``spatial/measured_cf``, ``body/`` and ``spatial/jacobian``, ``jaw/measured_js`` and ``jaw/setpoint_js``,
each from the values the console hands it. Only topics with a subscriber are computed and sent.
"""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import PoseStamped, TwistStamped, WrenchStamped  # type: ignore[import-untyped]
from rclpy.node import Node
from sensor_msgs.msg import JointState  # type: ignore[import-untyped]
from std_msgs.msg import Float64MultiArray, MultiArrayDimension  # type: ignore[import-untyped]

from hardware_if.common import convert
from hardware_if.common.crtk import JAW_JOINT_NAME, JOINT_NAMES, ArmTopics, periodic_qos
from hardware_if.console.arm_model import ArmSample
from hardware_if.console.stamp_fault import StampFault
from psm_control.robot import PsmConfiguration

__all__ = ["StateTopics"]


class StateTopics:
    """The periodic state topics of one arm, published on a console's node.

    Args:
        node: The console's node.
        topics: The arm's topic names.

    Attributes:
        stamp_fault: What becomes of each ``measured_js`` once an injected clock fault starts (None: nothing).
    """

    def __init__(self, node: Node, topics: ArmTopics) -> None:
        self.topics = topics
        self.stamp_fault: StampFault | None = None
        state = periodic_qos()
        t = topics.topic
        create = node.create_publisher
        self._pub = {
            name: create(JointState, t(name), state)
            for name in ("measured_js", "setpoint_js", "jaw/measured_js", "jaw/setpoint_js")
        }
        for name in ("measured_cp", "setpoint_cp", "local/measured_cp", "local/setpoint_cp"):
            self._pub[name] = create(PoseStamped, t(name), state)
        for name in ("body/measured_cf", "spatial/measured_cf"):
            self._pub[name] = create(WrenchStamped, t(name), state)
        for name in ("measured_cv", "local/measured_cv"):
            self._pub[name] = create(TwistStamped, t(name), state)
        for name in ("body/jacobian", "spatial/jacobian"):
            self._pub[name] = create(Float64MultiArray, t(name), state)

    def subscribed(self, name: str) -> bool:
        """Whether any subscriber is matched on a state topic: a message for nobody is neither built nor sent.

        At 1 kHz, building and publishing the 14 state topics took most of the console's time, and a client
        typically reads half of them. A subscriber that connects gets the next period's message.
        """
        return bool(self._pub[name].get_subscription_count() > 0)

    def publish_arm_joints(
        self,
        stamp: float,
        sample: ArmSample,
        efforts: np.ndarray,
        setpoint_q: np.ndarray,
        setpoint_effort: np.ndarray,
        *,
        effort_mode: bool,
    ) -> None:
        """The arm's ``measured_js`` (``efforts``, plus the commanded ``setpoint_effort`` in effort mode) and
        ``setpoint_js``."""
        if self.subscribed("measured_js"):
            # Joint efforts: what the motors exert against the force on the tool (J^T f) and what the console
            # does not model (the console's sensor), plus a commanded effort in effort mode. measured_cf is
            # computed from them the other way round, as the console does.
            effort = efforts
            if effort_mode:
                effort = effort + setpoint_effort
            message = convert.joint_state(JOINT_NAMES, sample.q, sample.qd, effort, stamp_s=stamp)
            if self.stamp_fault is not None:
                message = self.stamp_fault.measured(message)
            self._pub["measured_js"].publish(message)
        if self.subscribed("setpoint_js"):
            self._pub["setpoint_js"].publish(
                convert.joint_state(JOINT_NAMES, setpoint_q, effort=setpoint_effort, stamp_s=stamp)
            )

    def publish_jaw(self, stamp: float, sample: ArmSample, setpoint_jaw: float) -> None:
        """``jaw/measured_js`` and ``jaw/setpoint_js``."""
        if self.subscribed("jaw/measured_js"):
            self._pub["jaw/measured_js"].publish(
                convert.joint_state(
                    (JAW_JOINT_NAME,), [sample.jaw], [sample.jaw_velocity], [sample.jaw_effort], stamp_s=stamp
                )
            )
        if self.subscribed("jaw/setpoint_js"):
            self._pub["jaw/setpoint_js"].publish(convert.joint_state((JAW_JOINT_NAME,), [setpoint_jaw], stamp_s=stamp))

    def publish_poses_and_force(
        self,
        stamp: float,
        configuration: PsmConfiguration,
        sample: ArmSample,
        setpoint_q: np.ndarray,
        sensed_force: np.ndarray,
    ) -> None:
        """The Cartesian topics at the set-point and measured joints (``configuration`` is moved to them), the
        force the console senses, the Jacobians and the velocities."""
        base_id, local_id = self.topics.base_frame_id, self.topics.local_frame_id
        wanted = {name for name in _MEASURED_TOPICS + _SETPOINT_TOPICS if self.subscribed(name)}
        if wanted & set(_SETPOINT_TOPICS):
            configuration.update(setpoint_q, sample.jaw)
            self._publish_pose(configuration, "setpoint", wanted, stamp)
        if not wanted & set(_MEASURED_TOPICS):
            return
        configuration.update(sample.q, sample.jaw)
        self._publish_pose(configuration, "measured", wanted, stamp)
        rotation = configuration.measured_pose()[:3, :3]
        if "spatial/measured_cf" in wanted:
            spatial = convert.wrench_stamped(sensed_force, frame_id=base_id, stamp_s=stamp)
            self._pub["spatial/measured_cf"].publish(spatial)
        if "body/measured_cf" in wanted:
            tip_id = f"{self.topics.arm}_tip"
            body = convert.wrench_stamped(rotation.T @ sensed_force, frame_id=tip_id, stamp_s=stamp)
            self._pub["body/measured_cf"].publish(body)
        if not wanted & {"spatial/jacobian", "body/jacobian", "measured_cv", "local/measured_cv"}:
            return
        local_jacobian = configuration.local_jacobian()
        spatial_jacobian = configuration.base_jacobian()
        if "spatial/jacobian" in wanted:
            self._pub["spatial/jacobian"].publish(_matrix_message(spatial_jacobian))
        if "body/jacobian" in wanted:
            body_jacobian = np.vstack([rotation.T @ spatial_jacobian[:3], rotation.T @ spatial_jacobian[3:]])
            self._pub["body/jacobian"].publish(_matrix_message(body_jacobian))
        if "measured_cv" in wanted:
            self._pub["measured_cv"].publish(_twist_stamped(spatial_jacobian @ sample.qd, base_id, stamp))
        if "local/measured_cv" in wanted:
            self._pub["local/measured_cv"].publish(_twist_stamped(local_jacobian @ sample.qd, local_id, stamp))

    def _publish_pose(self, configuration: PsmConfiguration, prefix: str, wanted: set[str], stamp: float) -> None:
        """``<prefix>_cp`` and ``local/<prefix>_cp`` at the configuration's joints, those subscribed."""
        if f"local/{prefix}_cp" in wanted:
            local = convert.pose_stamped(configuration.local_pose(), self.topics.local_frame_id, stamp)
            self._pub[f"local/{prefix}_cp"].publish(local)
        if f"{prefix}_cp" in wanted:
            pose = convert.pose_stamped(configuration.measured_pose(), self.topics.base_frame_id, stamp)
            self._pub[f"{prefix}_cp"].publish(pose)


#: State topics computed at the measured joints.
_MEASURED_TOPICS = (
    "measured_cp",
    "local/measured_cp",
    "body/measured_cf",
    "spatial/measured_cf",
    "body/jacobian",
    "spatial/jacobian",
    "measured_cv",
    "local/measured_cv",
)
#: State topics computed at the set-point joints.
_SETPOINT_TOPICS = ("setpoint_cp", "local/setpoint_cp")


def _matrix_message(matrix: np.ndarray) -> Float64MultiArray:
    """A row-major ``std_msgs/Float64MultiArray`` of a 2-D array, as the dVRK publishes its Jacobians."""
    rows, columns = matrix.shape
    message = Float64MultiArray()
    message.layout.dim = [
        MultiArrayDimension(label="rows", size=rows, stride=rows * columns),
        MultiArrayDimension(label="columns", size=columns, stride=columns),
    ]
    message.data = [float(v) for v in matrix.ravel()]
    return message


def _twist_stamped(twist: np.ndarray, frame_id: str, stamp_s: float) -> TwistStamped:
    """A ``geometry_msgs/TwistStamped`` from [linear (3); angular (3)]."""
    message = TwistStamped()
    message.header.stamp = convert.seconds_to_time(stamp_s)
    message.header.frame_id = frame_id
    linear, angular = message.twist.linear, message.twist.angular
    linear.x, linear.y, linear.z = (float(v) for v in twist[:3])
    angular.x, angular.y, angular.z = (float(v) for v in twist[3:])
    return message
