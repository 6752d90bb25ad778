"""``replay --plot``: a deploy or dry-run recording as a figure fit for a paper.

Each episode is drawn on its own clock (the simulation's, or the arm's, from the episode's first tick),
the episodes end to end with a boundary and a label (episode, seed, result) between them, so the gaps of
homing and resets between episodes take no room. Four panels share that axis:

- the retraction force's magnitude with the force limit as a line: the measured force in the band of the
  sensing's error bound the recording's meta names (none for exact sensing; the true force lies within it),
  the chain's travel bound on the true force where it was in force (:mod:`safety.force_bound`), the
  force-limit events (an excursion above the limit, a stall the limit caused) as marks, and, in a dry run,
  the predicted force;
- the jaw angle, commanded and measured;
- the tool tip's tracking error, from forward kinematics of the command of one tick and the measurement
  of the next (the arm's answer to it) [mm];
- the safety filter's events: the ticks where it changed the command, where it stopped the arm, and
  holds, each labelled with its reason.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from hardware_if.recording.replay import Recording, answers
from psm_control.outputs import atomic_path
from psm_control.robot import PsmModel
from safety.force_watch import FORCE_LIMIT_EXCEEDED, FORCE_LIMIT_STALL

__all__ = [
    "LAYOUT_KEY",
    "EpisodeSpan",
    "draw_recording",
    "episode_spans",
    "figure_layout",
    "plot_recording",
    "sensing_error_n",
]

#: Events that stopped commanding.
_HOLD_KINDS = ("hold", "deadman", "interrupted")


@dataclass(frozen=True)
class EpisodeSpan:
    """Where one episode lies in the recording and on the figure's axis.

    Attributes:
        label: ``episode 0 (seed 2): success``.
        start_t: Recording time of its start [s].
        end_t: Recording time of its end (the next episode's start, or the recording's end) [s].
        offset_s: Where its clock's zero lies on the figure's axis [s].
        duration_s: Its length on its own clock [s].
    """

    label: str
    start_t: float
    end_t: float
    offset_s: float
    duration_s: float


def episode_spans(rec: Recording) -> list[EpisodeSpan]:
    """The episodes of a recording, laid end to end on their own clocks."""
    starts = [e for e in rec.events if e.get("kind") == "episode_start"]
    ends = {e.get("episode"): e for e in rec.events if e.get("kind") == "episode_end"}
    last_t = max([float(rec.measured_t.max())] if len(rec.measured_t) else [0.0])
    spans, offset = [], 0.0
    for k, start in enumerate(starts):
        end_t = float(starts[k + 1]["t"]) if k + 1 < len(starts) else last_t + 1e-9
        inside = (rec.measured_t >= start["t"]) & (rec.measured_t < end_t)
        clock = _clock(rec.measured_stamp_s[inside], rec.measured_t[inside])
        duration = float(clock[-1] - clock[0]) if len(clock) else 0.0
        end = ends.get(start.get("episode"))
        result = "no end" if end is None else ("success" if end.get("success") else "no success")
        label = f"episode {start.get('episode')} (seed {start.get('seed')}): {result}"
        spans.append(EpisodeSpan(label, float(start["t"]), end_t, offset, duration))
        offset += duration
    return spans


def _clock(stamps_s: np.ndarray, recording_t: np.ndarray) -> np.ndarray:
    """The messages' own clock (their stamps) where it is valid, else the recording's time."""
    return stamps_s if len(stamps_s) and np.all(np.isfinite(stamps_s)) else recording_t


def _on_axis(span: EpisodeSpan, t: np.ndarray, stamps_s: np.ndarray, first_stamp_s: float) -> np.ndarray:
    """Times of an episode's messages on the figure's axis: its offset plus its own clock from its start."""
    return span.offset_s + (_clock(stamps_s, t) - first_stamp_s)


def _tip_error_mm(rec: Recording) -> np.ndarray:
    """|tip(command at tick k-1) - tip(measured at tick k)| [mm], nan where k does not answer k-1."""
    error = np.full(len(rec.measured_q), np.nan)
    paired = answers(rec)
    if not paired.any():
        return error
    model = PsmModel.from_variant()
    configuration = model.configuration()

    def tip(q: np.ndarray) -> np.ndarray:
        configuration.update(q)
        return np.asarray(configuration.local_pose()[:3, 3], dtype=float)

    for k in np.flatnonzero(paired):
        error[k] = 1000.0 * float(np.linalg.norm(tip(rec.command_q[k - 1]) - tip(rec.measured_q[k])))
    return error


#: The PNG text field that names the figure's panels (:func:`figure_layout`), so a figure kept in the docs
#: can be checked against what ``replay --plot`` draws today.
LAYOUT_KEY = "Layout"


def figure_layout(figure: Figure) -> str:
    """The panels of a figure, top to bottom, by their y labels, and the x label: its layout in one line."""
    axes = figure.get_axes()
    labels = [" ".join(ax.get_ylabel().split()) or "events" for ax in axes]
    return " | ".join(labels) + f" || {axes[-1].get_xlabel()}" if axes else ""


def plot_recording(rec: Recording, out: str | Path) -> Path:
    """Draw the figure of :func:`draw_recording` and write it (PNG, 200 dpi), its title and layout (the
    panels, :func:`figure_layout`) in the PNG's text fields."""
    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure = draw_recording(rec)
    with atomic_path(path, "--plot") as temporary:
        figure.savefig(temporary, metadata={"Title": figure.get_suptitle(), LAYOUT_KEY: figure_layout(figure)})
    return path


