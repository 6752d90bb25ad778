"""``tissue-retract bench sensing``: the force-sensing models' free-space error beside real PSMs' logs.

On a free-space joint log (nothing touches the tool, so the console's whole estimate is error) it prints,
by insertion depth and tool-tip speed, the RMS of:

* the logged console's estimate, ``pinv(J^T) tau`` of the logged efforts, as the console computes it; the
  column is named by the console the log came from: ``real console`` for the public WPI and radiang layouts
  (real PSMs), the console a bag's metadata names (``custom_data: console``, ``sim-dvrk`` or ``dvrk``), else
  ``logged console`` (a bag or a deploy recording does not say whether a real PSM or ``sim-dvrk`` served it);
* the ``dvrk`` sensing preset's estimate along the same motion (:mod:`sim.force_sensing`);
* an identified arm's (:mod:`sim.identified_arm`) along the same motion: its free-space efforts and its
  residual, drawn as the model draws it.

With ``--calibration F.json`` (a ``calibrate-wrench`` file fitted on another log) it prints the same for what
a calibrated deploy reads: the calibrated error on the log with its accelerations (a deploy gives the
calibration the chain's commanded acceleration, which the arm tracks), the ``dvrk-calibrated`` preset's, and
the calibrated error with no acceleration at all, for scale, and what the identified arm's own parameters leave
with the log's accelerations (``<arm>, exact``): the least a calibration that found that arm exactly would leave,
on a ``sim-dvrk`` log (whose console draws its efforts from that arm) the floor below which no fit of the log's
velocities can go. Ratios are model over real: the presets' error
statistics should be within 25 % of the real ones (0.75-1.25) in the bins a log covers. A bin of fewer than
:data:`THIN_SAMPLES` samples is marked thin (``thin`` in the JSON): its RMS is a few samples', not the bin's.
After each table one line judges the preset (``dvrk``, ``dvrk-calibrated``) on the bins that are not thin:
within 0.75-1.25 x in every one, or ``MISMATCH`` with the ratios' range (``agreement`` in the JSON).

With ``--write-arm OUT.json --held-out LOG`` it first identifies an arm: ``calibrate-wrench``'s model fitted
on the ``--from`` logs, its residual (spread and correlation time per joint) measured on the held-out log,
written as :mod:`sim.identified_arm` reads it; then it compares on the held-out log. The shipped
``sim/data/identified_arm_wpi_psm.json`` was written so from the WPI PSM's logs (its ``provenance``).
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import itertools
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from hardware_if.wrench.bag_files import MAX_BAG_METADATA_BYTES
from hardware_if.wrench.calibration import read_calibration
from hardware_if.wrench.fit import (
    DEPTH_BINS_M,
    SPEED_BINS_M_S,
    PreparedLog,
    check_calibration,
    fit_calibration,
    prepare_log,
)
from hardware_if.wrench.joint_logs import read_joint_log
from psm_control.errors import ConfigurationError
from psm_control.inputs import check_output_path, given_as, load_yaml, read_text
from psm_control.robot import PsmModel
from sim.force_sensing import ArmResidual, ForceSensor, sensing_params
from sim.identified_arm import ARM_FILES, IdentifiedArm, identified_arm
from sim.strict_json import write_strict_json
from tissue_retract.cli._checks import int_in, output_file

__all__ = ["THIN_SAMPLES", "add_arguments", "run"]

#: A bin with fewer samples than this is thin: its RMS says little (the 0.75-1.25 comparison asks for 50 or more).
THIN_SAMPLES = 50
#: Log layouts recorded on real PSMs (:mod:`hardware_if.wrench.joint_logs`): the public WPI and radiang logs.
_REAL_PSM_LAYOUTS = {
    "wpi": "a real PSM's (the WPI-AIM/dvrk_dynamics_identification layout)",
    "radiang": "a real PSM's (the radiang/dvrk_parameter_identification layout)",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the target's options."""
    parser.add_argument(
        "--from",
        dest="logs",
        nargs="+",
        required=True,
        metavar="PATH",
        help="free-space joint logs (as calibrate-wrench --from reads them)",
    )
    parser.add_argument("--arm", default="PSM1", help="arm namespace in bags (default: PSM1)")
    parser.add_argument("--rate", type=float, default=None, help="sample rate of CSV logs [Hz] (default by layout)")
    parser.add_argument(
        "--identified-arm",
        default="wpi-psm",
        choices=sorted(ARM_FILES),
        help="the identified arm to compare (default: wpi-psm)",
    )
    parser.add_argument(
        "--calibration",
        metavar="F.json",
        default=None,
        help="also compare what a deploy calibrated by this file reads (fit it on another log)",
    )
    parser.add_argument(
        "--draws",
        type=int_in(1, 1000),
        default=16,
        help="the models' residual drawn this many times, their RMS over all draws (default: 16)",
    )
    parser.add_argument(
        "--write-arm",
        metavar="OUT.json",
        type=output_file("--write-arm"),
        default=None,
        help="identify an arm on the --from logs, its residual on --held-out, and write it",
    )
    parser.add_argument(
        "--held-out", nargs="+", metavar="PATH", default=None, help="with --write-arm: logs to check on"
    )


