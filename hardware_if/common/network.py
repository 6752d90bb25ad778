"""Where ROS 2 traffic may go: the loopback-only defaults for the simulated dVRK, dry runs and tests.

Fast DDS discovers peers by multicast on every interface by default. The simulated dVRK, dry runs and
the tests keep discovery on this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``), on a domain of
their own so that parallel runs do not see each other, over UDPv4 only. These variables are read when
rclpy initialises, so they must be in the environment before that: in a child process's environment, or
set by :func:`apply_local_ros_env` before the first ``import rclpy``. Nothing here imports rclpy.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, MutableMapping

from psm_control.errors import ConfigurationError

__all__ = ["MAX_DOMAIN_ID", "apply_local_ros_env", "environment_domain_id", "local_ros_env", "run_domain_id"]

#: Largest ROS_DOMAIN_ID that maps to valid UDP ports on Linux for every participant id.
MAX_DOMAIN_ID = 101


def environment_domain_id() -> int:
    """The domain id in ``$ROS_DOMAIN_ID``, or 0 (ROS 2's own default) when it is unset or not a number."""
    try:
        return int(os.environ.get("ROS_DOMAIN_ID", "0"))
    except ValueError:
        return 0


def run_domain_id(seed: int | None = None) -> int:
    """A domain id in 1..100 derived from ``seed`` (default: this process id), for one run's traffic."""
    value = os.getpid() if seed is None else seed
    return 1 + value % 100


def local_ros_env(domain_id: int, base: Mapping[str, str] | None = None) -> dict[str, str]:
    """Return ``base`` (default: ``os.environ``) with the loopback-only ROS 2 settings for ``domain_id``.

    Raises:
        ConfigurationError: ``domain_id`` is outside 0..101.
    """
    if not 0 <= domain_id <= MAX_DOMAIN_ID:
        raise ConfigurationError("domain_id", domain_id, f"an integer in 0..{MAX_DOMAIN_ID}")
    env = dict(os.environ if base is None else base)
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["FASTDDS_BUILTIN_TRANSPORTS"] = "UDPv4"
    env.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    # Static peers would add addresses beyond loopback; discovery stays automatic and local.
    env.pop("ROS_STATIC_PEERS", None)
    return env


def apply_local_ros_env(domain_id: int, environ: MutableMapping[str, str] | None = None) -> None:
    """Set the loopback-only settings in ``environ`` (default: ``os.environ``); call before rclpy starts."""
    target = os.environ if environ is None else environ
    target.update(local_ros_env(domain_id, base=target))
    target.pop("ROS_STATIC_PEERS", None)
