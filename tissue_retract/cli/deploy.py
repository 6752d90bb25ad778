"""``tissue-retract deploy``: run a policy through the safety chain, in the simulation or on a dVRK.

POLICY is ``scripted``, ``random``, ``module:callable`` or a checkpoint path, as for ``evaluate``.
``--target sim`` runs the task's PyBullet environment; ``--target dvrk`` drives the arm's CRTK topics
over ROS 2 with the same chain (``tissue-retract sim-dvrk --task ID`` serves a simulated one). The
observation is assembled from ``measured_cp``, ``jaw/measured_js``, ``body/measured_cf`` and a task source:

- ``--site X Y Z`` (or ``--registration FILE`` from ``tissue-retract register``): no perception needed. The
  site is where the operator registered it, the goal is ``--goal X Y Z`` or the task's nominal goal about
  the site, the grasp is sensed by the jaw stalling on tissue (``jaw/measured_js`` vs ``jaw/setpoint_js``),
  and while grasped the site moves with the jaws (:mod:`hardware_if.client.task_estimate`). No task topic is read;
  success is then an estimate (``sim-dvrk --blind --truth FILE`` scores it).
- ``--task-topics`` (the default without ``--site``): ``/<arm>/task/{site,goal,achieved_goal,grasped}``,
  from a perception node, or from ``sim-dvrk`` without ``--blind``.

An arm that is not ENABLED and homed is enabled and homed first (not in a dry run).

One commander per arm (docs/one-commander.md): before anything is sent to the console (its first command
waits 3.5 s for discovery) and every 0.1 s after, any other node publishing the arm's command topics, or
a second console, is a hold that names it (``HOLD: another commander: /node publishes /PSM1/servo_jp``).
Each episode starts from the task's start joints: an arm elsewhere is moved there with ``move_jp`` (a dry
run holds instead), and a measured pose that stops following the commands holds (tracking divergence).
A recording that cannot be written is a hold too: ``HOLD: recording failed: <path>: <os error>``.

``--dry-run`` (dVRK) listens to the live arm and computes, logs and records every command but creates
no command publisher: nothing is published on servo_jp, servo_cp, move_jp, move_cp, jaw/servo_jp or
jaw/move_jp. It ends with a report: commands it would have sent, safety interventions, predicted forces.

Every fault ends in the same hold: the policy raising or returning anything but 5 finite numbers, a policy
step slower than ``--policy-budget`` (default one policy period, 0.05 s), malformed or non-finite data on
a subscribed topic, an arm not ENABLED, homed and idle when an episode starts (waited for up to
``--wait``), a stale or vanished arm (a ``measured_js`` whose stamp stops advancing, goes back or jumps
included), a tracking error. Deploy then stops commanding (the arm keeps the last verified command), records
the fault, prints ``HOLD: <reason>`` and exits with status 4.
Ctrl-C (SIGINT), SIGTERM and SIGHUP stop between two control ticks and close the recording; the exit
status is 128 + the signal: 130, 143, 129. A run in which the force certainly exceeded the limit (``FORCE
LIMIT ... EXCEEDED``: the true force in the simulation, the measured force beyond the limit plus the
sensing's error bound on a dVRK) exits with status 3, unless it held (4) or was stopped (128 + the signal).
Every run is recorded to MCAP (``--record``, default ``runs/deploy-<time>.mcap``; see ``replay``; an existing
recording is kept: the run is refused unless ``--force`` replaces it), with its
3-D scene in Foxglove's schemas: the measured arm, the commanded arm (translucent blue; in a dry run, where
it would be sent), the tissue, site, goal and force, and holds as log messages; ``--live [PORT]`` serves the
same scene on ws://127.0.0.1:PORT while it runs (layout: ``docs/foxglove/tissue-retract-layout.json``).

Discovery stays on localhost (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) for dry runs and unless
``--network`` is given; ``--domain-id`` (default ``$ROS_DOMAIN_ID`` or 0) must match the robot's. To reach
a real console on another machine pass ``--network`` and the console's domain id, and make sure
``ROS_AUTOMATIC_DISCOVERY_RANGE``/``ROS_STATIC_PEERS`` in your environment reach it.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import time
from pathlib import Path

from hardware_if.client.registration import read_registration
from hardware_if.common.task_topics import DEFAULT_RIG
from hardware_if.deploy.options import DeployOptions
from hardware_if.wrench.calibration import read_calibration
from policies.resolve import POLICY_NAMES, names_a_checkpoint
from psm_control.errors import ConfigurationError
from psm_control.inputs import check_output_path, given_as
from safety.config import MAX_CONTROL_RATE_HZ, MIN_CONTROL_RATE_HZ, load_safety_config
from sim.force_sensing import error_bound_n, sensing_params
from tissue_retract.cli._camera import (
    add_perception_argument,
    add_texture_argument,
    check_texture,
    load_perception,
    texture_warning,
)
from tissue_retract.cli._checks import MAX_EPISODES, float_in, int_in
from tissue_retract.cli._live import add_live_argument
from tissue_retract.cli._next import command, replay_command, say_next, without_options
from tissue_retract.cli._ros import add_console_arguments, apply_console_arguments, point_argument
from tissue_retract.cli._sensing import add_force_sensing_argument, announce

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the subcommand to its parser."""
    parser.add_argument(
        "--policy",
        required=True,
        help=f"{POLICY_NAMES}; pretrained is the policy shipped for the task and the force sensing the run has "
        "(--force-sensing with --target sim; with --target dvrk the console's: dvrk, or dvrk-calibrated with "
        "--wrench-calibration) and, with --perception camera, the camera's",
    )
    parser.add_argument("--target", required=True, choices=("sim", "dvrk"), help="simulation or a dVRK over ROS 2")
    parser.add_argument("--task", default="lift", help="task id: lift, target, multisite, expose (default: lift)")
    parser.add_argument("--arm", default="PSM1", help="arm name / topic namespace (default: PSM1)")
    parser.add_argument(
        "--rate",
        type=float_in(MIN_CONTROL_RATE_HZ, MAX_CONTROL_RATE_HZ),
        default=None,
        help=f"control rate [Hz], {MIN_CONTROL_RATE_HZ:g}-{MAX_CONTROL_RATE_HZ:g} (default: 100 on the dVRK, the "
        "simulation's in sim)",
    )
    parser.add_argument("--dry-run", action="store_true", help="compute and record, publish nothing on motion topics")
    parser.add_argument("--safety-config", metavar="FILE", default=None, help="control chain settings (.toml/.yaml)")
    parser.add_argument("--record", metavar="FILE.mcap", default=None, help="MCAP recording (default: runs/...)")
    parser.add_argument("--force", action="store_true", help="replace an existing --record file")
    add_force_sensing_argument(
        parser,
        note=". --target sim only: with --target dvrk the filter senses what the console measures (dvrk, or "
        "dvrk-calibrated with --wrench-calibration), and --policy pretrained takes the policy shipped for that "
        "sensing",
    )
    parser.add_argument(
        "--wrench-calibration",
        metavar="F.json",
        default=None,
        help="dvrk only: the force-sensing calibration calibrate-wrench wrote; the safety filter trusts the force "
        "to its held-out error (default: the console's uncompensated measured_cf, to its model's error bound)",
    )
    parser.add_argument(
        "--force-sensor",
        metavar="NEWTONS",
        type=float,
        default=None,
        help="dvrk only, not with --wrench-calibration: the console's measured_cf comes from a force sensor at the "
        "instrument (its force source set to it), off by at most NEWTONS; the safety filter trusts the force to that "
        "and --policy pretrained takes the policy shipped for exact sensing",
    )
    source = parser.add_mutually_exclusive_group()
    point_argument(
        source, "--site", "dvrk: the registered grasp site [m] in <arm>_base; the task state comes from it and the jaw"
    )
    source.add_argument(
        "--registration", metavar="FILE", default=None, help="dvrk: the site from `tissue-retract register --out FILE`"
    )
    source.add_argument(
        "--task-topics",
        action="store_true",
        help="dvrk: site, goal and grasp from /<arm>/task/* (a perception node); the default without --site",
    )
    point_argument(
        parser,
        "--goal",
        "with --site/--registration or --perception camera: where the site must go [m] in <arm>_base (default: "
        "the task's nominal goal about the site, which with the camera carries the estimate's error)",
    )
    add_perception_argument(parser)
    parser.add_argument(
        "--camera-site",
        choices=("centre", "left", "right"),
        default="centre",
        help="dvrk with --perception camera: which of the flap's named sites the episodes grasp (default: "
        "centre; sim-dvrk --blind prints the episode's)",
    )
    parser.add_argument(
        "--image-timeout",
        type=float_in(0.0, 60.0, open_low=True),
        default=0.5,
        metavar="SECONDS",
        help="dvrk with --perception: endoscope images older than this hold the arm (default: 0.5)",
    )
    parser.add_argument(
        "--endoscope-rig",
        default=DEFAULT_RIG,
        metavar="RIG",
        help=f"dvrk with --perception: the stereo rig of /RIG/{{left,right}}/image_raw (default: {DEFAULT_RIG})",
    )
    add_texture_argument(parser)
    add_live_argument(parser)
    parser.add_argument("--episodes", type=int_in(1, MAX_EPISODES), default=1, help="episodes (default: 1)")
    parser.add_argument(
        "--seed", type=int_in(0, 2**31 - 1 - MAX_EPISODES), default=0, help="seed of the first episode (default: 0)"
    )
    parser.add_argument(
        "--wait",
        type=float_in(0.0, 3600.0, open_low=True),
        default=30.0,
        help="seconds to wait for the arm (ENABLED, homed) and the task topics",
    )
    parser.add_argument(
        "--policy-budget",
        type=float_in(0.0, 3600.0, open_low=True),
        default=None,
        metavar="SECONDS",
        help="longest a policy step may take before the arm is held (default: one policy period)",
    )
    add_console_arguments(
        parser, network_help="dvrk only, not with --dry-run: keep your ROS discovery settings instead of localhost-only"
    )


