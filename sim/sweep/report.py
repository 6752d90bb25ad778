"""The sweep's report: a summary card, success, peak force and failure classes against each varied parameter,
as PNG plots and a self-contained HTML page (plus Markdown)."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import FormatStrFormatter, FuncFormatter

from psm_control import __version__
from psm_control.outputs import atomic_path
from sim.evaluation import FAILURE_CLASSES, describe_exceedances, force_limit_summary
from sim.stiffness_fifths import StiffnessFifth, by_stiffness_fifth, expert_summary
from sim.sweep.page import Page, percent, percent_interval, quantity
from sim.sweep.space import ParameterRange
from sim.sweep.stats import THIN_BIN_EPISODES, binned_success, wilson_interval

__all__ = ["summarize", "write_report"]


def summarize(records: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Overall numbers of a sweep: success with 95 % CI, peak force, interventions, failures."""
    finished = [r for r in records if "error" not in r]
    successes = sum(1 for r in finished if r.get("success"))
    forces = [float(r["peak_force_n"]) for r in finished if r.get("peak_force_n") is not None]
    low, high = wilson_interval(successes, len(finished))
    interventions: Counter[str] = Counter()
    for r in finished:
        interventions.update({str(k): int(v) for k, v in (r.get("interventions") or {}).items()})
    return {
        "episodes": len(records),
        "errors": len(records) - len(finished),
        "success_rate": successes / len(finished) if finished else math.nan,
        "ci95": [low, high],
        "peak_force_n": {
            "max": max(forces) if forces else None,
            "p50": float(np.percentile(forces, 50)) if forces else None,
            "p95": float(np.percentile(forces, 95)) if forces else None,
        },
        "safety_stops": sum(int(r.get("safety_stops") or 0) for r in finished),
        "invalid_actions": sum(int(r.get("invalid_actions") or 0) for r in finished),
        **force_limit_summary(finished),
        "interventions": dict(sorted(interventions.items())),
        "failure_classes": dict(sorted(Counter(str(r.get("failure_class", "none")) for r in finished).items())),
    }


def _plot_success(records: Sequence[dict[str, Any]], parameter: ParameterRange, path: Path) -> None:
    stats = [
        b
        for b in binned_success(records, parameter.name, relative=parameter.relative, integer=parameter.integer)
        if b.episodes
    ]
    figure = Figure(figsize=(5.5, 3.5), dpi=110)
    axis = figure.subplots()
    centres = [_centre(b.low, b.high, parameter.relative) for b in stats]
    rates = [100 * b.success_rate for b in stats]
    errors = [[100 * (b.success_rate - b.ci_low) for b in stats], [100 * (b.ci_high - b.success_rate) for b in stats]]
    axis.errorbar(centres, rates, yerr=errors, fmt="o-", capsize=4, color="tab:blue")
    if parameter.relative:
        _plain_log_axis(axis)
    axis.set_ylim(-5, 105)
    axis.set_xlabel(_axis_label(parameter))
    axis.set_ylabel("success [%] (95 % CI)")
    axis.grid(alpha=0.3)
    figure.tight_layout()
    with atomic_path(path, "--out") as temporary:
        figure.savefig(temporary)


def _plot_force_against(
    records: Sequence[dict[str, Any]], parameter: ParameterRange, path: Path, force_limit_n: float | None
) -> None:
    rows = [r for r in records if "error" not in r and r.get("peak_force_n") is not None]
    figure = Figure(figsize=(5.5, 3.5), dpi=110)
    axis = figure.subplots()
    for success, colour, label in ((True, "tab:green", "success"), (False, "tab:red", "failure")):
        chosen = [r for r in rows if bool(r.get("success")) is success and parameter.name in r.get("params", {})]
        axis.scatter(
            [float(r["params"][parameter.name]) for r in chosen],
            [float(r["peak_force_n"]) for r in chosen],
            s=14,
            color=colour,
            label=label,
        )
    if force_limit_n is not None:
        axis.axhline(force_limit_n, color="black", linestyle="--", label=f"limit {force_limit_n:g} N")
    if parameter.relative:
        _plain_log_axis(axis)
    axis.set_xlabel(_axis_label(parameter))
    axis.set_ylabel("peak retraction force [N]")
    axis.legend(fontsize=8)
    axis.grid(alpha=0.3)
    figure.tight_layout()
    with atomic_path(path, "--out") as temporary:
        figure.savefig(temporary)


