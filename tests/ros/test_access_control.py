"""Access control (SROS2 / DDS-Security) with the ROS 2 Jazzy wheels this project installs.

DDS-Security would let only the deploy's enclave publish the arm's command topics. The Fast DDS inside
the ``ros-jazzy`` PyPI wheels is built without its security plugins: asked to enforce security, it
refuses to create a node. This test checks that fact, which ``docs/one-commander.md`` states; when a
wheel with the plugins is installed, it fails, and ``--ros-enclave`` can then be built on it.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

SCRIPT = """
import rclpy
rclpy.init(args=["--ros-args", "--enclave", "/deploy"])
try:
    rclpy.create_node("secured")
    print("node created")
except Exception as e:
    print(f"refused: {e}")
"""


def test_enforced_security_is_refused_by_the_installed_fast_dds(ros_env: dict[str, str], tmp_path: Path) -> None:
    """ROS_SECURITY_ENABLE with Enforce: node creation fails, Fast DDS lacking its security libraries."""
    (tmp_path / "enclaves" / "deploy").mkdir(parents=True)
    env = {
        **ros_env,
        "ROS_SECURITY_KEYSTORE": str(tmp_path),
        "ROS_SECURITY_ENABLE": "true",
        "ROS_SECURITY_STRATEGY": "Enforce",
    }
    done = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=120)
    assert "refused:" in done.stdout and "doesn't have the security libraries" in done.stdout, done.stdout
