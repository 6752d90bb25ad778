"""Actor and critic networks shared by every algorithm.

All networks take the normalised observation and goal, concatenated (``x``); critics also take the
action. Hidden layers are ReLU MLPs (3 x 128 for the DDPG family, 4 x 256 for DEX, as in the paper).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import nn
from torch.nn import functional as F  # noqa: N812 (the conventional name)

__all__ = ["MLP", "Critic", "DeterministicActor", "GaussianActor", "TwinCritic"]

#: Bounds of the SAC actor's log standard deviation (as in SAC's reference code).
LOG_STD_MIN, LOG_STD_MAX = -20.0, 2.0


class MLP(nn.Sequential):
    """A ReLU MLP with a linear output layer.

    A ``Sequential`` of ``Linear`` and ``ReLU`` modules (so parameters are named ``0.weight``,
    ``2.weight``, ...), whose forward pass applies the layers' weights directly instead of calling each
    submodule: with layers this small, the per-module call overhead is a large share of the arithmetic,
    and acting on a single observation takes half the time. The result is the same as ``Sequential``'s.
    """

    def __init__(self, in_dim: int, hidden: Sequence[int], out_dim: int) -> None:
        layers: list[nn.Module] = []
        last = in_dim
        for width in hidden:
            layers += [nn.Linear(last, width), nn.ReLU(inplace=True)]
            last = width
        layers.append(nn.Linear(last, out_dim))
        super().__init__(*layers)
        # A tuple, not a module attribute: the layers stay registered once, under their indices.
        self.linears: tuple[nn.Linear, ...] = tuple(m for m in layers if isinstance(m, nn.Linear))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        *hidden, output = self.linears
        for layer in hidden:
            x = torch.relu_(F.linear(x, layer.weight, layer.bias))
        return F.linear(x, output.weight, output.bias)


class DeterministicActor(nn.Module):
    """pi(x) in [-1, 1]^act_dim: the action as a fraction of the maximum action."""

    def __init__(self, in_dim: int, act_dim: int, hidden: Sequence[int]) -> None:
        super().__init__()
        self.net = MLP(in_dim, hidden, act_dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.tanh(self.net(x))


class Critic(nn.Module):
    """Q(x, a), one output per row."""

    def __init__(self, in_dim: int, act_dim: int, hidden: Sequence[int]) -> None:
        super().__init__()
        self.net = MLP(in_dim + act_dim, hidden, 1)

    def forward(self, x: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        return self.net(torch.cat((x, a), dim=-1))


class TwinCritic(nn.Module):
    """Two independent critics; SAC bootstraps from their minimum."""

    def __init__(self, in_dim: int, act_dim: int, hidden: Sequence[int]) -> None:
        super().__init__()
        self.q1 = Critic(in_dim, act_dim, hidden)
        self.q2 = Critic(in_dim, act_dim, hidden)

    def forward(self, x: torch.Tensor, a: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.q1(x, a), self.q2(x, a)


class GaussianActor(nn.Module):
    """A tanh-squashed Gaussian policy (SAC); its deterministic action is tanh(mean)."""

    def __init__(self, in_dim: int, act_dim: int, hidden: Sequence[int]) -> None:
        super().__init__()
        self.net = MLP(in_dim, hidden, 2 * act_dim)
        self.act_dim = act_dim

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """The deterministic action tanh(mean), so that deployment treats every actor alike."""
        return torch.tanh(self.net(x)[..., : self.act_dim])

    def sample(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """A reparameterised action and its log-probability (one per row)."""
        mean, log_std = self.net(x).split(self.act_dim, dim=-1)
        log_std = log_std.clamp(LOG_STD_MIN, LOG_STD_MAX)
        std = log_std.exp()
        noise = torch.randn_like(mean)
        u = mean + std * noise
        a = torch.tanh(u)
        log_prob = (-0.5 * noise.pow(2) - log_std - 0.5 * math.log(2 * math.pi)).sum(-1, keepdim=True)
        # Change of variables through tanh, in the numerically stable form 2 (log 2 - u - softplus(-2u)).
        log_prob -= (2.0 * (math.log(2.0) - u - nn.functional.softplus(-2.0 * u))).sum(-1, keepdim=True)
        return a, log_prob