def draw_recording(rec: Recording) -> Figure:
    """The figure: force with its sensing error band, limit, travel bound and force-limit events; jaw, tip
    tracking error and filter events; per episode."""
    spans = episode_spans(rec)
    force_limit_n = rec.report.get("force_limit_n")
    tip_error = _tip_error_mm(rec)
    figure = Figure(figsize=(7.2, 7.0), dpi=200)
    axes = figure.subplots(4, 1, sharex=True, gridspec_kw={"height_ratios": [3, 2, 2, 1.2]})
    force_ax, jaw_ax, error_ax, event_ax = axes
    error_n = sensing_error_n(rec)
    travel = rec.travel_bound_n if len(rec.travel_bound_n) == len(rec.command_t) else None
    drawn_travel = False
    for k, span in enumerate(spans):
        first = k == 0
        measured = (rec.measured_t >= span.start_t) & (rec.measured_t < span.end_t)
        command = (rec.command_t >= span.start_t) & (rec.command_t < span.end_t)
        if not measured.any():
            continue
        zero = float(_clock(rec.measured_stamp_s[measured], rec.measured_t[measured])[0])
        x_meas = _on_axis(span, rec.measured_t[measured], rec.measured_stamp_s[measured], zero)
        x_cmd = _on_axis(span, rec.command_t[command], rec.command_stamp_s[command], zero)
        force = np.linalg.norm(rec.force_n[measured], axis=1)
        force_ax.plot(x_meas, force, color="tab:blue", lw=1.0, label="measured |force|" if first else None)
        if error_n > 0.0:
            force_ax.fill_between(
                x_meas, np.maximum(force - error_n, 0.0), force + error_n, color="tab:blue", alpha=0.15, lw=0,
                label=f"sensing error \u00b1{error_n:.3g} N (the true force lies within)" if first else None,
            )  # fmt: skip
        if travel is not None and np.isfinite(travel[command]).any():
            force_ax.plot(
                x_cmd, travel[command], color="tab:green", lw=1.0, ls="-.",
                label="travel bound (held load + stiffness x travel)" if not drawn_travel else None,
            )  # fmt: skip
            drawn_travel = True
        predicted = rec.predicted_force_n[command]
        if np.isfinite(predicted).any():
            force_ax.plot(
                x_cmd, predicted, color="tab:orange", lw=1.0, ls=":", label="predicted |force|" if first else None
            )
        jaw_ax.step(
            x_cmd, rec.command_jaw[command], where="post", color="black", lw=0.9, ls="--",
            label="commanded" if first else None,
        )  # fmt: skip
        jaw_ax.plot(x_meas, rec.measured_jaw[measured], color="tab:blue", lw=1.0, label="measured" if first else None)
        error_ax.plot(x_meas, tip_error[measured], color="tab:purple", lw=0.9)
        _event_raster(event_ax, x_cmd, rec.intervened[command], 1, "tab:orange", "filter changed the command", first)
        _event_raster(event_ax, x_cmd, rec.safety_stop[command], 0, "tab:red", "safety stop", first)
    for span in spans:
        for ax in axes:
            ax.axvline(span.offset_s, color="0.6", lw=0.8)
        where = force_ax.get_xaxis_transform()
        force_ax.text(
            span.offset_s, 1.02, span.label, transform=where, fontsize=6, rotation=0 if len(spans) <= 4 else 30,
            va="bottom", ha="left",
        )  # fmt: skip
    _mark_holds(rec, spans, axes)
    _mark_force_limit_events(rec, spans, force_ax)
    if force_limit_n is not None and np.isfinite(float(force_limit_n)):
        force_ax.axhline(
            float(force_limit_n), color="tab:red", ls="--", lw=1.0, label=f"force limit {float(force_limit_n):g} N"
        )
    # The lines and marks decide the scale, not the band: a dVRK's uncalibrated error bound is 100 N and more.
    drawn = [np.asarray(line.get_ydata(), dtype=float) for line in force_ax.get_lines()]
    top = max((float(np.nanmax(y)) for y in drawn if np.isfinite(y).any()), default=0.0)
    force_ax.set_ylim(0.0, 1.15 * top if top > 0.0 else None)
    error_ax.set_ylim(bottom=0.0)
    force_ax.set_ylabel("retraction force [N]")
    jaw_ax.set_ylabel("jaw angle [rad]")
    error_ax.set_ylabel("tip tracking\nerror [mm]")
    event_ax.set_yticks([0, 1], ["safety stop", "filter changed\ncommand"], fontsize=7)
    event_ax.set_ylim(-0.6, 1.6)
    event_ax.set_xlabel("time in episode [s] (each episode on its own clock, end to end)")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
        if ax is not event_ax and ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper right", fontsize=7, framealpha=0.9)
    kind = "dry run" if rec.meta.get("dry_run") else "deploy"
    figure.suptitle(
        f"{rec.meta.get('policy', '?')} on {rec.meta.get('task', '?')}: {kind} to {rec.meta.get('target', '?')}",
        fontsize=9,
    )
    figure.tight_layout()
    return figure


