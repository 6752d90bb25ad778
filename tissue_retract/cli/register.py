"""``tissue-retract register``: record the grasp site by touch, for ``deploy --site`` on a robot without perception.

Hold the closed jaws on the site (the arm in its clutch or free mode, or moved there by teleoperation) and
run ``tissue-retract register --arm PSM1``: it listens to the arm (it commands nothing), averages the grasp
point (midway along the jaws, by the arm's kinematics) over ``--samples`` measurements, refuses if the tool
moved more than 1 mm meanwhile, the jaws are open or the site is outside the chain's workspace box, warns
when it is far from the depth the tissue lies at (:mod:`hardware_if.client.registration_checks`), and prints
``site: X Y Z`` in metres in ``<arm>_base``. ``--out FILE``
also writes it as JSON for ``deploy --registration FILE``. Discovery stays on localhost unless
``--network`` is given, as for ``deploy``.
"""

from __future__ import annotations

import argparse
import shlex
import sys

from psm_control.inputs import check_output_path
from sim.strict_json import write_strict_json
from tissue_retract.cli._checks import float_in, int_in
from tissue_retract.cli._next import command, console_words, say_next
from tissue_retract.cli._ros import add_console_arguments, apply_console_arguments

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the subcommand to its parser."""
    parser.add_argument("--arm", default="PSM1", help="arm name / topic namespace (default: PSM1)")
    parser.add_argument(
        "--samples", type=int_in(5, 10_000), default=50, help="measurements averaged, 5-10000 (default: 50)"
    )
    parser.add_argument("--out", metavar="FILE.json", default=None, help="also write the registration as JSON")
    parser.add_argument(
        "--wait",
        type=float_in(0.0, 3600.0, open_low=True),
        default=10.0,
        help="seconds to wait for each measurement of the arm (default: 10)",
    )
    add_console_arguments(parser, network_help="keep your ROS discovery settings instead of localhost-only")


def run(args: argparse.Namespace) -> int:
    """Register, print ``site: X Y Z``; 0, or 1 with the reason when the tool was not still or the arm silent."""
    output = check_output_path(args.out, "--out") if args.out else None
    apply_console_arguments(args)
    # The ros extra, imported after the environment it reads is set.
    from hardware_if.client.psm_client import PsmClient
    from hardware_if.client.registration import RegistrationError, console_base_frame, register_site
    from hardware_if.client.registration_checks import check_registration
    from hardware_if.client.task_estimate import format_point
    from hardware_if.common.session import ros_session

    with ros_session(), PsmClient(args.arm, listen_only=True, node_name=f"{args.arm.lower()}_register") as client:
        print(f"{args.arm}: hold the closed jaws still on the site", flush=True)
        try:
            registration = register_site(client, samples=args.samples, timeout_s=args.wait)
        except RegistrationError as e:
            print(f"tissue-retract register: error: {e}", file=sys.stderr)
            return 1
        findings = check_registration(registration.site_m, console_base_frame(client), client.measure().jaw)
    refusals = [f.text for f in findings if f.refuse]
    for finding in findings:
        kind = "error" if finding.refuse else "warning"
        print(f"tissue-retract register: {kind}: {finding.text}", file=sys.stderr)
    if refusals:
        print(f"  not registered: the jaws were at {format_point(registration.site_m)} m", file=sys.stderr)
        return 1
    print(registration.line())
    print(f"  frame {args.arm}_base [m], {registration.samples} samples within {registration.spread_m * 1000:.3f} mm")
    if output is not None:
        write_strict_json(output, registration.to_dict(), field="--out")
        print(f"  written to {output}")
    site = ["--registration", str(output)] if output else ["--site", *(f"{v:.4f}" for v in registration.site_m)]
    say_next(
        f"{command('ready-arm', '--arm', args.arm, *console_words(args))} (enable, home, to the episodes' start), "
        f"then deploy --target dvrk {shlex.join(site)} --dry-run"
    )
    return 0