def _plot_forces(records: Sequence[dict[str, Any]], path: Path, force_limit_n: float | None) -> None:
    forces = [float(r["peak_force_n"]) for r in records if r.get("peak_force_n") is not None and "error" not in r]
    figure = Figure(figsize=(5.5, 3.5), dpi=110)
    axis = figure.subplots()
    axis.hist(forces or [0.0], bins=20, color="tab:orange", edgecolor="black")
    if force_limit_n is not None:
        axis.axvline(force_limit_n, color="red", linestyle="--", label=f"force limit {force_limit_n:g} N")
        axis.legend()
    axis.set_xlabel("peak retraction force per episode [N]")
    axis.set_ylabel("episodes")
    axis.grid(alpha=0.3)
    figure.tight_layout()
    with atomic_path(path, "--out") as temporary:
        figure.savefig(temporary)


def _plain_log_axis(axis: Any) -> None:
    """A logarithmic x axis labelled 0.2, 0.5, 1, 2 rather than 5 x 10^-1 (minor ticks at 2, 3, 5 only)."""
    axis.set_xscale("log")
    axis.xaxis.set_major_formatter(FormatStrFormatter("%g"))

    def minor(value: float, _position: int) -> str:
        mantissa = value / 10 ** math.floor(math.log10(value))
        return f"{value:g}" if round(mantissa) in (2, 3, 5) and abs(mantissa - round(mantissa)) < 1e-6 else ""

    axis.xaxis.set_minor_formatter(FuncFormatter(minor))


def _centre(low: float, high: float, relative: bool) -> float:
    return math.sqrt(low * high) if relative and low > 0 else (low + high) / 2


def _axis_label(parameter: ParameterRange) -> str:
    if parameter.relative:
        return f"{parameter.name} (x nominal)"
    return f"{parameter.name} [{parameter.unit}]" if parameter.unit else parameter.name


def _counts(counts: dict[str, int]) -> str:
    """``{"none": 45, "timeout": 3}`` as ``none 45, timeout 3`` (``none`` when empty)."""
    return ", ".join(f"{name} {count}" for name, count in counts.items() if count) or "none"


def _interventions(counts: dict[str, int]) -> str:
    """``{"total": 54, "joint_acceleration": 40, ...}`` as ``54 (joint_acceleration 40, ...)``."""
    kinds = {name: count for name, count in counts.items() if name != "total"}
    total = counts.get("total", sum(kinds.values()))
    return f"{total} ({_counts(kinds)})" if kinds else str(total)


def _bin_label(low: float, high: float, parameter: ParameterRange) -> str:
    unit = " x" if parameter.relative else (f" {parameter.unit}" if parameter.unit else "")
    if parameter.integer:
        return f"{low:.0f}{unit}" if low == high else f"{low:.0f} to {high:.0f}{unit}"
    if parameter.unit == "m" and not parameter.relative and max(abs(low), abs(high)) < 0.1:
        return f"{1000 * low:.2f} to {1000 * high:.2f} mm"  # millimetres read better than 8.19e-05 m
    return f"{quantity(low)} to {quantity(high)}{unit}"


