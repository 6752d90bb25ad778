"""SafetyConfig: defaults, presets, loading and validation errors that name the field."""

from __future__ import annotations

from pathlib import Path

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
    with pytest.raises(ConfigurationError) as info:
        SafetyConfig(**{field: value})
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
