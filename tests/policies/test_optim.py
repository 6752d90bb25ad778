"""The agents' Adam takes exactly torch's fused Adam steps, through resumes and missing gradients."""

from __future__ import annotations

import torch
from torch import nn

from policies.algos.base import FusedAdam


def _steps(optimizer: torch.optim.Optimizer, nets: list[nn.Module], count: int, skip_second: bool) -> None:
    generator = torch.Generator().manual_seed(5)
    for i in range(count):
        x = torch.randn(32, 6, generator=generator)
        optimizer.zero_grad(set_to_none=True)
        used = nets[:1] if skip_second and i % 3 == 0 else nets
        sum(net(x).square().mean() for net in used).backward()  # type: ignore[misc]
        optimizer.step()


def test_fused_adam_matches_torch_adam_bit_for_bit() -> None:
    """Same parameters and state as Adam(fused=True), with per-group rates and gradient-less steps."""
    torch.manual_seed(0)
    reference_nets = [nn.Sequential(nn.Linear(6, 16), nn.ReLU(), nn.Linear(16, 3)) for _ in range(2)]
    nets = [nn.Sequential(nn.Linear(6, 16), nn.ReLU(), nn.Linear(16, 3)) for _ in range(2)]
    for net, ref in zip(nets, reference_nets, strict=True):
        net.load_state_dict(ref.state_dict())
    groups = [(0, 1e-3), (1, 3e-4)]
    reference = torch.optim.Adam(
        [{"params": list(reference_nets[i].parameters()), "lr": lr} for i, lr in groups], fused=True
    )
    optimizer = FusedAdam([{"params": list(nets[i].parameters()), "lr": lr} for i, lr in groups])

    _steps(reference, reference_nets, 10, skip_second=True)
    _steps(optimizer, nets, 10, skip_second=True)
    # A resumed optimiser gets fresh state tensors: the fast path must pick them up.
    resumed = FusedAdam([{"params": list(nets[i].parameters()), "lr": lr} for i, lr in groups])
    resumed.load_state_dict(optimizer.state_dict())
    _steps(reference, reference_nets, 5, skip_second=False)
    _steps(resumed, nets, 5, skip_second=False)

    for net, ref in zip(nets, reference_nets, strict=True):
        for p, q in zip(net.parameters(), ref.parameters(), strict=True):
            assert torch.equal(p, q)
    for (_, state), (_, ref_state) in zip(
        resumed.state_dict()["state"].items(), reference.state_dict()["state"].items(), strict=True
    ):
        for key in ("step", "exp_avg", "exp_avg_sq"):
            assert torch.equal(state[key], ref_state[key])
