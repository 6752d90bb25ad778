"""``tissue-retract calibrate-wrench``: fit the dVRK's force-sensing errors in free space, for ``deploy``.

Offline, from logs (:mod:`hardware_if.wrench.joint_logs`: rosbag2 bags of ``/<ARM>/measured_js``, this project's
recordings, the public WPI and radiang CSV layouts)::

    tissue-retract calibrate-wrench --from A [B ...] [--held-out C] --out F.json
    tissue-retract calibrate-wrench --check F.json --from C [--json OUT.json]

The first fits on the ``--from`` logs and checks on ``--held-out`` (default: the last ``--from`` log when there
are several, else the last third of the one); the second prints the free-space force error of the console's
estimate and of the calibrated one on the logs, overall and by insertion depth and tool-tip speed, what a tare
at the grasp would leave of it (:mod:`hardware_if.wrench.drift`), how each joint's friction differs from the
file's (:mod:`hardware_if.wrench.friction_shift`), and its verdict: whether the file's bounds held on the samples
inside the regimes they cover (exit 1 when not).
A log is fitted or checked on only when it shows an arm moving under its own dynamics
(:func:`hardware_if.wrench.joint_logs.check_free_space_log`).

Live, with no tissue in the jaws, the arm is driven through two short excitation trajectories (Lissajous
motions of the tool tip with a yaw swing about the start, the tool 12 cm in and the jaws open, through the
whole control chain: IK, safety filter, Ruckig, verifier). The first is fitted
(:mod:`hardware_if.wrench.calibration`), the second held out: the command prints the free-space force error
of the console's estimate and of the calibrated one on it (RMS and largest, N), and writes the calibration
to ``--out`` for ``deploy --target dvrk --wrench-calibration F.json``. The arm must be ENABLED and homed
(``tissue-retract ready-arm --arm PSM1`` does that); nothing may touch the instrument meanwhile.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import shlex
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from psm_control.commands import CartesianDelta
from psm_control.errors import ConfigurationError, TissueRetractError
from psm_control.inputs import check_output_path, given_as
from psm_control.outputs import write_atomic
from psm_control.robot import PsmModel
from safety.config import SafetyConfig
from sim.force_sensing import error_bound_n, sensing_params
from sim.sweep.stopping import handling
from tissue_retract.cli._checks import float_in
from tissue_retract.cli._next import command, console_words, say_next
from tissue_retract.cli._ros import add_console_arguments, apply_console_arguments

if TYPE_CHECKING:  # the chain (numba, the QP solvers): imported only when the arm moves
    from safety.chain import ControlChain

__all__ = ["add_arguments", "run"]

#: Each trajectory's tip frequencies along x, y, z and its yaw frequency [Hz]: the fitted and the held-out
#: ones differ, so the check is on motions the fit did not see.
#: Tip speeds up to about 0.3 m/s, as the public real PSMs' identification runs (0.25-0.42 m/s), and 5 cm
#: about the start, within the workspace box: slower or smaller swings excite the gravity and inertia terms
#: too little for the fit to tell them from the arm's friction residual (on sim-dvrk: 1.1-1.3 x lower RMS
#: held out at half these amplitudes and speeds, 2-3 x at these).
_FREQUENCIES_HZ = ((0.62, 0.94, 0.46, 0.38), (0.82, 0.58, 0.74, 0.54))
_AMPLITUDE_M = np.array([0.05, 0.05, 0.03])
_YAW_AMPLITUDE_RAD = 0.8
#: The deadman of the excitation [s]: in free space, with no tissue held, a late measurement costs a sample,
#: not safety; a loaded machine's console is late by more than the deploy's 50 ms now and then.
_DEADMAN_S = 0.25
#: Holds for a late measurement an excitation resumes from before it gives up.
_MAX_HOLDS = 20
#: A new target for the chain every this many ticks (the policies' 10 Hz at the dVRK's 100 Hz).
_TICKS_PER_TARGET = 10
#: Log layouts (:mod:`hardware_if.wrench.joint_logs`) recorded on real PSMs: the public WPI and radiang logs.
_REAL_PSM_LAYOUTS = {"wpi", "radiang"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the subcommand to its parser."""
    parser.add_argument("--arm", default="PSM1", help="arm name / topic namespace (default: PSM1)")
    parser.add_argument("--out", metavar="F.json", help="where to write the calibration (fitting)")
    parser.add_argument(
        "--from",
        dest="logs",
        nargs="+",
        metavar="PATH",
        help="fit (or --check) offline on free-space joint logs: rosbag2 bags (folder, .mcap or .db3) with "
        "/ARM/measured_js, deploy recordings with efforts, WPI or radiang CSV logs",
    )
    parser.add_argument("--held-out", nargs="+", metavar="PATH", help="logs to check the offline fit on")
    parser.add_argument(
        "--check",
        metavar="F.json",
        help="print a calibration's free-space error on the --from logs, what a tare at the grasp would leave of it, "
        "each joint's friction against the file's, and whether the file's bounds held (exit 1 when not)",
    )
    parser.add_argument("--json", metavar="OUT.json", help="with --check: write the figures as JSON")
    parser.add_argument(
        "--rate", type=float_in(1.0, 10000.0), default=None, help="sample rate of CSV logs [Hz] (default by layout)"
    )
    parser.add_argument(
        "--duration",
        type=float_in(5.0, 600.0),
        default=20.0,
        help="seconds of each of the two trajectories, 5-600 (default: 20)",
    )
    parser.add_argument(
        "--wait", type=float_in(0.0, 3600.0, open_low=True), default=10.0, help="seconds to wait for the arm"
    )
    parser.add_argument(
        "--record",
        metavar="BAG",
        default=None,
        help="live: also keep both excitations as a rosbag2 bag (MCAP) of /ARM/measured_js, for --from",
    )
    add_console_arguments(parser, network_help="keep your ROS discovery settings instead of localhost-only")


