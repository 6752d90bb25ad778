"""The validated training configuration."""

from __future__ import annotations

import pytest

from policies.config import TrainConfig
from psm_control.errors import ConfigurationError


def test_defaults_are_the_papers() -> None:
    """Defaults: 3 x 128 (DEX 4 x 256), lr 1e-3 (SQIL 1e-4), HER 0.8, Q-filter in DDPGBC only, CoL 2,000 BC steps."""
    ddpg = TrainConfig()
    assert ddpg.hidden == (128, 128, 128) and ddpg.lr_actor == ddpg.lr_critic == 1e-3
    assert (ddpg.gamma, ddpg.tau, ddpg.batch_size, ddpg.buffer_size, ddpg.random_steps) == (
        0.99,
        0.005,
        128,
        100_000,
        1000,
    )
    assert ddpg.updates_per_episode == 40 and ddpg.her_probability == pytest.approx(0.8)
    assert (ddpg.norm_clip, ddpg.norm_eps, ddpg.obs_clip, ddpg.noise_std) == (5.0, 0.01, 200.0, 0.1)
    assert TrainConfig(algo="dex").hidden == (256, 256, 256, 256)
    assert TrainConfig(algo="sqil").lr_actor == 1e-4 and TrainConfig(algo="sqil").sac_init_temperature == 0.1
    assert TrainConfig(algo="ddpgbc").use_q_filter and not TrainConfig(algo="col").use_q_filter
    assert TrainConfig(algo="col").pretrain_steps == 2000 and TrainConfig(algo="ddpgbc").pretrain_steps == 0
    assert TrainConfig(algo="ddpgbc").bc_weight == 5.0 and TrainConfig(algo="dex").dex_k == 5


@pytest.mark.parametrize(
    ("field", "value", "allowed"),
    [
        ("gamma", 1.0, "[0, 1)"),
        ("tau", 0.0, "(0, 1]"),
        ("batch_size", 0, ">= 1"),
        ("her_k", -1, ">= 0"),
        ("norm_clip", float("nan"), "(0, inf]"),
        ("hidden_sizes", (64, 0), "positive integers"),
        ("algo", "ppo", "'ddpg'"),
    ],
)
def test_invalid_values_name_the_field_and_range(field: str, value: object, allowed: str) -> None:
    """An invalid value raises ConfigurationError naming the field and what is allowed."""
    with pytest.raises(ConfigurationError) as info:
        TrainConfig(**{field: value})  # type: ignore[arg-type]
    assert info.value.field == field
    assert field in str(info.value) and allowed in str(info.value)


def test_round_trips_through_dict() -> None:
    """to_dict -> from_dict gives an equal configuration; unknown keys are refused."""
    config = TrainConfig(algo="dex", hidden_sizes=(32, 32), bc_weight=2.0)
    assert TrainConfig.from_dict(config.to_dict()) == config
    with pytest.raises(ConfigurationError):
        TrainConfig.from_dict({"lerning_rate": 1})
