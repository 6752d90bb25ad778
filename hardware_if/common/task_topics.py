"""The topics a task is seen on besides the arm's own: the simulated scene's and the endoscope's.

The simulated console publishes both and a client subscribes to them, so their names live here, below
both: :data:`TASK_TOPICS` under ``/<arm>/task/`` (the simulation's ground truth, which a perception node
would supply on a real robot), and a stereo rig's images and camera info as the dVRK's video pipeline
names them (:func:`camera_topics`).
"""

from __future__ import annotations

__all__ = ["DEFAULT_RIG", "TASK_TOPICS", "camera_topics", "task_topic"]

#: Simulation-only topics under ``/<arm>/task/`` (a perception node's job on a real robot).
TASK_TOPICS = {
    "site": "geometry_msgs/PointStamped: the grasp site on the flap, in <arm>_base [m]",
    "goal": "geometry_msgs/PointStamped: the desired goal (where the site must go), in <arm>_base [m]",
    "achieved_goal": "geometry_msgs/PointStamped: the task's achieved goal, in <arm>_base [m]",
    "grasped": "std_msgs/Bool: the jaw holds the flap",
    "reset": "std_msgs/Int64 (subscribed): rebuild the scene with this seed (a new episode)",
    "resets": "std_msgs/Int64: how many resets the scene has done (a client knows its reset took effect)",
}


def task_topic(arm: str, name: str) -> str:
    """The fully qualified name of a simulation-only task topic, e.g. ``/PSM1/task/site``."""
    if name not in TASK_TOPICS:
        raise KeyError(f"unknown task topic {name!r}; one of {', '.join(TASK_TOPICS)}")
    return f"/{arm}/task/{name}"


#: The dVRK video pipeline's default stereo rig name (``dvrk_video``'s launch files).
DEFAULT_RIG = "jhu_daVinci"


def camera_topics(rig: str) -> dict[str, str]:
    """Topic names of a stereo rig: ``left_image``, ``right_image``, ``left_info``, ``right_info``."""
    return {
        f"{side}_{kind}": f"/{rig}/{side}/{name}"
        for side in ("left", "right")
        for kind, name in (("image", "image_raw"), ("info", "camera_info"))
    }