def _excitation_jaw_rad() -> float:
    """The jaws during the excitation [rad]: open, as at an episode's start."""
    from sim.envs.base import EnvConfig  # the environments (PyBullet): only when the arm moves

    return float(EnvConfig().jaw_open_rad)


def _trajectory(
    client: Any, chain: ControlChain, frequencies: tuple[float, ...], duration_s: float, wait_s: float
) -> tuple[Any, list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]]:
    """Drive one excitation trajectory; return its measurements as a joint log, and each sample as a deploy
    computes its force from it: ``(q, qd, effort, commanded qdd)``, the console's velocity and the acceleration
    the chain commanded (:func:`_deployed_error`)."""
    jaw_rad = _excitation_jaw_rad()
    local = PsmModel().configuration()
    measured = client.wait_for_measurement(wait_s)
    chain.reset(measured)
    local.update(measured.q)
    start = local.local_pose()[:3, 3].copy()
    samples, deployed = [], []
    rate = chain.config.control_rate_hz
    ticks = round(duration_s * rate)
    next_tick = time.monotonic()
    holds = 0
    for tick in range(ticks):
        if tick % _TICKS_PER_TARGET == 0:
            t, later = tick / rate, (tick + _TICKS_PER_TARGET) / rate
            wave = np.array([math.sin(2 * math.pi * f * t) for f in frequencies[:3]])
            yaw = _YAW_AMPLITUDE_RAD * (
                math.sin(2 * math.pi * frequencies[3] * later) - math.sin(2 * math.pi * frequencies[3] * t)
            )
            local.update(measured.q)
            step = start + _AMPLITUDE_M * wave - local.local_pose()[:3, 3]
            # An arm that fell behind (a slow console) is led back to the wave, within what the chain accepts.
            reach = 0.5 * chain.config.max_translation_m
            step *= min(1.0, reach / max(float(np.linalg.norm(step)), 1e-12))
            chain.set_target(CartesianDelta(step, yaw, jaw_rad, "local"), measured)
        output = chain.tick(measured)
        if output.safety_stop:
            raise RuntimeError(f"the control chain stopped the excitation: {output.reason}")
        client.servo_jp(output.command)
        commanded_qdd = np.asarray(output.command.qdd, dtype=float).copy()
        status = client.status
        if status.holding:  # a late measurement: the arm held; resume from where it is, without the sample
            holds += 1
            if holds > _MAX_HOLDS:
                raise RuntimeError(f"the arm held {holds} times, last: {status.reason}")
            measured = client.next_measurement(measured.stamp_s, wait_s)
            client.resume()
            chain.reset(measured)
            next_tick = time.monotonic()
            continue
        # Paced by the clock, as deploy is: the chain's deadman compares its own clock with the arm's.
        next_tick += 1.0 / rate
        delay = next_tick - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        else:
            next_tick = time.monotonic()
        measured = client.measure()
        samples.append((measured.stamp_s, np.asarray(measured.q), np.asarray(measured.qd), client.efforts()))
        deployed.append((samples[-1][1], samples[-1][2], samples[-1][3], commanded_qdd))
    from hardware_if.wrench.joint_logs import joint_log_from_ticks

    return joint_log_from_ticks("calibrate-wrench excitation", "live", samples), deployed