#: Where the friction band's speed is looked for: these quantiles of a joint's speeds on the held-out log.
_BAND_SPEED_QUANTILES = (0.01, 0.02, 0.05, 0.1, 0.2, 0.3, 0.5)


def _spread_with_speed(residual: np.ndarray, speed: np.ndarray) -> tuple[float, float, float]:
    """One joint's residual spread as :meth:`IdentifiedArm.residual_spread` models it: the moving spread, the
    band's and its speed, ``variance = moving**2 + band**2 exp(-speed / band_speed)``.

    For each band speed tried, the two variances are the least-squares fit of the squared residual (none
    negative); the speed kept is the one of largest Gaussian likelihood, no band when none is likelier.
    Written here: it is a two-parameter moment fit with a one-dimensional search.
    """
    squared = np.square(residual)
    best = (float(np.sqrt(squared.mean())), 0.0, 1.0)
    best_likelihood = -0.5 * squared.size * (float(np.log(squared.mean())) + 1.0)
    for band_speed in np.quantile(speed, _BAND_SPEED_QUANTILES):
        if band_speed <= 0.0:
            continue
        decay = np.exp(-speed / band_speed)
        design = np.column_stack([np.ones_like(decay), decay])
        moving, band = np.linalg.lstsq(design, squared, rcond=None)[0]
        if band <= 0.0 or moving <= 0.0:
            continue
        variance = moving + band * decay
        likelihood = -0.5 * float(np.sum(np.log(variance) + squared / variance))
        if likelihood > best_likelihood:
            best, best_likelihood = (float(np.sqrt(moving)), float(np.sqrt(band)), float(band_speed)), likelihood
    return best


