"""The chain's compiled kernels are ready at import and are never compiled again inside a control tick."""

from __future__ import annotations

import numpy as np

from psm_control import active_set, boxqp
from psm_control.commands import CartesianDelta, MeasuredState
from safety import filter_kernels, halfspace
from safety.chain import ControlChain
from safety.config import SafetyConfig
from tissue_retract.cli import bench_chain

KERNELS = (
    active_set.kkt_residual,
    boxqp.solve_box_qp,
    filter_kernels.merge_bounds,
    filter_kernels.normalise_rows,
    filter_kernels.clip_and_count_violations,
    filter_kernels.assess,
    filter_kernels.solver_rows,
    filter_kernels.worst_row_violation,
    halfspace.project_onto_box_and_halfspace,
)


def test_every_kernel_is_compiled_once_at_import_and_reused_by_the_chain() -> None:
    before = {kernel.__name__: list(kernel.signatures) for kernel in KERNELS}
    assert all(len(signatures) == 1 for signatures in before.values()), before
    _, _, _, paths = bench_chain._run(False, 3000, 0)  # the benchmark's pulling input, with force feedback
    assert paths.solver > 0  # the active-set solver and its KKT check ran
    chain = ControlChain(SafetyConfig())
    q = chain.model.home()
    measured = MeasuredState(q, np.zeros(6), 0.0, np.zeros(3), 0.0)
    chain.reset(measured)
    for k, action in enumerate([(0.01, 0.0, 0.0), (np.nan, 0.0, 0.0), (0.0, 0.0, -0.01), (0.0, 0.01, 0.0)]):
        chain.set_target(CartesianDelta(np.array(action), 0.0, 0.0), measured)
        for _ in range(200):
            chain.tick(MeasuredState(q, np.zeros(6), 0.0, np.array([0.0, 0.0, 3.0 * k]), chain._stamp))
    after = {kernel.__name__: list(kernel.signatures) for kernel in KERNELS}
    assert after == before