def _deployed_error(calibration: Any, deployed: Sequence[tuple[np.ndarray, ...]]) -> tuple[float, int]:
    """The largest calibrated free-space error as a deploy computes it [N], over the samples at retraction speeds
    whose commanded accelerations are within those the calibration was fitted on (the regime its bound covers; at
    any speed when fewer than ``MIN_REGIME_SAMPLES`` are that slow), and how many samples it was taken over.

    A deploy gives the calibration the console's velocity and the chain's commanded acceleration
    (:class:`hardware_if.client.arm_listener.ArmListener`), not the filtered ones the fit and its held-out figures
    use; where the arm's acceleration is not the commanded one (a console whose arm lags or steps), the deploy's
    error is larger than those figures say. The excitation knows what it commanded, so it measures that error too.
    """
    from hardware_if.wrench.fit import MIN_INSERTION_M, MIN_REGIME_SAMPLES, RETRACTION_TIP_SPEED_M_S

    configuration = PsmModel().configuration()
    errors, speeds = [], []
    for q, qd, effort, qdd in deployed:
        if q[2] < MIN_INSERTION_M or not calibration.covers(qdd):
            continue
        configuration.update(q)
        errors.append(float(np.linalg.norm(calibration.force(configuration, qd, effort, qdd))))
        speeds.append(float(np.linalg.norm(configuration.base_jacobian()[:3] @ qd)))
    values, slow = np.asarray(errors), np.asarray(speeds) <= RETRACTION_TIP_SPEED_M_S
    judged = values[slow] if np.count_nonzero(slow) >= MIN_REGIME_SAMPLES else values
    return (float(judged.max()) if len(judged) else 0.0), len(judged)


def _covering_deploys(calibration: Any, deployed: Sequence[tuple[np.ndarray, ...]]) -> tuple[Any, str]:
    """The calibration with its bounds raised to cover the held-out error as a deploy computes it
    (:func:`_deployed_error`), and a line saying what was measured."""
    from hardware_if.wrench.fit import BOUND_MARGIN

    largest, count = _deployed_error(calibration, deployed)
    needed = BOUND_MARGIN * largest
    line = (
        f"as a deploy computes it (the console's velocity, the chain's commanded acceleration): largest held-out "
        f"error {largest:.3f} N over {count} samples"
    )
    if needed <= calibration.error_bound_with_acceleration_n:
        return calibration, f"{line}, within the bound"
    raised = dataclasses.replace(
        calibration,
        error_bound_with_acceleration_n=needed,
        error_bound_n=max(calibration.error_bound_n, needed),
    )
    return raised, f"{line}: the bounds cover {BOUND_MARGIN:g} x that"


def _to_start(client: Any, wait_s: float) -> None:
    """Move to the excitation's start (the tool 12 cm in, the wrist straight, the jaws open) with the
    console's move_jp.

    A homed PSM rests with the tool at the RCM, where the chain refuses to work (the dVRK's 45 mm minimum).
    Open jaws hold nothing, so the chain's tissue-force limit stays out of the excitation (see :func:`run`).
    """
    from hardware_if.client.arm_pose import return_to_start

    reason = return_to_start(client, PsmModel().home(), wait_s, start_jaw=_excitation_jaw_rad())
    if reason:
        raise RuntimeError(f"the arm did not reach the excitation's start: {reason}")


def _table(summary: dict[str, Any]) -> str:
    """The binned figures as text: one line per insertion-depth and tip-speed bin."""
    lines = [
        f"free-space force error over {summary['samples']} samples: console RMS {summary['rms_before_n']:.2f} N, "
        f"max {summary['max_before_n']:.2f} N; calibrated RMS {summary['rms_after_n']:.2f} N, "
        f"max {summary['max_after_n']:.2f} N "
        f"({summary['rms_before_n'] / max(summary['rms_after_n'], 1e-12):.1f} x lower RMS)",
        "  without the acceleration (as a deploy computes it): "
        f"RMS {summary['rms_after_without_acceleration_n']:.2f} N",
        f"  largest calibrated error at tip speeds <= {summary['retraction_tip_speed_m_s']:g} m/s: "
        f"{summary['max_after_retraction_speed_n']:.2f} N",
        "  bin                 samples  console RMS / max  calibrated RMS / max [N]",
    ]
    for key, label, unit, scale in (
        ("by_depth", "insertion_m", "cm", 100.0),
        ("by_speed", "tip_speed_m_s", "m/s", 1.0),
    ):
        for row in summary[key]:
            low, high = row[label]
            span = f"{scale * low:g}-{scale * high:g} {unit}" if high is not None else f">= {scale * low:g} {unit}"
            lines.append(
                f"  {span:<18} {row['samples']:>8}  {row['rms_before_n']:>6.2f} / {row['max_before_n']:>6.2f}"
                f"      {row['rms_after_n']:>6.2f} / {row['max_after_n']:>6.2f}"
            )
    return "\n".join(lines)