#: What the report's terms mean, printed under its summary.
DEFINITIONS = (
    ("success", "the task's goal reached at the episode's last step (the paper's criterion)"),
    (
        "tissue_damage",
        "an episode in which the force on the tissue exceeded 5 N or a spring of the flap was stretched past twice "
        "its rest length (sim.mechanics.DamageLimits), whatever the force limit of the safety filter",
    ),
    ("force limit exceeded", "episodes whose true peak retraction force went past the safety filter's limit"),
    ("interventions", "constraints of the safety filter that changed a command, counted once per constraint and step"),
    (
        "thin",
        f"a bin of fewer than {THIN_BIN_EPISODES} episodes: its success rate is known to +-20 points or worse "
        "(read it with its 95 % CI)",
    ),
    (
        "stopped by the force limit",
        "an unsuccessful episode that the safety filter's force limit held back (failure class force_limit_stall: "
        "the pull held at the limit, no more serious event)",
    ),
)


def _newtons(value: float | None) -> str:
    """A force for a table cell [N] ("-": none recorded)."""
    return "-" if value is None else f"{value:.2f} N"


def _stiffness_section(page: Page, fifths: Sequence[StiffnessFifth], expert: bool) -> None:
    """The table of success and force-limit stops by fifth of the drawn stiffness (the expert's beside)."""
    page.heading("Where the force limit stops a retraction, by fifth of the drawn stiffness")
    beside = ", the scripted expert's episodes of the same trials (seeds and draws) beside the policy's"
    page.paragraph(
        "The trials ordered by the Young's modulus their flap was drawn with, in five groups whose sizes differ by "
        f"at most one{beside if expert else ''}. The last column names what ended the policy's unsuccessful "
        "episodes (failure classes, see Terms); the force limit's by what its bound was on: the travel bound (the "
        "grasp point's travel since the grasp times the stiffest tissue's stiffness, where the force sensing cannot "
        "tell the limit: a bound, not a measured force) or the measured force. The largest peak is the true "
        "retraction force's (the simulation's, whatever the sensing): with exact sensing, what retracting tissue of "
        "that stiffness took."
    )
    header = ["Young's modulus", "trials", "success", "stopped by the force limit", "largest true peak"]
    if expert:
        header += ["expert success", "expert stopped by the force limit", "expert largest true peak"]
    header.append("what ended the policy's unsuccessful episodes")
    rows = []
    for f in fifths:
        data = f.to_dict()
        row = [
            f"{quantity(f.stiffness_low_kpa)} to {quantity(f.stiffness_high_kpa)} kPa",
            f"{f.trials} (thin)" if f.thin else str(f.trials),
            percent(data["success"]),
            percent(data["force_limit_stall"]),
            _newtons(f.largest_peak_n),
        ]
        if expert:
            row += [
                percent(data["expert_success"]),
                percent(data["expert_force_limit_stall"]),
                _newtons(f.expert_largest_peak_n),
            ]
        row.append(_counts(f.stopped_by) if f.stopped_by else "none")
        rows.append(row)
    page.table(header, rows)