def _write_arm(args: argparse.Namespace) -> tuple[IdentifiedArm, list[str]]:
    """Identify an arm on the ``--from`` logs, measure its residual on ``--held-out``, write it."""
    if not args.held_out:
        raise ConfigurationError("--held-out", None, "logs of the same arm to measure the residual on")
    fit = [prepare_log(read_joint_log(path, arm=args.arm, rate_hz=args.rate)) for path in args.logs]
    with given_as("--held-out", "--from"):
        held_out = [prepare_log(read_joint_log(path, arm=args.arm, rate_hz=args.rate)) for path in args.held_out]
    calibration, _ = fit_calibration(args.arm, fit, held_out)
    residual = np.concatenate([p.log.effort - p.model_efforts(calibration.parameter_vector()) for p in held_out])
    speed = np.abs(np.concatenate([p.qd for p in held_out]))
    spreads = [_spread_with_speed(residual[:, joint], speed[:, joint]) for joint in range(6)]
    moving, band, band_speed = (tuple(float(s[i]) for s in spreads) for i in range(3))
    name = Path(args.write_arm).stem.removeprefix("identified_arm_").replace("_", "-")
    arm = IdentifiedArm(
        name=name,
        columns=calibration.columns,
        parameters=calibration.parameters,
        residual=moving,
        residual_band=band,
        residual_band_speed=band_speed,
        residual_time_s=0.0,
        residual_bound_n=calibration.error_bound_with_acceleration_n,
        provenance=(
            f"tissue-retract bench sensing --from {' '.join(Path(p).name for p in args.logs)} --held-out "
            f"{' '.join(Path(p).name for p in args.held_out)} --write-arm {Path(args.write_arm).name}: "
            f"{len(calibration.parameters)} parameters on {calibration.samples} samples; held out, the console's "
            f"free-space error {calibration.rms_before_n:.2f} N RMS, the arm's residual {calibration.rms_after_n:.2f} N"
        ),
    )
    normalised = residual / arm.residual_spread(speed)
    lags = []
    for joint in range(6):  # the 1/e lag of each joint's residual over its spread, by autocorrelation
        x = normalised[:, joint] - normalised[:, joint].mean()
        correlation = np.correlate(x, x, "full")[len(x) - 1 :] / max(float(x @ x), 1e-30)
        lags.append(int(np.argmax(correlation < math.exp(-1.0))) / held_out[0].log.rate_hz)
    arm = dataclasses.replace(arm, residual_time_s=float(np.median(lags)))
    arm.write(Path(args.write_arm))
    print(f"identified arm written to {args.write_arm}: {arm.provenance}")
    return arm, list(args.held_out)