def _offline(args: argparse.Namespace) -> int:
    """Fit on logs or check a calibration on them; 0, or 1 with the reason."""
    from hardware_if.wrench.calibration import read_calibration
    from hardware_if.wrench.drift import change_line, error_change
    from hardware_if.wrench.fit import (
        bound_verdict,
        check_calibration,
        coverage_line,
        effort_residuals,
        fit_calibration,
        prepare_log,
        unimproved,
        verdict_line,
    )
    from hardware_if.wrench.friction_shift import friction_line, friction_shift
    from hardware_if.wrench.joint_logs import MIN_SAMPLES, check_free_space_log, read_joint_log

    def prepared(paths: list[str], field: str = "--from") -> list[Any]:
        with given_as(field, "--from"):
            return [prepare_log(read_joint_log(path, arm=args.arm, rate_hz=args.rate)) for path in paths]

    if args.check is not None:
        if args.json:
            check_output_path(args.json, "--json", (args.check, *args.logs))
        with given_as("--check", "--wrench-calibration"):
            calibration = read_calibration(args.check, exact_console=True)  # checked on logs, not a console
        logs = prepared(args.logs)
        error = check_calibration(calibration, logs)
        print(f"the logs cover {coverage_line(logs)}")
        verdict = bound_verdict(calibration, error)
        residuals = effort_residuals(calibration, logs)  # one pass over the logs' regressors for both
        change, friction = error_change(calibration, logs, residuals), friction_shift(logs, residuals)
        summary = error.summary() | verdict | {"error_change_one_way": change, "friction_shift": friction}
        print(_table(summary))
        print(change_line(change))
        print(friction_line(friction))
        print(verdict_line(verdict))
        if args.json:
            write_atomic(args.json, json.dumps(summary, indent=2) + "\n", "--json")
            print(f"written to {args.json}")
        if verdict["bound_held"]:
            say_next(
                f"{command('ready-arm', '--arm', args.arm)} (enable, home, to the episodes' start), then deploy "
                f"--target dvrk --wrench-calibration {shlex.quote(args.check)} --dry-run"
            )
        return 0 if verdict["bound_held"] else 1
    if args.out is None:
        raise ConfigurationError("--out", None, "a file to write the calibration to (or --check F.json)")
    output = check_output_path(args.out, "--out", (*args.logs, *(args.held_out or ())))
    logs = [read_joint_log(path, arm=args.arm, rate_hz=args.rate) for path in args.logs]
    if args.held_out:
        fit, held_out = [prepare_log(log) for log in logs], prepared(args.held_out, "--held-out")
    elif len(logs) > 1:
        fit, held_out = [prepare_log(log) for log in logs[:-1]], [prepare_log(logs[-1])]
    else:
        log, cut = logs[0], 2 * len(logs[0].t_s) // 3
        check_free_space_log(log, min_samples=3 * MIN_SAMPLES)  # a third of it is held out
        parts = [
            dataclasses.replace(log, t_s=log.t_s[s], q=log.q[s], qd=log.qd[s], effort=log.effort[s])
            for s in (slice(0, cut), slice(cut, None))
        ]
        fit, held_out = [prepare_log(parts[0])], [prepare_log(parts[1])]
    calibration, error = fit_calibration(args.arm, fit, held_out)
    layouts = sorted({p.log.layout for p in fit})
    # The public CSV layouts are real PSMs' logs; a bag or a recording may come from any console.
    console = "dvrk" if set(layouts) <= _REAL_PSM_LAYOUTS else "unknown"
    calibration = dataclasses.replace(calibration, sensing=f"logs: {', '.join(layouts)}", console=console)
    print(f"the logs cover, fitted on: {coverage_line(fit)}; held out: {coverage_line(held_out)}")
    print(f"fitted {len(calibration.parameters)} parameters on {calibration.samples} samples; held out:")
    print(_table(error.summary()))
    print(
        f"error bound for the safety filter: {calibration.error_bound_n:.2f} N without the acceleration "
        f"(a deploy), {calibration.error_bound_with_acceleration_n:.2f} N with it"
    )
    refusal = unimproved(calibration)
    if refusal:
        print(
            f"tissue-retract calibrate-wrench: error: {refusal}; no calibration written (fit and check on "
            "free-space logs of this arm that cover the poses and speeds it is used at)",
            file=sys.stderr,
        )
        return 1
    calibration.write(Path(output))
    print(f"written to {output} (fitted on {calibration.origin})")
    say_next(
        f"{command('calibrate-wrench', '--check', str(output), '--from', 'LOG')} (a free-space log of this arm "
        f"the fit has not seen), then deploy --target dvrk --wrench-calibration {shlex.quote(str(output))}"
    )
    return 0