def write_report(
    out_dir: Path,
    records: Sequence[dict[str, Any]],
    ranges: Sequence[ParameterRange],
    *,
    title: str,
    context: dict[str, str],
    force_limit_n: float | None = None,
    limit_enforced: bool = True,
    command: str = "",
    expert_records: Sequence[dict[str, Any]] | None = None,
    warnings: Sequence[str] = (),
) -> dict[str, Path]:
    """Write plots, ``report.md`` and a self-contained ``report.html`` into ``out_dir``.

    Args:
        out_dir: Where the files go.
        records: The sweep's trial records.
        ranges: The varied parameters.
        title: The page's heading.
        context: Label -> text rows for the summary card (policy, task, sampling...).
        force_limit_n: The retraction-force limit the episodes ran under [N] (None: not known).
        limit_enforced: False when the safety filter was off (the limit is shown, not claimed).
        command: The command line that ran the sweep.
        expert_records: The scripted expert's records of the same trials, shown beside the policy's
            (``robustness --beside-expert``); None: no expert pass.
        warnings: What the run warned of at its start (the force sensing's, the policy's), shown under the card.

    Returns:
        The written files by role (``report_html``, ``report_md``, the PNGs).
    """
    summary = summarize(records)
    files: dict[str, Path] = {"forces_png": out_dir / "peak_force_histogram.png"}
    _plot_forces(records, files["forces_png"], force_limit_n)
    page = Page(title)
    low, high = summary["ci95"]
    worst = summary["peak_force_n"]["max"]
    rows = [*context.items()]
    rows += [
        ("episodes", f"{summary['episodes']} ({summary['errors']} errors)"),
        ("success", f"{percent(summary['success_rate'])} (95 % CI {percent_interval(low, high)})"),
    ]
    if expert_records is not None:
        expert = expert_summary(expert_records)
        rows.append(
            (
                "scripted expert, same trials",
                f"{percent(expert['expert_success'])} (95 % CI {percent_interval(*expert['expert_ci95'])})",
            )
        )
    alert = []
    if force_limit_n is not None and worst is not None:
        ratio = worst / force_limit_n
        enforced = "" if limit_enforced else ", not enforced: safety filter off"
        rows.append(
            (
                "worst peak force",
                f"{quantity(worst, 'N')}, {ratio:.2f} x the {quantity(force_limit_n, 'N')} limit{enforced}",
            )
        )
        if ratio > 1.0:
            alert.append("worst peak force")
    else:
        rows.append(("worst peak force", quantity(worst, "N")))
    rows += [
        (
            "peak force median / p95",
            f"{quantity(summary['peak_force_n']['p50'], 'N')} / {quantity(summary['peak_force_n']['p95'], 'N')}",
        ),
        ("safety stops", f"{summary['safety_stops']} ticks"),
        ("invalid actions", f"{summary['invalid_actions']} (held; the jaw kept)"),
        ("force limit exceeded", describe_exceedances(summary)),
        ("interventions", _interventions(summary["interventions"])),
        ("failure classes", _counts(summary["failure_classes"])),
        ("package", f"tissue-retract {__version__}"),
    ]
    page.card(rows, alert=alert)
    if warnings:
        page.heading("Warnings at the start of the run")
        page.items(list(warnings))
    if command:
        page.heading("Command")
        page.command(command)
    page.heading("Terms")
    page.table(["term", "meaning"], [list(row) for row in DEFINITIONS])
    fifths = by_stiffness_fifth(records, expert_records)
    if fifths:
        _stiffness_section(page, fifths, expert_records is not None)
    for parameter in ranges:
        stats = [
            b
            for b in binned_success(records, parameter.name, relative=parameter.relative, integer=parameter.integer)
            if b.episodes
        ]
        success_png = out_dir / f"success_vs_{parameter.name}.png"
        force_png = out_dir / f"peak_force_vs_{parameter.name}.png"
        _plot_success(records, parameter, success_png)
        _plot_force_against(records, parameter, force_png, force_limit_n)
        files[f"success_{parameter.name}_png"] = success_png
        files[f"force_{parameter.name}_png"] = force_png
        page.heading(f"Success and peak force against {parameter.describe()}")
        page.table(
            [parameter.name, "episodes", "success", "95 % CI", "peak force max", "peak force p95"],
            [
                [
                    _bin_label(b.low, b.high, parameter),
                    f"{b.episodes} (thin)" if b.episodes < THIN_BIN_EPISODES else str(b.episodes),
                    percent(b.success_rate),
                    percent_interval(b.ci_low, b.ci_high),
                    quantity(b.peak_force_max_n, "N"),
                    quantity(b.peak_force_p95_n, "N"),
                ]
                for b in stats
            ],
        )
        page.figure(success_png, f"success against {parameter.name} (95 % CI)")
        page.figure(force_png, f"peak force against {parameter.name}, per episode")
        classes = [c for c in FAILURE_CLASSES if any(b.failure_classes.get(c) for b in stats)]
        page.heading(f"Failure classes against {parameter.name}")
        page.table(
            [parameter.name, *classes],
            [
                [_bin_label(b.low, b.high, parameter), *(str(b.failure_classes.get(c, 0)) for c in classes)]
                for b in stats
            ],
        )
    page.heading("Peak force")
    page.figure(files["forces_png"], "peak retraction force per episode")
    files.update(page.write(out_dir))
    return files
