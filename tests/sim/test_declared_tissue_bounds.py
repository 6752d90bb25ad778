"""Tissue bounds a safety configuration declares are kept, or refused by name, never replaced."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from psm_control.errors import ConfigurationError
from safety.config import SafetyConfig
from sim.force_sensing import tissue_bounds, with_sensing
from sim.randomization import DEFAULT_RANGES
from tests.conftest import run_cli

DECLARED = "tissue_stiffness_bound_n_per_m = 300.0\nheld_load_bound_n = 1.0\n"


def test_declared_bounds_are_kept_and_undeclared_ones_are_the_ranges() -> None:
    """300 N/m and 1 N declared stay 300 N/m and 1 N; a configuration that declares none takes the ranges' own."""
    declared = dataclasses.replace(SafetyConfig(), tissue_stiffness_bound_n_per_m=300.0, held_load_bound_n=1.0)
    kept = with_sensing(declared, 7.0, DEFAULT_RANGES)
    assert (kept.tissue_stiffness_bound_n_per_m, kept.held_load_bound_n) == (300.0, 1.0)
    assert kept.force_sensing_error_n == 7.0
    stiffer = dict(DEFAULT_RANGES, tissue_youngs_modulus_kpa=(6.0, 42.0))
    derived = with_sensing(SafetyConfig(), 7.0, stiffer)
    assert (derived.tissue_stiffness_bound_n_per_m, derived.held_load_bound_n) == tissue_bounds(stiffer)


def test_a_bound_below_the_simulated_tissue_is_refused_and_a_dvrk_takes_the_users_word() -> None:
    """50 N/m under the task flap's 110.88 N/m: refused by name in the simulation, kept on a dVRK."""
    low = dataclasses.replace(SafetyConfig(), tissue_stiffness_bound_n_per_m=50.0)
    with pytest.raises(ConfigurationError, match=r"tissue_stiffness_bound_n_per_m.*at least 110.9 N/m"):
        with_sensing(low, 7.0, DEFAULT_RANGES)
    assert with_sensing(low, 7.0, DEFAULT_RANGES, tissue_known=False).tissue_stiffness_bound_n_per_m == 50.0


def test_evaluate_and_safety_show_use_the_declared_bounds(tmp_path: Path) -> None:
    """evaluate's sensing warning keeps the file's 300 N/m and 1 N; safety show lists both as declared."""
    config = tmp_path / "tissue.toml"
    config.write_text(DECLARED)
    run = run_cli(
        "evaluate", "--policy", "scripted", "--task", "lift", "--episodes", "1", "--seeds", "1",
        "--force-sensing", "dvrk", "--safety-config", str(config),
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    said = " ".join((run.stdout + run.stderr).split())
    assert "no stiffer than 300 N/m and loads the jaws by at most 1.00 N" in said, said
    shown = run_cli("safety", "show", "--safety-config", str(config))
    assert shown.returncode == 0, shown.stderr
    text = " ".join(shown.stdout.split())
    assert "300 N/m (declared" in text and "1 N (declared" in text, text
