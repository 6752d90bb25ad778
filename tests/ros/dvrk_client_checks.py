"""Drive a sim-dvrk with the dVRK 2.4 Python client (crtk, dvrk), unmodified, as a dVRK user's script does.

Run by ``test_dvrk_client.py`` in a child process whose PYTHONPATH holds the client and PyKDL
(``dvrk_client.client_env``). Usage: ``dvrk_client_checks.py ARM``. Every check prints one line
``CHECK <name> <ok|FAIL> <json detail>``; the exit status is the number of failed checks. Waits are on the
console's events (operating state, fresh data), never fixed sleeps, and no check bounds the time something
took on this machine's clock: a loaded machine delays every message. How long a move took is read from the
console's own stamps on ``operating_state`` (:class:`ConsoleMoves`); a wait's guard only bounds a failure.
"""

from __future__ import annotations

import json
import math
import sys
import time
import traceback
from collections.abc import Callable
from typing import Any

import crtk  # type: ignore[import-not-found]
import dvrk  # type: ignore[import-not-found]
import numpy as np
import PyKDL  # type: ignore[import-not-found]
from crtk_msgs.msg import OperatingState  # type: ignore[import-untyped]
from std_msgs.msg import String  # type: ignore[import-untyped]

from hardware_if.console.motion import JointTrajectory
from psm_control.robot import PsmModel
from tests.ros.rclpy_rate_race import close_the_race

close_the_race()

failures: list[str] = []
SPEC = PsmModel.from_variant().spec
#: The servo_cp stream: goals at 100 Hz for 2 s, along this offset from where the arm is [m].
STREAM_GOALS = 200
STREAM_OFFSET = PyKDL.Vector(0.02, 0.01, 0.0)
#: Longest a check waits for the arm to settle before it fails [s]: a guard, never the expected time.
SETTLE_GUARD_S = 20.0
#: The trajectory ratio of the move that hold stops (0.8 rad of yaw then takes about 10 s).
HOLD_RATIO = 0.1


def check(name: str, ok: bool, **detail: Any) -> None:
    """Report one check."""
    print(f"CHECK {name} {'ok' if ok else 'FAIL'} {json.dumps(detail, default=str)}", flush=True)
    if not ok:
        failures.append(name)


def poll(condition: Callable[[], bool], timeout_s: float = SETTLE_GUARD_S) -> bool:
    """Wait for an observable condition (fresh data arriving); ``timeout_s`` only bounds a failure."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.005)
    return condition()


def move_duration(start: np.ndarray, goal: np.ndarray, ratio: float = 1.0) -> float:
    """The console's trajectory duration for a joint move [s]."""
    return JointTrajectory(start, goal, SPEC.velocity_limit * ratio, SPEC.acceleration_limit * ratio).duration_s


def jaw_move_duration(start: float, goal: float) -> float:
    """The console's trajectory duration for a jaw move [s] (the jaw's own limits)."""
    limits = np.array([SPEC.jaw_velocity_limit]), np.array([SPEC.jaw_acceleration_limit])
    return JointTrajectory(np.array([start]), np.array([goal]), *limits).duration_s


def timed_wait(handle: Any, timeout: float = 30.0) -> tuple[bool, float]:
    """``handle.wait()`` and how long it took here [s] (a detail: a busy machine makes it longer)."""
    start = time.monotonic()
    result = handle.wait(timeout=timeout)
    return bool(result), time.monotonic() - start


class ConsoleMoves:
    """The console's ``operating_state`` events with the console's stamps: when each move began and ended there.

    The console stamps ``is_busy`` true when it takes a move and false at the tick the move ends, so their
    difference is the move's duration on the console, whatever the delays between the console and here.
    """

    def __init__(self, ral: Any, arm_name: str) -> None:
        self._ral = ral
        self.events: list[tuple[float, bool]] = []
        ral.subscriber(f"/{arm_name}/operating_state", OperatingState, self._on_state, queue_size=100)

    def _on_state(self, message: Any) -> None:
        self.events.append((self._ral.to_sec(message), bool(message.is_busy)))

    def now(self) -> float:
        """The client's ROS time now [s] (the console's clock on this machine)."""
        return float(self._ral.to_sec(self._ral.now()))

    def duration_since(self, sent_s: float) -> float | None:
        """The console's duration [s] of the first move it took after ``sent_s``; None if it has not ended."""
        events = list(self.events)
        busy = next((t for t, is_busy in events if is_busy and t >= sent_s), None)
        if busy is None:
            return None
        idle = next((t for t, is_busy in events if not is_busy and t > busy), None)
        return None if idle is None else idle - busy


