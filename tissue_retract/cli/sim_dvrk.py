"""``tissue-retract sim-dvrk``: serve a simulated dVRK PSM's CRTK topics over ROS 2.

Users rehearse against it exactly as against a real console: the same topic names, types, QoS and
frames, the operating-state machine (enable, home) and the refusal of Cartesian goals below 45 mm of
insertion. Discovery stays on this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, UDPv4) on the
domain given by ``--domain-id`` (default: ``$ROS_DOMAIN_ID``, else 0); clients must use the same domain.
With ``--task ID`` the arm moves in that task's PyBullet tissue scene: the tissue force is on
``body/measured_cf``, the grasp works, ``<arm>_base`` is the scene's world frame (the RCM's pose in it
comes from the scene, not ``--base-xyz``), homing goes to the task's start joints, and the
simulation-only topics ``/<arm>/task/{site,goal,achieved_goal,grasped}`` carry what a perception node
would supply on a real robot (``/<arm>/task/reset`` with a seed starts a new episode).

``--blind`` serves only what the dVRK console serves (no ``/<arm>/task/*`` topic: one scene, no resets),
prints ``site: X Y Z`` and ``goal: X Y Z`` (metres, ``<arm>_base``) at start as an operator would register
and set them for ``deploy --site ... --goal ...``, and reports the jaw as a real one on tissue: closing
on the flap it stalls open (0.12 rad) with a squeezing effort on ``jaw/measured_js``. ``--truth FILE``
writes the scene's true state as JSON lines at the policy rate (``t``, ``grasped``, ``site``,
``achieved_goal``, ``goal``, ``grasp_point``, ``distance_m``), to score a blind deploy.
``--place-jaws-on SITE`` (with ``--task``) starts with the closed jaws on the episode's grasp site (``site``)
or a named one of the flap (``centre``, ``left``, ``right``), as an operator holds them there to
``register`` it: registration rehearsed end to end. It refuses to start when another console already serves
the arm on the domain (it looks for one for 3.5 s first), and warns on ``/<arm>/warning`` when commands come
from more than one node. Needs the ``ros`` extra. Ctrl-C (or SIGTERM, SIGHUP) stops it.

``--stamp-fault MODE`` breaks the console's clock on ``measured_js``, to rehearse a deploy's deadman against
it, from the ``--stamp-fault-after``-th accepted ``servo_jp`` on or when the process gets SIGUSR1:
``frozen`` (the last ``measured_js`` repeated, same stamp and sample), ``past`` (stamped 5 s in the past),
``jump`` (one stamped 1 h ahead, then repeated).
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import threading

import numpy as np

from hardware_if.client.task_estimate import format_point
from hardware_if.common.executor import make_executor
from hardware_if.common.gc_pauses import freeze_startup_heap
from hardware_if.common.network import apply_local_ros_env, environment_domain_id
from hardware_if.common.session import require_ros, ros_session
from hardware_if.common.task_topics import DEFAULT_RIG, camera_topics
from hardware_if.console.endoscope_stream import EndoscopeStream
from hardware_if.console.sim_task import PLACEABLE_SITES, TaskArm, TaskTopics, TruthLog
from hardware_if.console.stamp_fault import STAMP_FAULTS, StampFault
from psm_control.errors import ConfigurationError
from psm_control.inputs import check_output_path
from psm_control.robot import PsmModel
from sim.force_sensing import SENSING_NAMES, ForceSensor, sensing_params
from sim.scene3d import PsmScene
from sim.scene_stream import LiveScene, SceneStream
from tissue_retract.cli._camera import add_texture_argument, check_texture
from tissue_retract.cli._checks import MAX_EPISODES, float_in, int_in
from tissue_retract.cli._live import add_live_argument
from tissue_retract.cli._next import command, say_next

__all__ = ["add_arguments", "run"]

#: Signals that stop the console as Ctrl-C does (its exit status stays 0: stopping is how a console ends).
_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the subcommand to its parser."""
    parser.add_argument("--arm", default="PSM1", help="arm name and topic namespace (default: PSM1)")
    parser.add_argument(
        "--task", default=None, metavar="ID", help="serve a task's tissue scene (force on body/measured_cf)"
    )
    parser.add_argument(
        "--seed",
        type=int_in(0, 2**31 - 1 - MAX_EPISODES),
        default=0,
        help="seed of the task scene's first episode (default: 0)",
    )
    parser.add_argument("--rate", type=float, default=100.0, help="publishing rate [Hz] (default: 100, the dVRK's)")
    parser.add_argument(
        "--domain-id", type=int, default=environment_domain_id(), help="ROS_DOMAIN_ID (default: $ROS_DOMAIN_ID or 0)"
    )
    parser.add_argument(
        "--base-xyz",
        type=float_in(-5.0, 5.0),
        nargs=3,
        default=(0.0, 0.0, 0.0),
        metavar=("X", "Y", "Z"),
        help="position of the RCM in <arm>_base [m], as set_base_frame would set it (default: 0 0 0)",
    )
    parser.add_argument(
        "--blind",
        action="store_true",
        help="with --task: no task topics; print the site and goal; the jaw stalls on the held flap",
    )
    parser.add_argument(
        "--truth", metavar="FILE.jsonl", default=None, help="with --task: write the true task state as JSON lines"
    )
    parser.add_argument(
        "--wrench",
        choices=SENSING_NAMES,
        default="dvrk",
        help="what the console makes of the tissue force on measured_js effort and body/ and spatial/measured_cf: "
        "dvrk (the default: the console's estimate from motor currents, no gravity or friction model), "
        "dvrk-calibrated (what is left after calibrate-wrench) or ideal (the exact force)",
    )
    add_texture_argument(parser)
    parser.add_argument(
        "--endoscope",
        nargs="?",
        const=DEFAULT_RIG,
        default=None,
        metavar="RIG",
        help=f"with --task: publish the stereo endoscope's images on /RIG/{{left,right}}/image_raw and camera_info "
        f"(default RIG: {DEFAULT_RIG}, the dVRK video pipeline's)",
    )
    parser.add_argument(
        "--endoscope-rate",
        type=float_in(1.0, 30.0),
        default=10.0,
        metavar="HZ",
        help="endoscope frames per second, 1-30 (default: 10)",
    )
    parser.add_argument(
        "--place-jaws-on",
        choices=PLACEABLE_SITES,
        default=None,
        metavar="SITE",
        help=f"with --task: start with the closed jaws on this site (rehearse register): {', '.join(PLACEABLE_SITES)}",
    )
    parser.add_argument(
        "--stamp-fault",
        choices=tuple(STAMP_FAULTS),
        default=None,
        help="inject a clock fault on measured_js (from --stamp-fault-after or SIGUSR1 on): "
        + "; ".join(f"{name}: {what}" for name, what in STAMP_FAULTS.items()),
    )
    parser.add_argument(
        "--stamp-fault-after",
        type=int_in(1, 10**9),
        default=None,
        metavar="N",
        help="with --stamp-fault: start it after the N-th accepted servo_jp (default: only on SIGUSR1)",
    )
    add_live_argument(parser)


