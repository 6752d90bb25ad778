"""``tissue-retract safety show [--safety-config FILE]``: print the effective safety limits."""

from __future__ import annotations

import argparse

from rich.console import Console
from rich.table import Table

from safety.config import (
    DEADMAN_MIN_PERIODS,
    FORCE_PRESETS,
    MAX_CONTROL_RATE_HZ,
    MIN_CONTROL_RATE_HZ,
    SafetyConfig,
    load_safety_config,
)
from sim.force_sensing import TISSUE_BOUNDS, declared_tissue_bounds

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the subcommand to its parser."""
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    show = actions.add_parser("show", help="print the effective limits as a table")
    show.add_argument(
        "--safety-config",
        "--config",  # the older name, still taken
        dest="config",
        metavar="FILE",
        default=None,
        help="a TOML or YAML safety configuration, as every other command's --safety-config",
    )


def run(args: argparse.Namespace) -> int:
    """Print the limits of the default or given configuration."""
    config = load_safety_config(args.config) if args.config else SafetyConfig()
    spec = config.spec
    joints = Table(title=f"{spec.name}: joint limits at {config.control_rate_hz:g} Hz (unit: rad, or m for insertion)")
    columns = ("joint", "unit", "lower", "upper", "margin", "velocity (unit/s)", "accel. (unit/s^2)", "jerk (unit/s^3)")
    for column in columns:
        joints.add_column(column, justify="left" if column in ("joint", "unit") else "right")
    lower, upper = config.lower, config.upper
    for i, joint in enumerate(spec.joints):
        joints.add_row(
            joint.dvrk_name,
            "m" if joint.kind == "prismatic" else "rad",
            f"{lower[i]:.4g}",
            f"{upper[i]:.4g}",
            f"{config.position_margin[i]:.4g}",
            f"{config.velocity[i]:.4g}",
            f"{config.acceleration[i]:.4g}",
            f"{config.jerk[i]:.4g}",
        )
    other = Table(title="other limits")
    other.add_column("setting")
    other.add_column("value", justify="right")
    preset = FORCE_PRESETS[config.tissue]
    force_source = "explicit" if config.force_limit_n is not None else f"preset {config.tissue!r}: {preset.source}"
    for name, value in (
        ("force_limit_n", f"{config.effective_force_limit_n:g} ({force_source})"),
        ("min_insertion_m", f"{config.min_insertion_m:g}"),
        ("workspace_min_m", str(config.workspace_min_m)),
        ("workspace_max_m", str(config.workspace_max_m)),
        ("workspace_tolerance_m", f"{config.workspace_tolerance_m:g}"),
        ("cbf_gamma", f"{config.cbf_gamma:g}"),
        ("horizon_s", f"{config.horizon_s:g}"),
        (
            "control_rate_hz",
            f"{config.control_rate_hz:g} (allowed {MIN_CONTROL_RATE_HZ:g}-{MAX_CONTROL_RATE_HZ:g}; "
            "below 1 kHz the verifier may hold a tip overshooting the box by ~1 mm)",
        ),
        (
            "deadman_timeout_s",
            f"{config.deadman_timeout_s:g} (at least {DEADMAN_MIN_PERIODS} periods: "
            f"{DEADMAN_MIN_PERIODS * config.control_period_s:g} s)",
        ),
        ("slack_penalty", f"{config.slack_penalty:g} (per unit of a soft limit's normalised slack)"),
        (
            "stiffness prior / min / max [N/m]",
            f"{config.stiffness_prior_n_per_m:g} / {config.stiffness_min_n_per_m:g} / {config.stiffness_max_n_per_m:g}",
        ),
        ("max_translation_m / max_yaw_rad", f"{config.max_translation_m:g} / {config.max_yaw_rad:g}"),
        *_tissue_rows(config),
        (
            "force_sensing_error_n",
            "set by each run's force sensing: 0 in the simulation's ideal, the preset's or the "
            "--wrench-calibration file's bound otherwise (printed at the run's start)",
        ),
        (
            "solver eps / max_iter / hard tol",
            f"{config.solver_eps:g} / {config.solver_max_iter} / {config.hard_tolerance:g}",
        ),
    ):
        other.add_row(name, value)
    console = Console(width=140)
    console.print(joints)
    console.print(other)
    return 0


def _tissue_rows(config: SafetyConfig) -> list[tuple[str, str]]:
    """The held tissue's bounds in force and where each comes from (declared, or the task flap's)."""
    declared = declared_tissue_bounds(config)
    rows = []
    for name, (unit, _, rule) in TISSUE_BOUNDS.items():
        value = getattr(config, name)
        if name in declared:
            source = "declared: a dVRK deploy keeps it; the simulation keeps it, or refuses it below its own tissue's"
        else:
            source = f"the task flap's, {rule}; a simulated run takes its own tissue ranges'"
        rows.append((name, f"{value:g} {unit} ({source})"))
    return rows