def took_its_duration(console_s: float, expected_s: float) -> bool:
    """Whether a move lasted its trajectory's duration on the console: from the stamp of the command taken to
    that of the first tick after the end. Either stamp can be taken a little after its moment on a busy
    machine, so a tenth of the duration is allowed below it; a move cut short or not run at all is far below.
    """
    return bool(console_s >= 0.9 * expected_s)


def console_wait(moves: ConsoleMoves, command: Callable[[], Any], timeout: float = 30.0) -> tuple[bool, float, float]:
    """Send a move, ``wait()`` on its handle; whether it ended in time, its time here and on the console [s].

    The console's duration is nan when its end did not arrive (the wait failed, or its idle event is late).
    """
    sent = moves.now()
    ok, took = timed_wait(command(), timeout)
    console_s = moves.duration_since(sent) if poll(lambda: moves.duration_since(sent) is not None) else None
    return ok, took, float("nan") if console_s is None else console_s


def frame_matrix(frame: Any) -> np.ndarray:
    """A PyKDL frame as a 4x4 array."""
    matrix = np.eye(4)
    for i in range(3):
        for j in range(3):
            matrix[i, j] = frame.M[i, j]
        matrix[i, 3] = frame.p[i]
    return matrix


def wait_for_services(ral: Any, names: list[str], timeout_s: float = 20.0) -> bool:
    """Wait until the console's services are in the ROS graph (the client calls them blocking)."""
    node = ral._node  # the ral exposes no graph query; its node is the client's own
    return poll(lambda: set(names) <= {n for n, _ in node.get_service_names_and_types()}, timeout_s)


