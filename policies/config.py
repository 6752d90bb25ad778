"""One validated configuration for every algorithm and the trainer.

The defaults are those of the algorithm code the seed paper used (see ``../shared/facts/seed-paper.md``
in the project's notes): they are documented field by field below and can be overridden by keyword.
Validation happens once, in :meth:`TrainConfig.__post_init__`; an error names the field and the range
that is allowed.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from psm_control.errors import ConfigurationError, UnknownVariantError

__all__ = ["ALGORITHMS", "PAPER_TASKS", "TrainConfig"]

#: The algorithms ``tissue-retract train --algo`` knows.
ALGORITHMS = ("ddpg", "sqil", "ddpgbc", "col", "dex")

#: The seed paper's Tasks I-III -> their Gymnasium ids (``tissue-retract reproduce --tasks``).
PAPER_TASKS = {"I": "TissueRetract-Lift-v0", "II": "TissueRetract-Target-v0", "III": "TissueRetract-MultiSite-v0"}


#: Largest network accepted (from --set or a checkpoint's header): a bound on what loading allocates.
MAX_HIDDEN_WIDTH = 4096
MAX_HIDDEN_LAYERS = 16


@dataclass(frozen=True)
class TrainConfig:
    """Hyperparameters of one training run.

    Attributes:
        algo: One of :data:`ALGORITHMS`.
        hidden_sizes: Hidden layer widths of actor and critic; ``None`` picks the algorithm's default
            (3 x 128 for DDPG-family and SQIL, 4 x 256 for DEX).
        gamma: Discount factor.
        tau: Polyak coefficient of the target networks (target <- (1 - tau) target + tau online).
        actor_lr: Adam learning rate of the actor; ``None``: 1e-3, or 1e-4 for SQIL.
        critic_lr: Adam learning rate of the critic; ``None``: 1e-3, or 1e-4 for SQIL.
        batch_size: Transitions per gradient update (and demonstration transitions per update).
        buffer_size: Capacity of the agent's replay buffer [transitions].
        random_steps: Uniformly random actions taken before the policy acts [env steps].
        updates_per_episode: Gradient updates after each collected episode.
        her_k: HER ``future`` strategy ratio; a goal is relabelled with probability 1 - 1 / (1 + k).
        action_l2: Weight of the mean squared action penalty in the actor loss.
        noise_std: Gaussian exploration noise, as a fraction of the maximum action.
        random_eps: Probability of a uniformly random action while exploring.
        obs_clip: Raw observations and goals are clipped to [-obs_clip, obs_clip].
        norm_clip: Normalised inputs are clipped to [-norm_clip, norm_clip].
        norm_eps: Smallest standard deviation the normaliser divides by.
        bc_weight: Weight of the behaviour-cloning (DDPGBC, CoL) or behaviour-gap (DEX) term.
        q_filter: Mask the BC term where the critic prefers the policy's action (DDPGBC).
        bc_pretrain_steps: Pure behaviour-cloning updates before RL starts (CoL).
        dex_k: Neighbours of the propagated expert action (DEX).
        sac_init_temperature: Initial entropy temperature of SAC (SQIL).
        sqil_demo_reward: Reward given to demonstration transitions (SQIL; agent transitions get 0).
    """

    algo: str = "ddpg"
    hidden_sizes: tuple[int, ...] | None = None
    gamma: float = 0.99
    tau: float = 0.005
    actor_lr: float | None = None
    critic_lr: float | None = None
    batch_size: int = 128
    buffer_size: int = 100_000
    random_steps: int = 1_000
    updates_per_episode: int = 40
    her_k: int = 4
    action_l2: float = 1.0
    noise_std: float = 0.1
    random_eps: float = 0.0
    obs_clip: float = 200.0
    norm_clip: float = 5.0
    norm_eps: float = 0.01
    bc_weight: float = 5.0
    q_filter: bool | None = None
    bc_pretrain_steps: int | None = None
    dex_k: int = 5
    sac_init_temperature: float = 0.1
    sqil_demo_reward: float = 1.0

    def __post_init__(self) -> None:
        if self.algo not in ALGORITHMS:
            raise UnknownVariantError("algo", self.algo, ALGORITHMS)
        if self.hidden_sizes is not None:
            sizes = tuple(self.hidden_sizes)
            widths_ok = all(
                isinstance(h, int) and not isinstance(h, bool) and 1 <= h <= MAX_HIDDEN_WIDTH for h in sizes
            )
            if not sizes or len(sizes) > MAX_HIDDEN_LAYERS or not widths_ok:
                raise ConfigurationError(
                    "hidden_sizes",
                    self.hidden_sizes,
                    f"1 to {MAX_HIDDEN_LAYERS} layer widths, positive integers up to {MAX_HIDDEN_WIDTH}",
                )
            object.__setattr__(self, "hidden_sizes", sizes)
        _in_range("gamma", self.gamma, 0.0, 1.0, low_open=False, high_open=True)
        _in_range("tau", self.tau, 0.0, 1.0, low_open=True, high_open=False)
        for name in ("actor_lr", "critic_lr"):
            value = getattr(self, name)
            if value is not None:
                _in_range(name, value, 0.0, 1.0, low_open=True, high_open=False)
        _int_at_least("batch_size", self.batch_size, 1, 65_536)
        _int_at_least("buffer_size", self.buffer_size, 1, 2_000_000)
        _int_at_least("random_steps", self.random_steps, 0)
        _int_at_least("updates_per_episode", self.updates_per_episode, 0)
        _int_at_least("her_k", self.her_k, 0)
        _in_range("action_l2", self.action_l2, 0.0, math.inf)
        _in_range("noise_std", self.noise_std, 0.0, math.inf)
        _in_range("random_eps", self.random_eps, 0.0, 1.0)
        _in_range("obs_clip", self.obs_clip, 0.0, math.inf, low_open=True)
        _in_range("norm_clip", self.norm_clip, 0.0, math.inf, low_open=True)
        _in_range("norm_eps", self.norm_eps, 0.0, math.inf, low_open=True)
        _in_range("bc_weight", self.bc_weight, 0.0, math.inf)
        if self.q_filter is not None and not isinstance(self.q_filter, bool):
            raise ConfigurationError("q_filter", self.q_filter, "True, False or None (the algorithm's default)")
        if self.bc_pretrain_steps is not None:
            _int_at_least("bc_pretrain_steps", self.bc_pretrain_steps, 0)
        _int_at_least("dex_k", self.dex_k, 1)
        _in_range("sac_init_temperature", self.sac_init_temperature, 0.0, math.inf, low_open=True)
        _in_range("sqil_demo_reward", self.sqil_demo_reward, -math.inf, math.inf)

    @property
    def hidden(self) -> tuple[int, ...]:
        """The hidden layer widths in effect."""
        if self.hidden_sizes is not None:
            return self.hidden_sizes
        return (256, 256, 256, 256) if self.algo == "dex" else (128, 128, 128)

    @property
    def lr_actor(self) -> float:
        """The actor's learning rate in effect."""
        return self.actor_lr if self.actor_lr is not None else (1e-4 if self.algo == "sqil" else 1e-3)

    @property
    def lr_critic(self) -> float:
        """The critic's learning rate in effect."""
        return self.critic_lr if self.critic_lr is not None else (1e-4 if self.algo == "sqil" else 1e-3)

    @property
    def use_q_filter(self) -> bool:
        """Whether the BC term is Q-filtered (DDPGBC by default; never CoL)."""
        return self.q_filter if self.q_filter is not None else self.algo == "ddpgbc"

    @property
    def pretrain_steps(self) -> int:
        """Behaviour-cloning updates before RL (CoL: 2,000 by default)."""
        if self.bc_pretrain_steps is not None:
            return self.bc_pretrain_steps
        return 2_000 if self.algo == "col" else 0

    @property
    def her_probability(self) -> float:
        """Probability that a sampled transition's goal is relabelled: 1 - 1 / (1 + k)."""
        return 1.0 - 1.0 / (1.0 + self.her_k)

    @property
    def uses_demos(self) -> bool:
        """Whether the algorithm learns from demonstrations."""
        return self.algo != "ddpg"

    def to_dict(self) -> dict[str, Any]:
        """The configuration as JSON-ready values."""
        out = dataclasses.asdict(self)
        if out["hidden_sizes"] is not None:
            out["hidden_sizes"] = list(out["hidden_sizes"])
        return out

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> TrainConfig:
        """Rebuild (and re-validate) a configuration from :meth:`to_dict` output."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ConfigurationError(unknown[0], values[unknown[0]], "one of the fields " + ", ".join(sorted(known)))
        kwargs = dict(values)
        if kwargs.get("hidden_sizes") is not None:
            kwargs["hidden_sizes"] = tuple(kwargs["hidden_sizes"])
        return cls(**kwargs)


def _in_range(
    name: str, value: object, low: float, high: float, *, low_open: bool = False, high_open: bool = False
) -> None:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(float(value))
    if ok:
        v = float(value)  # type: ignore[arg-type]
        ok = (v > low if low_open else v >= low) and (v < high if high_open else v <= high)
    if not ok:
        left = "(" if low_open else "["
        right = ")" if high_open else "]"
        raise ConfigurationError(name, value, f"a finite number in {left}{low:g}, {high:g}{right}")


def _int_at_least(name: str, value: object, low: int, high: int | None = None) -> None:
    if not isinstance(value, int) or isinstance(value, bool) or value < low or (high is not None and value > high):
        raise ConfigurationError(name, value, f"an integer >= {low}" + (f" and <= {high}" if high is not None else ""))
