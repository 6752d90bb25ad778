"""Loopback-only ROS 2 for the tests: set before rclpy is imported, and rclpy is required.

Every test of this folder talks real rclpy over loopback DDS, on a domain id of this test process's own
(``domains.py``: each pytest-xdist worker has a block of domains), with discovery limited to localhost
and UDPv4 only. rclpy is imported here at module level on purpose: without the ``ros`` extra these
tests fail at collection instead of being skipped.
"""

from __future__ import annotations

import os

from domains import worker_domain_id

from hardware_if.common.network import apply_local_ros_env

DOMAIN_ID = worker_domain_id()
apply_local_ros_env(DOMAIN_ID)

import pytest  # noqa: E402
import rclpy  # noqa: E402, F401  (must import: the ros extra is part of `make test`)


def pytest_configure(config: pytest.Config) -> None:
    """lark-parser, a ROS dependency, raises DeprecationWarnings: they are not this project's."""
    config.addinivalue_line("filterwarnings", "ignore::DeprecationWarning:lark.*")


@pytest.fixture(scope="session")
def ros_env() -> dict[str, str]:
    """The environment for child processes: this run's domain, loopback discovery, UDPv4."""
    return dict(os.environ)
