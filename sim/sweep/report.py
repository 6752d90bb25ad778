"""The sweep's report: PNG plots and a self-contained HTML page (plus Markdown) a person reads first."""

from __future__ import annotations

import base64
import html
import math
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from sim.sweep.space import ParameterRange
from sim.sweep.stats import binned_success, wilson_interval

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
        "force_limit_exceeded": sum(int(r.get("force_limit_exceeded") or 0) for r in finished),
        "max_force_excess_n": max((float(r.get("max_force_excess_n") or 0.0) for r in finished), default=0.0),
        "interventions": dict(sorted(interventions.items())),
        "failure_classes": dict(sorted(Counter(str(r.get("failure_class", "none")) for r in finished).items())),
    }


def _plot_success(records: Sequence[dict[str, Any]], parameter: ParameterRange, path: Path) -> None:
    stats = [b for b in binned_success(records, parameter.name, relative=parameter.relative) if b.episodes]
    figure = Figure(figsize=(5.5, 3.5), dpi=110)
    axis = figure.subplots()
    centres = [math.sqrt(b.low * b.high) if parameter.relative and b.low > 0 else (b.low + b.high) / 2 for b in stats]
    rates = [100 * b.success_rate for b in stats]
    errors = [[100 * (b.success_rate - b.ci_low) for b in stats], [100 * (b.ci_high - b.success_rate) for b in stats]]
    axis.errorbar(centres, rates, yerr=errors, fmt="o-", capsize=4, color="tab:blue")
    if parameter.relative:
        axis.set_xscale("log")
    axis.set_ylim(-5, 105)
    axis.set_xlabel(parameter.name + (" (x nominal)" if parameter.relative else ""))
    axis.set_ylabel("success [%] (95 % CI)")
    axis.grid(alpha=0.3)
    figure.tight_layout()
    figure.savefig(path)


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
    figure.savefig(path)


def write_report(
    out_dir: Path,
    records: Sequence[dict[str, Any]],
    ranges: Sequence[ParameterRange],
    *,
    title: str,
    context: dict[str, Any],
    force_limit_n: float | None = None,
) -> dict[str, Path]:
    """Write plots, ``report.md`` and a self-contained ``report.html`` into ``out_dir``.

    Returns:
        The written files by role (``report_html``, ``report_md``, ``forces_png``, ``success_<name>_png``).
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    summary = summarize(records)
    files: dict[str, Path] = {"forces_png": out_dir / "peak_force_histogram.png"}
    _plot_forces(records, files["forces_png"], force_limit_n)
    for parameter in ranges:
        path = out_dir / f"success_vs_{parameter.name}.png"
        _plot_success(records, parameter, path)
        files[f"success_{parameter.name}_png"] = path
    lines = [f"# {title}", ""]
    lines += [f"- {key}: {value}" for key, value in context.items()]
    low, high = summary["ci95"]
    lines += [
        f"- episodes: {summary['episodes']} ({summary['errors']} errors)",
        f"- success: {100 * summary['success_rate']:.1f} % (95 % CI {100 * low:.1f} to {100 * high:.1f} %)",
        f"- peak force [N]: {summary['peak_force_n']}",
        f"- safety stops: {summary['safety_stops']}",
        f"- force limit exceeded: {summary['force_limit_exceeded']} time(s), "
        f"max excess {summary['max_force_excess_n']:.3f} N",
        f"- interventions: {summary['interventions']}",
        f"- failure classes: {summary['failure_classes']}",
        "",
    ]
    for parameter in ranges:
        lines += [
            f"## Success against {parameter.describe()}",
            "",
            "| bin | episodes | success % | 95 % CI | peak force p95 [N] |",
            "|---|---|---|---|---|",
        ]
        for b in binned_success(records, parameter.name, relative=parameter.relative):
            if b.episodes:
                lines.append(
                    f"| {b.low:.4g} to {b.high:.4g} | {b.episodes} | {100 * b.success_rate:.0f} | "
                    f"{100 * b.ci_low:.0f} to {100 * b.ci_high:.0f} | {b.peak_force_p95_n:.3g} |"
                )
        lines += ["", f"![success against {parameter.name}]({files[f'success_{parameter.name}_png'].name})", ""]
    lines += ["## Peak force", "", f"![peak force histogram]({files['forces_png'].name})", ""]
    markdown = "\n".join(lines)
    files["report_md"] = out_dir / "report.md"
    files["report_md"].write_text(markdown)
    files["report_html"] = out_dir / "report.html"
    files["report_html"].write_text(_html(markdown, out_dir))
    return files


def _html(markdown: str, out_dir: Path) -> str:
    """A minimal Markdown-to-HTML rendering with the PNGs inlined, so the page is one file."""
    body = []
    in_table = False
    for line in markdown.splitlines():
        if line.startswith("|"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            if all(set(c) <= {"-"} for c in cells):
                continue
            tag = "th" if not in_table else "td"
            if not in_table:
                body.append("<table>")
                in_table = True
            body.append("<tr>" + "".join(f"<{tag}>{html.escape(c)}</{tag}>" for c in cells) + "</tr>")
            continue
        if in_table:
            body.append("</table>")
            in_table = False
        if line.startswith("!["):
            name = line[line.index("(") + 1 : -1]
            data = base64.b64encode((out_dir / name).read_bytes()).decode()
            body.append(f'<p><img alt="{html.escape(name)}" src="data:image/png;base64,{data}"></p>')
        elif line.startswith("## "):
            body.append(f"<h2>{html.escape(line[3:])}</h2>")
        elif line.startswith("# "):
            body.append(f"<h1>{html.escape(line[2:])}</h1>")
        elif line.startswith("- "):
            body.append(f"<li>{html.escape(line[2:])}</li>")
        elif line:
            body.append(f"<p>{html.escape(line)}</p>")
    if in_table:
        body.append("</table>")
    style = "body{font-family:sans-serif;max-width:60em;margin:2em auto}td,th{border:1px solid #ccc;padding:.2em .6em}"
    return (
        f"<!doctype html><html><head><meta charset='utf-8'><style>{style}</style></head><body>\n"
        + "\n".join(body)
        + "\n</body></html>\n"
    )