def _default_record() -> Path:
    """``runs/deploy-<time>.mcap``, with ``-2``, ``-3`` ... when a run in the same second has it."""
    stem = Path("runs") / f"deploy-{time.strftime('%Y%m%d-%H%M%S')}"
    path, index = stem.with_suffix(".mcap"), 1
    while path.exists():
        index += 1
        path = stem.with_name(f"{stem.name}-{index}.mcap")
    return path


def run(args: argparse.Namespace) -> int:
    """Deploy, print the report, return 0, 3 (force limit certainly exceeded), 4 (hold) or 128 + the stop signal
    (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP)."""
    if args.network and args.dry_run:
        raise ConfigurationError("--network", True, "not with --dry-run: dry runs stay on localhost")
    if args.target == "dvrk":
        apply_console_arguments(args)
        if args.force_sensing != "ideal":
            raise ConfigurationError(
                "--force-sensing", args.force_sensing, "sim only: a dVRK senses what its console measures"
            )
    elif args.wrench_calibration is not None:
        raise ConfigurationError("--wrench-calibration", args.wrench_calibration, "dvrk only")
    elif args.force_sensor is not None:
        raise ConfigurationError("--force-sensor", args.force_sensor, "dvrk only: the simulation's is --force-sensing")
    sensing_error_n, sensing_source, calibration = None, "dvrk measured_cf, uncompensated", None
    if args.force_sensor is not None:
        if args.wrench_calibration is not None:
            raise ConfigurationError(
                "--force-sensor", args.force_sensor, "either a force sensor or --wrench-calibration, not both"
            )
        sensing_error_n = args.force_sensor  # its bound is checked with the options (DeployOptions)
        sensing_source = f"a force sensor on measured_cf, off by at most {args.force_sensor:g} N as declared"

    calibration_path, calibration_sha256 = None, None
    if args.wrench_calibration is not None:
        # Refused here, before the recording is opened: another arm's, a bound its own fit contradicts, one
        # fitted on exact forces (see read_calibration).
        calibration = read_calibration(args.wrench_calibration, args.arm)
        # The recording names the file by its digest too: a path is rewritten by the next calibrate-wrench.
        calibration_path = Path(args.wrench_calibration).resolve()
        calibration_sha256 = hashlib.sha256(calibration_path.read_bytes()).hexdigest()  # at most 1 MiB, checked
        # The deploy gives the calibration the chain's commanded acceleration: the bound fitted with one.
        sensing_error_n = calibration.error_bound_with_acceleration_n
        sensing_source = (
            f"dvrk measured_js efforts, calibrated by {args.wrench_calibration} (fitted on {calibration.origin})"
        )
    elif args.target == "dvrk" and args.force_sensor is None:
        sensing_error_n = error_bound_n(sensing_params("dvrk"))

    safety_config = None
    if args.safety_config is not None:
        safety_config = load_safety_config(args.safety_config)
    if names_a_checkpoint(args.policy):
        # Read and checked before the recording is opened: a file that is no checkpoint is a refusal, not a fault
        # of a run that has begun (the arm held, a recording left behind).
        from policies.checkpoint import load_checkpoint  # torch: only for a checkpoint

        load_checkpoint(args.policy)
    record = Path(args.record) if args.record else _default_record()
    site = args.site
    if args.registration is not None:
        site = read_registration(args.registration, args.arm)
    # A sensing error bound the options refuse can only be --force-sensor's: a calibration's is checked as it is read.
    with given_as("--force-sensor", "force_sensing_error_n"):
        options = DeployOptions(
            policy=args.policy,
            target=args.target,
            record=record,
            task=args.task,
            arm=args.arm,
            rate_hz=args.rate,
            dry_run=args.dry_run,
            safety_config=safety_config,
            episodes=args.episodes,
            seed=args.seed,
            wait_s=args.wait,
            policy_budget_s=args.policy_budget,
            live=args.live,
            site=None if site is None else tuple(site),
            goal=None if args.goal is None else tuple(args.goal),
            camera_site=args.camera_site,
            force_sensing=args.force_sensing,
            force_sensing_error_n=sensing_error_n,
            force_sensing_source=sensing_source,
            wrench_calibration=calibration,
            force_sensor=args.force_sensor is not None,
            wrench_calibration_path=calibration_path,
            wrench_calibration_sha256=calibration_sha256,
            perception=args.perception,
            image_timeout_s=args.image_timeout,
            endoscope_rig=args.endoscope_rig,
            texture=check_texture(args.texture) if args.texture is not None else None,
        )
    # After every input the options check: the record's folder is made here, and a refused input leaves none.
    inputs = (args.policy, args.safety_config, args.wrench_calibration, args.registration, args.texture)
    check_output_path(
        record,
        "--record",
        inputs,
        existing=None if args.force else "a new file: an earlier recording is kept unless --force replaces it",
    )
    # Refused here, before anything connects, if it is not a model.
    announce(texture_warning(load_perception(args.perception), options.texture))
    if args.target == "dvrk":
        bound = (
            "its error_bound_with_acceleration_n: the calibration is given the chain's commanded acceleration, "
            f"and the bound holds while the arm tracks it, with {calibration.regime_words()}; beyond them, to "
            f"its error_bound_n {calibration.error_bound_n:.3g} N up to tip speeds of "
            f"{calibration.bounded_tip_speed_m_s:.3g} m/s (the fastest its logs reached); faster, the force is not "
            "trusted and the travel bound keeps the limit"
            if calibration is not None
            else "--force-sensor: the promise holds while the sensor's error stays within it"
            if args.force_sensor is not None
            else "the dvrk sensing model's error bound: a real PSM's identified free-space efforts at the chain's "
            "acceleration limits, mostly the arm's inertia; the force limit is kept from the travel: on a robot, "
            "calibrate-wrench first"
        )
        print(
            f"force sensing: {sensing_source}; the filter trusts the force to {sensing_error_n:.3g} N ({bound})",
            flush=True,
        )
    from hardware_if.deploy.run import deploy  # the simulation and the policies: once the options are accepted

    report = deploy(options, echo=lambda line: print(line, flush=True))
    for line in report.lines():
        print(line)
    if report.fault and options.dry_run:  # nothing was commanded, so nothing holds the arm
        print(
            f"tissue-retract deploy: the dry run stopped: {report.fault}; it commanded nothing: the arm is as the "
            "console left it",
            file=sys.stderr,
        )
    elif report.fault:
        print(f"tissue-retract deploy: stopped, the arm is held: {report.fault}", file=sys.stderr)
    elif report.exit_code == 0 and options.dry_run:
        commanded = command(*without_options(args, ("--dry-run", "--force"), ("--record",)))
        say_next(f"{commanded} (the same run, commanded: the arm moves)")
    elif report.exit_code == 0:
        say_next(f"{replay_command(record)} (the run's forces, jaw, tracking and safety events)")
    return report.exit_code
