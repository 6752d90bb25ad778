"""ROS domain ids of this test process: each pytest-xdist worker has a block of its own.

A run of the suite draws one base id (from the xdist run's id, which all its workers share, or from the
process id without xdist) and splits the 100 usable domains into one block per worker, so two workers of
one run can never meet on a domain. Within its block a worker's tests pick fixed offsets: 0 is the
worker's own domain (the ``ros_env`` of every test), the fault matrix and the dVRK client's servers take
the others (:data:`FAULT_OFFSET`, :data:`CLIENT_OFFSET`).
"""

from __future__ import annotations

import os

from hardware_if.network import run_domain_id

#: Offsets within a worker's block: its own domain, then the fault matrix's servers, then the client's.
OWN_OFFSET = 0
FAULT_OFFSET = 1
CLIENT_OFFSET = 30

#: Usable domain ids (1..100), as :func:`hardware_if.network.run_domain_id` draws them.
DOMAINS = 100


def _worker() -> tuple[int, int]:
    """This worker's index and the number of workers (0 and 1 without xdist)."""
    name = os.environ.get("PYTEST_XDIST_WORKER", "")
    count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    return (int(name.removeprefix("gw")) if name.startswith("gw") else 0), max(count, 1)


def _run_seed() -> int:
    """One number per run of the suite: the xdist run id that all workers share, else this process id."""
    run_id = os.environ.get("PYTEST_XDIST_TESTRUNUID")
    return int(run_id, 16) if run_id else os.getpid()


def block_size() -> int:
    """How many domains each worker has."""
    return DOMAINS // _worker()[1]


def worker_domain_id(offset: int = OWN_OFFSET) -> int:
    """The domain id at ``offset`` in this worker's block (offsets wrap within the block)."""
    index, _ = _worker()
    size = block_size()
    base = run_domain_id(_run_seed()) - 1
    return 1 + (base + index * size + offset % size) % DOMAINS