def run(args: argparse.Namespace) -> int:
    """Calibrate, print the held-out errors, write the file; 0, or 1 with the reason."""
    if args.logs:
        try:
            return _offline(args)
        except TissueRetractError as e:
            print(f"tissue-retract calibrate-wrench: error: {e}", file=sys.stderr)
            return 1
    if args.check is not None:
        print(
            "tissue-retract calibrate-wrench: error: --check needs --from PATH (the logs to check on)", file=sys.stderr
        )
        return 1
    if args.out is None:
        print("tissue-retract calibrate-wrench: error: --out F.json is required", file=sys.stderr)
        return 1
    output = check_output_path(args.out, "--out", (args.record,))
    space = None
    if args.record is not None:  # before the arm moves: the bag's folder, and room for both excitations
        from hardware_if.wrench.bag_writer import reserve_bag_space

        space = reserve_bag_space(args.record, 2 * math.ceil(args.duration * 100.0))
    try:
        return _live(args, output, space)
    finally:
        if space is not None:
            space.discard()


def _live(args: argparse.Namespace, output: Path, space: Any) -> int:
    """Drive both excitations, keep them (``--record``), fit, write the calibration; 0, or 1 with the reason."""
    apply_console_arguments(args)
    # The ros extra, imported after the environment it reads is set.
    from hardware_if.client.psm_client import PsmClient
    from hardware_if.common.commander_watch import console_kind, served_by
    from hardware_if.common.errors import DvrkError
    from hardware_if.common.session import ros_session
    from hardware_if.deploy.stopping import STOP_SIGNALS, Interrupted
    from hardware_if.wrench.bag_writer import write_joint_bag
    from hardware_if.wrench.fit import fit_calibration, prepare_log, unimproved
    from hardware_if.wrench.joint_logs import JointLogError

    # The console's force estimate is what is being calibrated: in free space all of it is error (10 N and more
    # on a real arm). The chain is told so, as deploy tells it for an uncalibrated dVRK: taken for a tissue
    # force, it made the retraction-force limit back the tool off along it and steered the excitation up to
    # the workspace box's top (measured: the limit intervened in 3491 of 3553 ticks).
    from safety.chain import ControlChain

    config = dataclasses.replace(
        SafetyConfig(),
        control_rate_hz=100.0,
        deadman_timeout_s=_DEADMAN_S,
        force_sensing_error_n=error_bound_n(sensing_params("dvrk")),
    )
    chain = ControlChain(config)
    node = f"{args.arm.lower()}_calibrate_wrench"
    stage = "waiting for the arm"

    def stop(signum: int, _frame: Any) -> None:
        raise Interrupted(signum)

    # Stop signals of its own, not rclpy's: rclpy's shut the context down under the next servo_jp ("Failed to
    # publish: publisher's context is invalid"); these stop between two statements and leave the node cleanly.
    try:
        with handling(STOP_SIGNALS, stop):
            with (
                ros_session(signal_handlers=False),
                PsmClient(args.arm, node_name=node, deadman_timeout_s=_DEADMAN_S) as client,
            ):
                try:
                    client.wait_for_measurement(args.wait)
                    reason = client.wait_ready(args.wait)
                    if reason:
                        print(
                            f"tissue-retract calibrate-wrench: error: {reason} "
                            f"(tissue-retract ready-arm --arm {args.arm} enables and homes it)",
                            file=sys.stderr,
                        )
                        return 1
                    stage = "moving to the excitation's start"
                    _to_start(client, args.wait)
                    stage = "excitation 1 of 2"
                    print(f"{args.arm}: free space, no tissue in the jaws: {stage} ({args.duration:g} s)", flush=True)
                    fit, _ = _trajectory(client, chain, _FREQUENCIES_HZ[0], args.duration, args.wait)
                    stage = "excitation 2 of 2"
                    print(f"{args.arm}: {stage}, held out ({args.duration:g} s)", flush=True)
                    _to_start(client, args.wait)  # about the same start: the box has room for one swing
                    held_out, deployed = _trajectory(client, chain, _FREQUENCIES_HZ[1], args.duration, args.wait)
                    consoles = served_by(client, args.arm)  # by now discovery has brought the console's name
                except (DvrkError, RuntimeError) as e:
                    print(f"tissue-retract calibrate-wrench: error: {e}; the arm holds where it is", file=sys.stderr)
                    return 1
            record_error = None
            if args.record is not None:  # kept before the fit, which may refuse to write a calibration
                try:
                    write_joint_bag(
                        args.record,
                        args.arm,
                        [fit, held_out],
                        start_s=time.time(),
                        space=space,
                        console=None if console_kind(consoles) == "unknown" else console_kind(consoles),
                    )
                    print(f"excitation recorded to {args.record} (/{args.arm}/measured_js, both trajectories)")
                except TissueRetractError as e:  # the fit still runs: the calibration keeps what the arm did
                    record_error = e
                    print(f"tissue-retract calibrate-wrench: error: {e}; fitting all the same", file=sys.stderr)
            if not np.any(fit.effort) and not np.any(held_out.effort):
                print(
                    f"tissue-retract calibrate-wrench: error: {args.arm}'s console reported every joint effort as 0 "
                    "in free space: it reports the exact force (as sim-dvrk --wrench ideal does) or sends no "
                    "efforts. An exact console needs no calibration: deploy with --force-sensor N, N the force "
                    "sensor's error bound [N], not --wrench-calibration; no calibration written",
                    file=sys.stderr,
                )
                return 1
            stage = "the fit"
            try:
                calibration, _ = fit_calibration(args.arm, [prepare_log(fit)], [prepare_log(held_out)])
            except JointLogError as e:
                print(
                    "tissue-retract calibrate-wrench: error: the excitation's joint log does not show an arm moving "
                    f"under its own dynamics: expected {e.reason}; no calibration written",
                    file=sys.stderr,
                )
                return 1
    except Interrupted as e:
        print(
            f"tissue-retract calibrate-wrench: stopped by {signal.Signals(e.signum).name} during {stage}: "
            "no calibration written; the arm holds where it is",
            file=sys.stderr,
        )
        return 128 + e.signum
    calibration = dataclasses.replace(calibration, sensing="measured_js", console=console_kind(consoles))
    calibration, deployed_line = _covering_deploys(calibration, deployed)
    print(
        f"free-space force error on the held-out trajectory ({len(held_out.t_s)} samples): "
        f"before RMS {calibration.rms_before_n:.3f} N, max {calibration.max_before_n:.3f} N; "
        f"after RMS {calibration.rms_after_n:.3f} N, max {calibration.max_after_n:.3f} N "
        f"({calibration.rms_before_n / max(calibration.rms_after_n, 1e-12):.1f} x lower RMS)"
    )
    print(deployed_line)
    print(
        f"error bound for the safety filter: {calibration.error_bound_n:.3f} N "
        f"({calibration.error_bound_with_acceleration_n:.3f} N with the acceleration known)"
    )
    refusal = unimproved(calibration)
    if refusal:
        print(
            f"tissue-retract calibrate-wrench: error: {refusal}; no calibration written. Empty the jaws, "
            f"nothing touching the instrument, then tissue-retract ready-arm --arm {args.arm} and calibrate again",
            file=sys.stderr,
        )
        return 1
    calibration.write(Path(output))
    print(f"written to {output} (fitted on {calibration.origin})")
    if record_error is not None:
        print(f"tissue-retract calibrate-wrench: error: {record_error}", file=sys.stderr)
        return 1
    say_next(
        f"{command('ready-arm', '--arm', args.arm, *console_words(args))} (back to the episodes' start: a dry run "
        f"moves nothing), then deploy --target dvrk --wrench-calibration {shlex.quote(str(output))} --dry-run"
    )
    return 0