def _arm_errors(log: PreparedLog, arm: IdentifiedArm, efforts: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The identified arm's free-space error along the log's motion (N,) [N]: its efforts (``efforts``, (N, 6), the
    same for every draw) and its residual, drawn as the sensing model draws it."""
    residual = ArmResidual(arm, 1.0, rng)
    dt_s = 1.0 / log.log.rate_hz
    drawn = np.array([residual.advance(dt_s, qd) for qd in log.qd])
    return _norms(log, efforts + drawn)


def _norms(log: PreparedLog, efforts: np.ndarray) -> np.ndarray:
    """The console's force magnitude of ``efforts`` (N, 6) per sample, on the joints the log carries."""
    return np.linalg.norm(np.einsum("kij,kj->ki", log.projector, efforts * log.joint_mask), axis=1)


def _over_draws(draws: int, error: Callable[[np.random.Generator], np.ndarray]) -> np.ndarray:
    """A model's error per sample (N,) [N], root mean square over ``draws`` draws of its residual (seeds 0, 1, ...):
    the RMS of any bin of it is the model's expected RMS there, not one draw's."""
    return np.sqrt(np.mean([np.square(error(np.random.default_rng(seed))) for seed in range(draws)], axis=0))


def _preset_errors(log: PreparedLog, preset: str, rng: np.random.Generator) -> np.ndarray:
    """A sensing preset's free-space error along the log's motion (N,) [N]."""
    sensor = ForceSensor(sensing_params(preset), rng)
    configuration = PsmModel().configuration()
    dt_s = 1.0 / log.log.rate_hz
    efforts = np.zeros((len(log.log.q), 6))
    for k, q in enumerate(log.log.q):
        configuration.update(q)
        efforts[k] = sensor.efforts(configuration, log.qd[k], np.zeros(3), dt_s)
    return _norms(log, efforts)


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def _bins(key: np.ndarray, edges: tuple[float, ...], columns: dict[str, np.ndarray]) -> list[dict[str, Any]]:
    rows = []
    for low, high in itertools.pairwise(edges):
        inside = (key >= low) & (key < high)
        if np.any(inside):
            samples = int(inside.sum())
            rows.append(
                {"bin": [low, high if math.isfinite(high) else None], "samples": samples}
                | {"thin": samples < THIN_SAMPLES}
                | {name: _rms(values[inside]) for name, values in columns.items()}
            )
    return rows


def _log_console(path: str | Path, layout: str) -> tuple[str, str]:
    """Which console a log came from, as far as the log says: (``dvrk``, ``sim-dvrk`` or ``unknown``, why)."""
    if layout in _REAL_PSM_LAYOUTS:
        return "dvrk", _REAL_PSM_LAYOUTS[layout]
    metadata = Path(path) / "metadata.yaml"
    if layout == "rosbag2" and metadata.is_file():
        document = load_yaml(read_text(metadata, "--from", MAX_BAG_METADATA_BYTES), "--from", metadata)
        info = document.get("rosbag2_bagfile_information") if isinstance(document, dict) else None
        custom = info.get("custom_data") if isinstance(info, dict) else None
        named = custom.get("console") if isinstance(custom, dict) else None
        if named in ("dvrk", "sim-dvrk"):
            return str(named), f"named by the bag's metadata (custom_data: console: {named})"
    what = "a deploy recording" if layout == "recording" else "a rosbag2 bag"
    return "unknown", f"not named: {what} does not say whether a real PSM or sim-dvrk served it"


#: The first column's name by the console a log came from.
_CONSOLE_COLUMN = {"dvrk": "real console", "sim-dvrk": "sim-dvrk console", "unknown": "logged console"}
#: The calibrated column's name by the console a log came from.
_CALIBRATED_COLUMN = {"dvrk": "real, calibrated", "sim-dvrk": "sim-dvrk, calibrated", "unknown": "logged, calibrated"}


def _table(title: str, rows: list[dict[str, Any]], names: list[str], unit: str) -> list[str]:
    lines = [f"  {title:<14} {'samples':>7}  " + "  ".join(f"{n:>22}" for n in names)]
    for row in rows:
        low, high = row["bin"]
        scale = 100.0 if unit == "cm" else 1.0
        label = f"{low * scale:g}-{high * scale:g} {unit}" if high is not None else f">= {low * scale:g} {unit}"
        real = row[names[0]]
        cells = [f"{real:22.2f}"] + [f"{row[n]:13.2f} ({row[n] / real:4.2f} x)" for n in names[1:]]
        thin = f"  thin: fewer than {THIN_SAMPLES} samples" if row["samples"] < THIN_SAMPLES else ""
        lines.append(f"  {label:<14} {row['samples']:>7}  " + "  ".join(cells) + thin)
    return lines


def _compare(log: PreparedLog, columns: dict[str, np.ndarray]) -> dict[str, Any]:
    names = list(columns)
    return {
        "samples": len(log.log.q),
        "rms_n": {name: _rms(values) for name, values in columns.items()},
        "by_depth": _bins(log.insertion_m, DEPTH_BINS_M, columns),
        "by_speed": _bins(log.tip_speed_m_s, SPEED_BINS_M_S, columns),
        "columns": names,
    }


#: The ratios of a model's error RMS to the logged one within which the model describes the log's sensing.
AGREEMENT = (0.75, 1.25)


def agreement(result: dict[str, Any], name: str) -> dict[str, Any]:
    """Whether the column ``name`` is within :data:`AGREEMENT` of the logged column in every bin of
    :data:`THIN_SAMPLES` or more (by insertion and by tip speed): ``within``, the ratios' range and the bins
    judged."""
    logged = result["columns"][0]
    ratios = [
        row[name] / row[logged]
        for row in (*result["by_depth"], *result["by_speed"])
        if not row["thin"] and row[logged] > 0.0
    ]
    low, high = AGREEMENT
    return {
        "within": bool(ratios) and all(low <= r <= high for r in ratios),
        "ratio_min": min(ratios, default=None),
        "ratio_max": max(ratios, default=None),
        "bins_judged": len(ratios),
    }


def _agreement_line(result: dict[str, Any], name: str) -> str:
    """The verdict of :func:`agreement` in one line."""
    verdict, logged = result["agreement"][name], result["columns"][0]
    low, high = AGREEMENT
    if not verdict["bins_judged"]:
        return f"  {name}: no bin of {THIN_SAMPLES} samples or more to judge it on"
    spread = f"{verdict['ratio_min']:.2f}-{verdict['ratio_max']:.2f} x the error of {logged!r}"
    if verdict["within"]:
        return f"  {name}: within {low:g}-{high:g} x in every bin of {THIN_SAMPLES} samples or more ({spread})"
    return (
        f"  MISMATCH: {name} is {spread} in the bins of {THIN_SAMPLES} samples or more, not within {low:g}-{high:g} x: "
        f"figures computed with it describe another sensor than this log's"
    )


def _print(title: str, result: dict[str, Any], judged: tuple[str, ...] = ()) -> None:
    names = result["columns"]
    overall = ", ".join(f"{n} {result['rms_n'][n]:.2f}" for n in names)
    print(f"{title} ({result['samples']} samples), RMS [N]: {overall}")
    print("\n".join(_table("insertion", result["by_depth"], names, "cm")))
    print("\n".join(_table("tip speed", result["by_speed"], names, "m/s")))
    result["agreement"] = {name: agreement(result, name) for name in judged}
    for name in judged:
        print(_agreement_line(result, name))


def run(args: argparse.Namespace) -> int:
    """Measure and print."""
    inputs = (*(args.logs or ()), *(args.held_out or ()), args.calibration)
    for field, output in (("--write-arm", args.write_arm), ("--json", args.json)):
        if output is not None:  # checked as parsed; here against the logs it reads
            check_output_path(output, field, inputs)
    if args.write_arm:
        arm, paths = _write_arm(args)
    else:
        arm, paths = identified_arm(args.identified_arm), list(args.logs)
    with given_as("--calibration", "--wrench-calibration"):
        calibration = read_calibration(args.calibration, exact_console=True) if args.calibration else None
    results: dict[str, Any] = {"identified_arm": arm.name, "logs": {}}
    for path in paths:
        with given_as("--held-out" if args.write_arm else "--from", "--from"):  # --write-arm compares on --held-out
            log = prepare_log(read_joint_log(path, arm=args.arm, rate_hz=args.rate))
        console, said = _log_console(path, log.log.layout)
        arm_model = log.model_efforts(arm.parameter_vector())  # the identified arm's efforts along the log
        print(f"{path}: console: {console} ({said})")
        entry: dict[str, Any] = {
            "logged_by": {"console": console, "said_by": said, "layout": log.log.layout},
            "console": _compare(
                log,
                {
                    _CONSOLE_COLUMN[console]: _norms(log, log.log.effort),
                    "dvrk preset": _over_draws(args.draws, functools.partial(_preset_errors, log, "dvrk")),
                    f"{arm.name}": _over_draws(args.draws, functools.partial(_arm_errors, log, arm, arm_model)),
                },
            ),
        }
        _print(f"{path}: the console's free-space estimate", entry["console"], ("dvrk preset",))
        if calibration is not None:
            error = check_calibration(calibration, [log])
            entry["calibrated"] = _compare(
                log,
                {
                    _CALIBRATED_COLUMN[console]: error.after_n,
                    "dvrk-calibrated": _over_draws(
                        args.draws, functools.partial(_preset_errors, log, "dvrk-calibrated")
                    ),
                    "no acceleration": error.after_live_n,
                    f"{arm.name}, exact": _norms(log, log.log.effort - arm_model),
                },
            )
            _print(f"{path}: calibrated by {args.calibration}", entry["calibrated"], ("dvrk-calibrated",))
            if not entry["calibrated"]["agreement"]["dvrk-calibrated"]["within"]:
                rms = entry["calibrated"]["rms_n"]
                print(
                    f"  (the {arm.name} arm's own parameters leave {rms[f'{arm.name}, exact']:.2f} N RMS on this log, "
                    f"the calibration {rms[_CALIBRATED_COLUMN[console]]:.2f} N: on a log of that arm, or of sim-dvrk, "
                    "which draws its efforts from it, about the least a fit of its model leaves)"
                )
                print(
                    "  (tune-safety and robustness take this calibration's bound as their sensing with "
                    f"--wrench-calibration {args.calibration}, in place of --force-sensing dvrk-calibrated)"
                )
        results["logs"][path] = entry
    if args.json:
        write_strict_json(args.json, results, field="--json")
        print(f"written to {args.json}")
    return 0