def run(args: argparse.Namespace) -> int:
    """Run the simulated console until Ctrl-C."""
    # Read by rclpy and Fast DDS when they start, so set before the first import of rclpy.
    apply_local_ros_env(args.domain_id)

    if (args.blind or args.truth or args.endoscope or args.texture or args.place_jaws_on) and args.task is None:
        raise ConfigurationError(
            "--blind/--truth/--endoscope/--texture/--place-jaws-on",
            True,
            "with --task ID (they are about a task's scene)",
        )
    if args.stamp_fault_after is not None and args.stamp_fault is None:
        raise ConfigurationError("--stamp-fault-after", args.stamp_fault_after, "with --stamp-fault MODE")
    truth_path = check_output_path(args.truth, "--truth") if args.truth else None
    require_ros()
    # The ros extra, imported after the environment it reads is set.
    from rclpy.executors import ExternalShutdownException

    from hardware_if.console.sim_dvrk import SimulatedPsm

    texture = check_texture(args.texture) if args.texture is not None else None
    task = TaskArm(args.task, seed=args.seed, blind=args.blind, texture=texture) if args.task is not None else None
    if task is not None and args.endoscope is not None:
        task.endoscope = EndoscopeStream(args.task, texture=texture, rig=args.endoscope, rate_hz=args.endoscope_rate)
        images = ", ".join(camera_topics(args.endoscope).values())
        print(f"endoscope: {images} at {args.endoscope_rate:g} Hz (render process {task.endoscope.pid})", flush=True)
    base_frame = np.eye(4)
    base_frame[:3, 3] = args.base_xyz
    home_q = None
    if task is not None:
        base_frame, home_q = task.base_frame, task.home_q
    live_view = contextlib.nullcontext() if args.live is None else LiveScene(port=args.live)
    # Python's own Ctrl-C handling, not rclpy's: rclpy's shuts the context down from under a timer
    # callback's publish; a KeyboardInterrupt stops between two Python statements instead (installed
    # explicitly: a process started in the background of a script inherits SIGINT ignored, one started
    # from a thread that blocks it inherits it blocked). SIGTERM and SIGHUP stop it the same way: the
    # default SIGTERM ended it at once, its DDS participant and its endoscope's render process not closed.
    for sig in _STOP_SIGNALS:
        signal.signal(sig, signal.default_int_handler)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _STOP_SIGNALS)
    stamp_fault = None
    if args.stamp_fault is not None:
        fault = stamp_fault = StampFault(args.stamp_fault, args.stamp_fault_after)
        signal.signal(signal.SIGUSR1, lambda _signal, _frame: fault.start("SIGUSR1"))
        print(f"stamp fault on measured_js: {fault.describe()}", flush=True)
    with live_view as live, ros_session(signal_handlers=False):
        node: SimulatedPsm | None = None
        truth: TruthLog | None = None
        topics: TaskTopics | None = None
        # Ctrl-C may come at any point once the start-up line is out (a client waits for it), even
        # before spin() starts: all of it ends the server cleanly.
        try:
            scene = None
            if live is not None:  # the arm and the task's markers for the Foxglove app, 20 times a second
                model = PsmModel.from_variant()
                scene = SceneStream(PsmScene(model, f"{args.arm}_base", base_frame), [live], period_s=0.05)
                print(f"live: ws://127.0.0.1:{live.port} (open it in the Foxglove app)", flush=True)
            node = SimulatedPsm(
                args.arm,
                rate_hz=args.rate,
                arm_model=task,
                base_frame=base_frame,
                home_q=home_q,
                scene=scene,
                sensor=ForceSensor(sensing_params(args.wrench), np.random.default_rng(args.seed)),
                exclusive=True,
                stamp_fault=stamp_fault,
            )
            if task is not None and args.place_jaws_on is not None:
                node.place_arm(task.jaws_on(args.place_jaws_on), 0.0)
                point = format_point(task.task_state()["grasp_point"])
                print(f"jaws closed on the {args.place_jaws_on}: grasp point {point} (m, {args.arm}_base)", flush=True)
            # Made before the start-up line: a Ctrl-C right after it must not land in its constructor.
            executor = make_executor()
            executor.add_node(node)
            if truth_path is not None and task is not None:
                truth = TruthLog(node, task, truth_path)
            if task is not None and args.blind:
                state = task.task_state()
                for name in ("site", "goal"):
                    print(f"{name}: {format_point(state[name])}", flush=True)
                # A deploy without --goal aims at the task's nominal goal about the site it is given, which
                # differs from this scene's goal by the registration's error: one goal, given once.
                # The flap's named site the episode grasps: a camera sees all three, the user says which.
                print(
                    f"for a deploy: --goal {format_point(state['goal'])} --camera-site {task.env.site} (the "
                    "scene's goal and which of the flap's sites it grasps; without --goal a deploy aims at the "
                    "task's nominal goal about the site)",
                    flush=True,
                )
                node.get_logger().info(f"task {args.task!r} scene (seed {args.seed}), blind: no task topics")
            elif task is not None:
                topics = TaskTopics(node, task)
                node.get_logger().info(
                    f"task {args.task!r} scene (seed {args.seed}); task topics under /{args.arm}/task/"
                )
            node.get_logger().info(
                f"simulated {args.arm} at {args.rate:g} Hz on ROS_DOMAIN_ID={args.domain_id} (localhost discovery)"
            )
            console = ["--domain-id", str(args.domain_id)] if args.domain_id != environment_domain_id() else []
            if args.blind and args.place_jaws_on is not None:
                register = command("register", "--arm", args.arm, "--out", "site.json", *console)
                step = f"{register} (the jaws are on the site)"
            else:
                step = f"{command('ready-arm', '--arm', args.arm, *console)} (enable, home, to the episodes' start)"
            say_next(f"in another terminal, {step}")
            freeze_startup_heap()  # before the loop: short collector pauses from here on
            # From here Ctrl-C asks the loop to end: a KeyboardInterrupt raised in a callback that the C++
            # events executor runs is logged as a fatal callback error on its way out.
            stop = threading.Event()
            for sig in _STOP_SIGNALS:
                signal.signal(sig, lambda _signal, _frame: stop.set())
            endoscope = task.endoscope if task is not None else None
            while node.context.ok() and not stop.is_set():  # spin_once: see hardware_if.common.executor
                executor.spin_once(timeout_sec=0.05)
                if endoscope is not None and (ended := endoscope.ended()):  # killed: said once, the arm goes on
                    print(ended, flush=True)
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        finally:
            if topics is not None:
                topics.close()
            if node is not None:
                node.destroy_node()
            if truth is not None:
                truth.close()
            if task is not None:
                if task.endoscope is not None:
                    task.endoscope.close()
                task.close()
    return 0
