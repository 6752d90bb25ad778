"""SafetyConfig: defaults, presets, loading and validation errors that name the field."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from psm_control.errors import ConfigurationError
from safety.config import FORCE_PRESETS, SafetyConfig, load_safety_config


def test_default_force_limit_is_the_generic_preset() -> None:
    """Without an explicit force limit the tissue preset's value applies."""
    assert SafetyConfig().effective_force_limit_n == FORCE_PRESETS["generic"].force_limit_n
    assert SafetyConfig(tissue="liver").effective_force_limit_n == 1.75


@pytest.mark.parametrize(
    ("field", "value"),
    [("control_rate_hz", 10.0), ("min_insertion_m", 0.01), ("cbf_gamma", 2.0), ("force_limit_n", -1.0)],
)
def test_out_of_range_values_name_the_field(field: str, value: float) -> None:
    """A value outside its range raises ConfigurationError naming that field."""
    settings: dict[str, Any] = {field: value}
    with pytest.raises(ConfigurationError) as info:
        SafetyConfig(**settings)
    assert info.value.field == field


def test_toml_and_yaml_load_the_same_settings(tmp_path: Path) -> None:
    """TOML and YAML files with the same keys give equal configurations."""
    toml = tmp_path / "s.toml"
    toml.write_text('[safety]\ntissue = "bowel"\nworkspace_min_m = [-0.05, -0.05, -0.2]\n')
    yaml = tmp_path / "s.yaml"
    yaml.write_text("tissue: bowel\nworkspace_min_m: [-0.05, -0.05, -0.2]\n")
    assert load_safety_config(toml) == load_safety_config(yaml)


def test_unknown_key_is_refused(tmp_path: Path) -> None:
    """An unknown setting raises an error naming it."""
    path = tmp_path / "s.toml"
    path.write_text("force_limt_n = 2.0\n")
    with pytest.raises(ConfigurationError, match="force_limt_n"):
        load_safety_config(path)


def test_default_rate_is_the_dvrk_crtk_rate() -> None:
    """The default control rate is the dVRK's 100 Hz CRTK publishing rate."""
    assert SafetyConfig().control_rate_hz == 100.0
    assert SafetyConfig().control_period_s == pytest.approx(0.01)


@pytest.mark.parametrize("rate", [20.0, 60.0, 1000.0, 5000.0])
def test_rates_from_20_hz_to_5_khz_are_accepted(rate: float) -> None:
    """Every rate in [20, 5000] Hz is accepted with a deadman timeout of at least two periods."""
    config = SafetyConfig(control_rate_hz=rate, deadman_timeout_s=max(0.05, 2.0 / rate))
    assert config.control_period_s == pytest.approx(1.0 / rate)


@pytest.mark.parametrize("rate", [19.9, 5001.0])
def test_rates_outside_the_range_name_the_field(rate: float) -> None:
    """A rate outside [20, 5000] Hz raises an error naming control_rate_hz and the range."""
    with pytest.raises(ConfigurationError, match=r"control_rate_hz.*\[20, 5000\]") as info:
        SafetyConfig(control_rate_hz=rate, deadman_timeout_s=0.2)
    assert info.value.field == "control_rate_hz"


def test_deadman_shorter_than_two_periods_is_refused() -> None:
    """A deadman timeout under two control periods names the field, the rate and the minimum."""
    with pytest.raises(ConfigurationError, match=r"deadman_timeout_s.*2 control periods \(0.1 s") as info:
        SafetyConfig(control_rate_hz=20.0, deadman_timeout_s=0.05)
    assert info.value.field == "deadman_timeout_s"
    assert SafetyConfig(control_rate_hz=20.0, deadman_timeout_s=0.1).deadman_timeout_s == 0.1