def run(ral: Any, arm_name: str) -> None:
    errors: list[str] = []
    statuses: list[str] = []
    ral.subscriber(f"/{arm_name}/error", String, lambda m: errors.append(m.data))
    ral.subscriber(f"/{arm_name}/status", String, lambda m: statuses.append(m.data))
    moves = ConsoleMoves(ral, arm_name)
    arm = dvrk.psm(ral, arm_name)

    start = time.monotonic()
    try:
        ral.check_connections(30.0)
        check("check_connections", True, seconds=round(time.monotonic() - start, 3))
    except TimeoutError as e:
        check("check_connections", False, error=str(e))
        return

    start = time.monotonic()
    check("enable", bool(arm.enable(10)), seconds=round(time.monotonic() - start, 3))
    start = time.monotonic()
    homed = bool(arm.home(20))
    home_s = time.monotonic() - start
    check("home", homed and arm.is_homed(), seconds=round(home_s, 3))

    # Every read returns fresh data: stamped after the reads began (the console stamps each period's state
    # with its time then) and never ahead of now; sizes as the dVRK's. The first read of each may wait for its
    # first message (check_connections only checks that the topics are connected).
    readers = {
        "measured_js": arm.measured_js,
        "setpoint_js": arm.setpoint_js,
        "measured_cp": arm.measured_cp,
        "setpoint_cp": arm.setpoint_cp,
        "measured_cv": arm.measured_cv,
        "local.measured_cp": arm.local.measured_cp,
        "local.setpoint_cp": arm.local.setpoint_cp,
        "body.measured_cf": arm.body.measured_cf,
        "spatial.measured_cf": arm.spatial.measured_cf,
        "jaw.measured_js": arm.jaw.measured_js,
        "jaw.setpoint_js": arm.jaw.setpoint_js,
    }
    asked = ral.to_sec(ral.now())
    reads: dict[str, Any] = {}

    def fresh() -> bool:
        reads.update({name: read(wait_timeout=SETTLE_GUARD_S) for name, read in readers.items()})
        return all(value[-1] > asked for value in reads.values())

    fresh_after_ask = poll(fresh)
    now = ral.to_sec(ral.now())
    ages = {name: round(now - value[-1], 3) for name, value in reads.items()}
    check("reads_fresh", fresh_after_ask and all(a >= 0.0 for a in ages.values()), ages=ages)
    position, velocity, effort, _ = reads["measured_js"]
    check("measured_js_sizes", len(position) == 6 and len(velocity) == 6 and len(effort) == 6, effort=list(effort))
    check("measured_jf", len(arm.measured_jf()[0]) == 6)
    body_jacobian, _ = arm.body.jacobian(wait_timeout=SETTLE_GUARD_S)
    spatial_jacobian, _ = arm.spatial.jacobian(wait_timeout=SETTLE_GUARD_S)
    check("jacobians", body_jacobian.shape == (6, 6) and spatial_jacobian.shape == (6, 6))
    check("measured_cv", len(reads["measured_cv"][0]) == 6)

    # move_jp, insert_jp: wait() is True (it ended on the console's end of the move, not at its timeout), the
    # move took its trajectory's duration on the console, and the arm is at the goal.
    jp, _ = arm.setpoint_jp()
    goal = np.array([0.0, 0.0, 0.12, 0.0, 0.0, 0.0])
    expected = move_duration(jp, goal)
    ok, took, console_s = console_wait(moves, lambda: arm.move_jp(goal))
    reached = poll(lambda: np.allclose(arm.measured_jp()[0], goal, atol=1e-3))
    check(
        "move_jp_wait",
        ok and took_its_duration(console_s, expected) and reached,
        seconds=round(took, 3),
        console_s=round(console_s, 3),
        expected=expected,
    )
    ok, took = timed_wait(arm.move_jp(goal))
    check("move_jp_to_current_position", ok, seconds=round(took, 3))
    expected = move_duration(goal, np.array([0.0, 0.0, 0.15, 0.0, 0.0, 0.0]))
    ok, took, console_s = console_wait(moves, lambda: arm.insert_jp(0.15))
    reached = poll(lambda: abs(arm.measured_jp()[0][2] - 0.15) < 1e-3)
    check(
        "insert_jp_wait",
        ok and took_its_duration(console_s, expected) and reached,
        seconds=round(took, 3),
        console_s=round(console_s, 3),
        expected=expected,
    )

    # move_cp: 2 cm sideways, same orientation.
    cp, _ = arm.setpoint_cp()
    goal_cp = PyKDL.Frame(cp.M, cp.p + PyKDL.Vector(0.02, 0.0, 0.0))
    ok, took = timed_wait(arm.move_cp(goal_cp))
    reached = poll(lambda: (arm.measured_cp()[0].p - goal_cp.p).Norm() < 1e-4)
    error_m = (arm.measured_cp()[0].p - goal_cp.p).Norm()
    check("move_cp_wait", ok and reached, seconds=round(took, 3), error_m=error_m)

    # Jaw: open to 60 deg and close to -20 deg.
    for name, handle_of, angle in (
        ("jaw_open", arm.jaw.open, math.radians(60.0)),
        ("jaw_close", arm.jaw.close, math.radians(-20.0)),
    ):
        start_jaw = arm.jaw.setpoint_jp()[0][0]
        expected = jaw_move_duration(start_jaw, angle)
        ok, took, console_s = console_wait(moves, handle_of)
        reached = poll(lambda angle=angle: abs(arm.jaw.measured_jp()[0][0] - angle) < 1e-3)
        check(
            name,
            ok and took_its_duration(console_s, expected) and reached,
            seconds=round(took, 3),
            console_s=round(console_s, 3),
            expected=expected,
        )
    ok, took = timed_wait(arm.jaw.move_jp(np.array([math.radians(30.0)])))
    reached = poll(lambda: abs(arm.jaw.setpoint_jp()[0][0] - math.radians(30.0)) < 1e-6)
    check("jaw_move_jp", ok and reached, seconds=round(took, 3))

    # servo_jp and servo_cp track.
    jp, _ = arm.setpoint_jp()
    target = jp.copy()
    rate = ral.create_rate(100)
    for k in range(50):
        target = jp + np.array([0.002 * k, -0.001 * k, 0.0, 0.0, 0.0, 0.0])
        arm.servo_jp(target)
        rate.sleep()
    check("servo_jp_tracks", poll(lambda: np.allclose(arm.measured_jp()[0], target, atol=1e-6)))
    cp, _ = arm.setpoint_cp()
    goal_cp = PyKDL.Frame(cp.M, cp.p + PyKDL.Vector(0.0, 0.003, -0.002))
    arm.servo_cp(goal_cp)
    check("servo_cp_tracks", poll(lambda: (arm.measured_cp()[0].p - goal_cp.p).Norm() < 1e-4))

    # A servo_cp stream, 100 Hz for 2 s (2 cm along x, 1 cm along y), as a user's script streams it. Each goal
    # is a direct set-point, reached once the console has taken it: the console's measured_cp is its state at
    # the tick after the command, and on a busy machine the last goals are still on their way when the
    # stream ends (measured under load: up to 3 mm, about 30 goals, behind, settled within 0.4 s). So the
    # end is judged when measured_cp has settled at the last goal; the guard only bounds a failure.
    cp, _ = arm.setpoint_cp()
    errors_before = len(errors)
    rate = ral.create_rate(100)
    for k in range(1, STREAM_GOALS + 1):
        goal_cp = PyKDL.Frame(cp.M, cp.p + STREAM_OFFSET * (k / STREAM_GOALS))
        arm.servo_cp(goal_cp)
        rate.sleep()
    behind_mm = (arm.measured_cp()[0].p - goal_cp.p).Norm() * 1000.0
    start = time.monotonic()
    settled = poll(lambda: (arm.measured_cp()[0].p - goal_cp.p).Norm() < 1e-4, SETTLE_GUARD_S)
    check(
        "servo_cp_stream",
        settled and len(errors) == errors_before,
        behind_at_end_mm=round(behind_mm, 3),
        settled_s=round(time.monotonic() - start, 3),
        errors=errors[errors_before:],
    )

    # Relative commands, from a set-point published after the servo_cp was followed.
    followed = ral.to_sec(ral.now())
    poll(lambda: arm.setpoint_jp()[1] > followed + 0.02)
    jp, _ = arm.setpoint_jp()
    arm.servo_jr(np.array([0.01, 0.0, 0.0, 0.0, 0.0, 0.0]))
    check("servo_jr", poll(lambda: abs(arm.setpoint_jp()[0][0] - (jp[0] + 0.01)) < 1e-9))
    jp, _ = arm.setpoint_jp()
    ok, took = timed_wait(arm.move_jr(np.array([-0.05, 0.0, 0.0, 0.0, 0.0, 0.0])))
    reached = poll(lambda: abs(arm.setpoint_jp()[0][0] - (jp[0] - 0.05)) < 1e-9)
    check("move_jr", ok and reached, seconds=round(took, 3))

    # hold stops a move where it is; free is served and a move afterwards works. The hold must land while the
    # move runs: the move is slowed to HOLD_RATIO (about 10 s) so that no delay of a busy machine between the
    # set-point leaving the start and the hold reaching the console lets it end first.
    arm.trajectory_j_set_ratio(HOLD_RATIO)
    poll(lambda: arm.trajectory_j_get_ratio() == HOLD_RATIO)
    jp, _ = arm.setpoint_jp()
    far = jp.copy()
    far[0] = jp[0] + 0.8
    handle = arm.move_jp(far)
    handle.wait(is_busy=True)
    poll(lambda: arm.setpoint_jp()[0][0] > jp[0] + 0.01)
    arm.hold()
    ok, took = timed_wait(handle)
    poll(lambda: arm.setpoint_jp()[0][0] > jp[0])
    stopped = arm.setpoint_jp()[0][0]
    check(
        "hold", ok and jp[0] < stopped < far[0] - 1e-3, result=ok, seconds=round(took, 3), stopped=stopped, start=jp[0]
    )
    arm.trajectory_j_set_ratio(1.0)
    poll(lambda: arm.trajectory_j_get_ratio() == 1.0)
    arm.free()
    check("free", poll(lambda: any(": free" in text for text in statuses)))
    ok, _ = timed_wait(arm.move_jp(jp))
    check("free_then_move", ok and poll(lambda: np.allclose(arm.setpoint_jp()[0], jp, atol=1e-9)))

    # Effort commands are served: the effort shows on setpoint_js; a move afterwards works again.
    # (Each command is observed before the next: the console takes different topics in any order.)
    effort = np.array([0.0, 0.0, 0.5, 0.0, 0.0, 0.0])
    arm.servo_jf(effort)
    check("servo_jf", poll(lambda: np.allclose(arm.setpoint_jf()[0], effort)))
    arm.jaw.servo_jf(np.array([0.1]))
    for name, command in (("spatial.servo_cf", arm.spatial.servo_cf), ("body.servo_cf", arm.body.servo_cf)):
        before = arm.setpoint_jf()[0]
        command(np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0]) * (2.0 if name.startswith("body") else 1.0))
        check(name, poll(lambda before=before: not np.allclose(arm.setpoint_jf()[0], before)))
    ok, _ = timed_wait(arm.move_jp(jp))
    check("effort_then_move", ok and poll(lambda: np.allclose(arm.setpoint_jf()[0], 0.0)))

    # Settings (the console says each on status) and the trajectory ratio.
    arm.use_gravity_compensation(True)
    arm.body_set_cf_orientation_absolute(False)
    arm.set_tool_present(True)
    said = (
        f"{arm_name}: use_gravity_compensation True",
        f"{arm_name}: body/set_cf_orientation_absolute False",
        f"{arm_name}: emulate_tool_present True",
    )
    check("settings", poll(lambda: all(text in statuses for text in said)), said=said)
    arm.trajectory_j_set_ratio(0.5)
    check("trajectory_ratio", poll(lambda: arm.trajectory_j_get_ratio() == 0.5))
    goal = jp.copy()
    goal[1] += 0.2
    expected = move_duration(jp, goal, ratio=0.5)
    full_speed = move_duration(jp, goal)
    ok, took, console_s = console_wait(moves, lambda: arm.move_jp(goal))
    check(
        "trajectory_ratio_slows",
        ok and took_its_duration(console_s, expected) and console_s > (expected + full_speed) / 2,
        seconds=round(took, 3),
        console_s=round(console_s, 3),
        expected=expected,
        at_full_speed=full_speed,
    )
    arm.trajectory_j_set_ratio(1.0)
    poll(lambda: arm.trajectory_j_get_ratio() == 1.0)

    # FK and IK services.
    names = [f"/{arm_name}/{s}" for s in ("forward_kinematics", "local/forward_kinematics", "inverse_kinematics")]
    check("services_in_graph", wait_for_services(ral, names))
    q = np.array([0.2, -0.1, 0.14, 0.3, 0.2, -0.1])
    ok, _ = timed_wait(arm.move_jp(q))
    poll(lambda: np.allclose(arm.measured_jp()[0], q, atol=1e-9))
    fk, fk_ok, _ = arm.forward_kinematics(q, extra=True)
    local_fk, local_ok, _ = arm.local.forward_kinematics(q, extra=True)
    measured = frame_matrix(arm.measured_cp()[0])
    local_measured = frame_matrix(arm.local.measured_cp()[0])
    check(
        "forward_kinematics",
        fk_ok
        and local_ok
        and np.allclose(frame_matrix(fk), measured, atol=1e-6)
        and np.allclose(frame_matrix(local_fk), local_measured, atol=1e-6),
    )
    _, bad_ok, bad_message = arm.forward_kinematics(np.zeros(9), extra=True)
    check("forward_kinematics_refuses_bad_size", not bad_ok and bool(bad_message), message=bad_message)
    ik, ik_ok, message = arm.inverse_kinematics(q + 0.05, local_fk, extra=True)
    back = frame_matrix(arm.local.forward_kinematics(ik))
    check("inverse_kinematics", ik_ok and np.allclose(back, frame_matrix(local_fk), atol=1e-5), message=message)

    # A client started later reads the operating state at once.
    late_ral = crtk.ral("late_client")
    late = dvrk.arm(late_ral, arm_name)
    late_ral.spin()
    late_ral.check_connections(30.0)
    check("late_client_reads_state", poll(lambda: late.operating_state() == "ENABLED" and late.is_homed()))

    # disable, enable and home again; home on a homed arm is idempotent and keeps the next move.
    check("disable", bool(arm.disable(10)) and arm.is_disabled())
    check("enable_again", bool(arm.enable(10)))
    start = time.monotonic()
    check("home_idempotent", bool(arm.home(10)), seconds=round(time.monotonic() - start, 3))
    goal = np.array([0.0, 0.0, 0.12, 0.0, 0.0, 0.0])
    ok, _ = timed_wait(arm.move_jp(goal))
    check("move_after_home", ok and poll(lambda: np.allclose(arm.setpoint_jp()[0], goal, atol=1e-9)))
    check("unhome", bool(arm.unhome(10)) and not arm.is_homed())
    start = time.monotonic()
    homed = bool(arm.home(20))
    check("home_again", homed and arm.is_homed(), seconds=round(time.monotonic() - start, 3))
    check("no_console_errors", not errors, errors=errors)


def main() -> int:
    arm_name = sys.argv[1] if len(sys.argv) > 1 else "PSM1"
    ral = crtk.ral("dvrk_client_checks")
    ral.spin()
    try:
        run(ral, arm_name)
    except Exception:  # report it as a failed check, with the client's own traceback
        check("session", False, error=traceback.format_exc())
    finally:
        ral.shutdown()
    print(f"FAILED {len(failures)}: {failures}", flush=True)
    return min(len(failures), 100)


if __name__ == "__main__":
    raise SystemExit(main())