def sensing_error_n(rec: Recording) -> float:
    """The sensing error bound the recording's safety filter was given [N]; 0 for exact sensing, and where the
    recording does not say (before deploys recorded their sensing) or says a non-finite one."""
    sensing = rec.meta.get("sensing")
    value = sensing.get("force_sensing_error_n") if isinstance(sensing, dict) else None
    if value is None or not np.isfinite(float(value)):
        return 0.0
    return max(0.0, float(value))


def _mark_force_limit_events(rec: Recording, spans: list[EpisodeSpan], ax: Any) -> None:
    """A mark at each force-limit event: an excursion above the limit at its start and peak, a stall where the
    chain reported it, at the load holding the tissue cost."""
    marked: set[str] = set()
    for event in rec.events:
        kind = event.get("kind")
        if kind not in (FORCE_LIMIT_EXCEEDED, FORCE_LIMIT_STALL):
            continue
        inside = [s for s in spans if s.start_t <= event["t"] < s.end_t]
        if not inside:
            continue
        span = inside[0]
        if kind == FORCE_LIMIT_EXCEEDED:  # logged when it ended (in the simulation, at the episode's end)
            x = span.offset_s + min(max(float(event.get("start_s", 0.0)), 0.0), span.duration_s)
            y, marker, colour, label = event.get("peak_n"), "v", "tab:red", "force limit exceeded"
        else:  # logged at the tick that saw it
            x, y = _x_at(rec, span, event["t"]), event["static_load_n"]
            marker, colour, label = "s", "tab:purple", "force limit stalled the retraction"
        if y is None or not np.isfinite(float(y)):
            y = rec.report.get("force_limit_n")
        if y is None:
            continue
        ax.plot(
            [x], [float(y)], marker, color=colour, ms=6, mfc="none", mew=1.2,
            label=label if label not in marked else None,
        )  # fmt: skip
        marked.add(label)


def _x_at(rec: Recording, span: EpisodeSpan, t: float) -> float:
    """Where recording time ``t`` [s] lies on the figure's axis: at the episode's last measurement by then."""
    inside = (rec.measured_t >= span.start_t) & (rec.measured_t < span.end_t)
    if not inside.any():
        return span.offset_s
    clock = _clock(rec.measured_stamp_s[inside], rec.measured_t[inside])
    k = max(0, int(np.searchsorted(rec.measured_t[inside], t, side="right")) - 1)
    return span.offset_s + float(clock[k] - clock[0])


def _event_raster(ax: Any, x: np.ndarray, flags: np.ndarray, row: int, colour: str, label: str, first: bool) -> None:
    """Ticks where ``flags`` is set, as short vertical marks on ``row``."""
    if len(flags) and flags.any():
        ax.plot(x[flags], np.full(int(flags.sum()), row), "|", color=colour, ms=8, label=label if first else None)


def _mark_holds(rec: Recording, spans: list[EpisodeSpan], axes: Any) -> None:
    """A labelled line where each hold (or Ctrl-C) stopped commanding, in its episode's place."""
    for event in rec.events:
        if event.get("kind") not in _HOLD_KINDS:
            continue
        inside = [s for s in spans if s.start_t <= event["t"] < s.end_t] or spans[-1:]
        if not inside:
            continue
        span = inside[0]
        x = span.offset_s + span.duration_s  # the recording's last tick of that episode: where it stopped
        for ax in axes:
            ax.axvline(x, color="tab:red", lw=1.4)
        text = str(event.get("text") or event.get("kind"))
        axes[0].annotate(
            f"HOLD: {text[:70]}", (x, 0.5), xycoords=("data", "axes fraction"), xytext=(-4, 0),
            textcoords="offset points", ha="right", va="center", fontsize=6, color="tab:red",
            bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "tab:red", "lw": 0.6},
        )  # fmt: skip
