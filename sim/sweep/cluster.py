"""Connecting to Ray: the cluster at ``RAY_ADDRESS``, or a local one on loopback with no dashboard.

Ray is the ``dist`` extra, so it is imported only when a Ray backend is chosen.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from psm_control.errors import TissueRetractError

__all__ = ["RayNotAvailableError", "ray_cluster"]


class RayNotAvailableError(TissueRetractError):
    """The Ray backend was chosen but Ray is not installed."""


@contextmanager
def ray_cluster(jobs: int) -> Iterator[Any]:
    """Yield the ``ray`` module connected to a cluster, shutting down a cluster started here.

    Args:
        jobs: CPUs of a local cluster started here (ignored when ``RAY_ADDRESS`` names one, or Ray is
            already initialised in this process).

    Raises:
        RayNotAvailableError: Ray is not installed (the fix is named).
    """
    try:
        import ray  # the dist extra: optional, so imported only when a Ray backend is chosen
    except ImportError as e:
        raise RayNotAvailableError("the ray backend needs the 'dist' extra: pip install 'tissue-retract[dist]'") from e
    started_here = False
    if not ray.is_initialized():
        address = os.environ.get("RAY_ADDRESS")
        if address:
            ray.init(address=address, log_to_driver=False)
        else:
            # A local cluster on loopback only: without this variable Ray replaces 127.0.0.1 with the
            # machine's routable address and listens on every interface.
            os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
            os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
            ray.init(num_cpus=jobs, include_dashboard=False, _node_ip_address="127.0.0.1", log_to_driver=False)
        started_here = True
    try:
        yield ray
    finally:
        if started_here:
            ray.shutdown()
