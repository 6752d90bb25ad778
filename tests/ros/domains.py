"""ROS domain ids of this test process: each pytest-xdist worker has a block of its own.

A run of the suite draws one base id (from the xdist run's id, which all its workers share, or from the
process id without xdist) and splits the 100 usable domains into one block per worker, so two workers of
one run can never meet on a domain. Within its block a worker's tests pick fixed offsets: 0 is the
worker's own domain (the ``ros_env`` of every test), the dVRK client's servers take the last
:data:`CLIENT_SLOTS` (:func:`client_domain_id`), the one before them is for a program that commands an arm
under a shared node name (:func:`commander_domain_id`), the one before that for the documented rehearsal
(:func:`page_domain_id`) and the fault matrix takes the ones between (:func:`fault_domain_id`). No offset
wraps onto another kind's: a fault's server can never share the domain of a test's own sim-dvrk.
"""

from __future__ import annotations

import os

from hardware_if.common.network import run_domain_id

#: The worker's own domain, at the start of its block.
OWN_OFFSET = 0
#: Domains at the end of each block for the dVRK client's servers.
CLIENT_SLOTS = 7

#: Usable domain ids (1..100), as :func:`hardware_if.common.network.run_domain_id` draws them.
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


def client_domain_id(slot: int) -> int:
    """The domain of the dVRK client's server ``slot`` (0 .. :data:`CLIENT_SLOTS` - 1)."""
    if not 0 <= slot < CLIENT_SLOTS:
        raise ValueError(f"client slot {slot} outside 0..{CLIENT_SLOTS - 1}")
    return worker_domain_id(block_size() - CLIENT_SLOTS + slot)


def fault_domain_id(index: int) -> int:
    """A domain of the fault matrix for ``index`` (any integer): between the own domain and the client's.

    Faults run one at a time on a worker, so indices that share a domain (the block has fewer fault domains
    than the matrix has faults and retries) never meet on it.
    """
    slots = block_size() - CLIENT_SLOTS - 3
    return worker_domain_id(1 + index % slots)


def commander_domain_id() -> int:
    """The domain of a test whose program commands an arm under a node name others share (``bench ros``'s
    ``/psm1_client``).

    Such a node can stay in the DDS graph for a while after its process ends. On the worker's own domain a
    later deploy would then see it as another commander of the arm, and hold (measured once in a full run).
    """
    return worker_domain_id(block_size() - CLIENT_SLOTS - 1)


def page_domain_id() -> int:
    """The domain of the rehearsal a documentation page shows, run as written: a fresh console of its own, where
    no node of an earlier test (a deploy, a fault's injector) can linger."""
    return worker_domain_id(block_size() - CLIENT_SLOTS - 2)
