"""``tissue-retract ready-arm``: enable and home the arm, then move it to the episodes' start.

The first step of the safe order on a console (docs/rehearsal-and-reports.md): ``ready-arm``,
``calibrate-wrench`` in free space, ``register``, ``deploy --dry-run``, ``deploy``. It sends the console's
own state commands (``enable``, ``home``) and one joint move along the console's own trajectory
(``move_jp`` to the task's start joints, ``jaw/move_jp`` to the open jaw), nothing else: no policy runs and
no servo stream is sent. Before the first command it refuses, as a deploy does, when another node commands
the arm or a second console serves it. A dry run needs the arm where this leaves it, since a dry run moves
nothing. Discovery stays on localhost unless ``--network`` is given, as for ``deploy``.
"""

from __future__ import annotations

import argparse
import signal
import sys
from typing import Any

from sim.sweep.stopping import handling
from tissue_retract.cli._checks import float_in
from tissue_retract.cli._next import command, console_words, say_next
from tissue_retract.cli._ros import add_console_arguments, apply_console_arguments

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the subcommand to its parser."""
    parser.add_argument("--arm", default="PSM1", help="arm name / topic namespace (default: PSM1)")
    parser.add_argument(
        "--task",
        default="lift",
        choices=("lift", "target", "multisite", "expose"),
        help="the task whose episodes start where the arm is moved (default: lift; all tasks start alike)",
    )
    parser.add_argument(
        "--wait",
        type=float_in(0.0, 3600.0, open_low=True),
        default=20.0,
        help="seconds each step (measurement, enable, home, move) may take (default: 20)",
    )
    add_console_arguments(parser, network_help="keep your ROS discovery settings instead of localhost-only")


def run(args: argparse.Namespace) -> int:
    """Enable, home, move to the start; 0, 1 with the reason (the arm holds where it is), or 128 + signal."""
    apply_console_arguments(args)
    import sim.envs

    env = sim.envs.make(args.task)
    try:
        start_q, start_jaw = env.unwrapped.model.home(), float(env.unwrapped.config.jaw_open_rad)
    finally:
        env.close()
    # The ros extra, imported after the environment it reads is set.
    from hardware_if.client.arm_pose import return_to_start
    from hardware_if.client.psm_client import PsmClient
    from hardware_if.common.errors import DvrkError
    from hardware_if.common.session import ros_session
    from hardware_if.deploy.stopping import STOP_SIGNALS, Interrupted

    def stop(signum: int, _frame: Any) -> None:
        raise Interrupted(signum)

    stage = "waiting for the arm"
    try:
        with (
            handling(STOP_SIGNALS, stop),
            ros_session(signal_handlers=False),
            PsmClient(args.arm, node_name=f"{args.arm.lower()}_ready_arm") as client,
        ):
            client.watch_commanders()
            try:
                client.wait_for_measurement(args.wait)
                client.settle_graph(args.wait)
                conflict = client.exclusive()
                if conflict:
                    raise DvrkError(f"{conflict}; nothing was sent")
                for stage, step in (("enable", client.enable), ("home", client.home)):
                    step(args.wait)
                    print(f"{args.arm}: {stage}d", flush=True)
                stage = "the move to the start"
                reason = return_to_start(client, start_q, args.wait, start_jaw=start_jaw)
            except DvrkError as e:
                reason = str(e)
            if reason:
                print(f"tissue-retract ready-arm: error: {reason}; the arm holds where it is", file=sys.stderr)
                return 1
    except Interrupted as e:
        print(
            f"tissue-retract ready-arm: stopped by {signal.Signals(e.signum).name} during {stage}; "
            "the arm holds where it is",
            file=sys.stderr,
        )
        return 128 + e.signum
    joints = " ".join(f"{value:.4g}" for value in start_q)
    print(f"{args.arm}: at the episodes' start (joints {joints}; jaw open {start_jaw:g} rad): ready")
    arm, console = ["--arm", args.arm], console_words(args)
    deploy = ["--policy", "pretrained", "--target", "dvrk", "--task", args.task, *arm[: 2 * (args.arm != "PSM1")]]
    dry_run = command("deploy", *deploy, "--wrench-calibration", "wrench.json", *console, "--dry-run")
    say_next(
        f"{command('calibrate-wrench', *arm, '--out', 'wrench.json', *console)} (free space, nothing in the jaws); "
        f"once calibrated, the dry run: {dry_run}"
    )
    return 0
