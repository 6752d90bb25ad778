"""The dVRK 2.4 Python client, unmodified, against sim-dvrk over loopback: a dVRK user's first move.

Each test starts its own ``sim-dvrk`` on a domain id of its own and runs the client in a child process
(``dvrk_client.py`` says where the client and PyKDL come from). Waits are on observable events: the
simulator's start-up line, the client's exit; the client's own checks wait on the console's state.
"""

from __future__ import annotations

import json
import re
import time
from collections.abc import Iterator

import numpy as np
import pytest
import rclpy
from domains import client_domain_id
from dvrk_client import SCRIPTS_HERE, Process, client_dir, missing, run_client, start_sim

#: The client's own scripts that must run to completion, with the input they ask for.
SCRIPTS = {
    "dvrk_move_wait_test.py": ("PSM1", None),
    "dvrk_arm_test.py": ("PSM2", None),
    "dvrk_psm_test.py": ("PSM3", "\n" * 10),
}


#: What ``dvrk.psm(ral, 'PSM1')`` connects to, under ``/PSM1/`` (its ``check_connections()`` waits on the
#: topics): what the console publishes, what it subscribes to, the services it offers.
CLIENT_READS = (
    "measured_js", "measured_cp", "measured_cv", "setpoint_js", "setpoint_cp", "local/measured_cp",
    "local/setpoint_cp", "body/measured_cf", "spatial/measured_cf", "body/jacobian", "spatial/jacobian",
    "jaw/measured_js", "jaw/setpoint_js", "operating_state", "error", "warning", "status", "trajectory_j/ratio",
)  # fmt: skip
CLIENT_COMMANDS = (
    "servo_jp", "servo_jr", "servo_cp", "servo_jf", "move_jp", "move_jr", "move_cp", "hold", "free",
    "body/servo_cf", "spatial/servo_cf", "jaw/servo_jp", "jaw/move_jp", "jaw/servo_jf", "state_command",
    "trajectory_j/set_ratio", "use_gravity_compensation", "body/set_cf_orientation_absolute", "emulate_tool_present",
)  # fmt: skip
CLIENT_SERVICES = ("forward_kinematics", "local/forward_kinematics", "inverse_kinematics")


@pytest.fixture(scope="module", autouse=True)
def _client_present() -> None:
    """The client is a real test dependency: its absence fails these tests with what to do."""
    reason = missing()
    if reason is not None:
        pytest.fail(reason)


@pytest.fixture
def kinematic_sim() -> Iterator[int]:
    """A sim-dvrk without a task scene; yields its domain id."""
    domain = client_domain_id(0)
    sim = start_sim(domain)
    yield domain
    assert sim.stop() == 0, sim.output()


# The client's own exit race, not a fault of the server: ``ral_ros2.shutdown`` calls ``rclpy.shutdown()``
# while its daemon spin thread may be about to build a wait set, which then raises RCLError ("context is
# not valid"); ``_try_spin`` catches only ExternalShutdownException. Seen once in five loaded runs, after
# the script had finished with every wait on time. Only this exact traceback, from that thread, is ignored.
_CLIENT_EXIT_RACE = re.compile(
    r"Exception in thread [^\n]*\(_try_spin\):\nTraceback \(most recent call last\):\n(?:[ \t][^\n]*\n)*"
    r"rclpy\._rclpy_pybind11\.RCLError: failed to initialize wait set: the given context is not valid[^\n]*\n"
)


def _finish(process: Process, timeout_s: float) -> str:
    status = process.wait(timeout_s)
    if status is None:
        process.stop()
        pytest.fail(f"did not finish within {timeout_s} s:\n{process.output()}")
    return process.output()


def test_console_serves_every_endpoint_of_the_client_once_constructed() -> None:
    """The console has every topic and service the client connects to once constructed, before its start-up line."""
    from hardware_if.console.sim_dvrk import SimulatedPsm  # the ros extra

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = SimulatedPsm("PSM1", context=context)
        name, namespace = node.get_name(), node.get_namespace()
        published = {topic for topic, _ in node.get_publisher_names_and_types_by_node(name, namespace)}
        subscribed = {topic for topic, _ in node.get_subscriber_names_and_types_by_node(name, namespace)}
        services = {service for service, _ in node.get_service_names_and_types_by_node(name, namespace)}
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    assert {f"/PSM1/{t}" for t in CLIENT_READS} <= published, sorted(published)
    assert {f"/PSM1/{t}" for t in CLIENT_COMMANDS} <= subscribed, sorted(subscribed)
    assert {f"/PSM1/{s}" for s in CLIENT_SERVICES} <= services, sorted(services)


def test_client_api_against_sim_dvrk(kinematic_sim: int) -> None:
    """check_connections passes; reads are fresh; waits end with their moves; servo streams end at their goals."""
    client = run_client(SCRIPTS_HERE / "dvrk_client_checks.py", kinematic_sim, "PSM1")
    output = _finish(client, 240.0)
    print(output)  # every check's line with its details (times here and on the console), for -rP
    checks = dict(re.findall(r"^CHECK (\S+) (ok|FAIL)", output, flags=re.MULTILINE))
    failed = [name for name, result in checks.items() if result != "ok"]
    assert not failed and "FAILED 0" in output, output
    for name in (
        "check_connections",
        "move_jp_wait",
        "jaw_open",
        "jaw_close",
        "servo_cp_stream",
        "hold",
        "settings",
        "trajectory_ratio_slows",
        "servo_jf",
        "forward_kinematics",
        "inverse_kinematics",
        "late_client_reads_state",
        "home_again",
    ):
        assert checks.get(name) == "ok", (name, output)


@pytest.mark.slow
@pytest.mark.parametrize("script", list(SCRIPTS))
def test_dvrk_script_runs_to_completion_on_a_task_scene(script: str) -> None:
    """The dVRK's own test script runs to completion against ``sim-dvrk --task lift``; no wait() times out."""
    arm, stdin = SCRIPTS[script]
    domain = client_domain_id(1 + list(SCRIPTS).index(script))
    sim = start_sim(domain, "--task", "lift", "--arm", arm)
    try:
        start = time.monotonic()
        client = run_client(client_dir() / "scripts" / script, domain, "-a", arm, stdin=stdin)
        output = _finish(client, 480.0)
        wall_s = time.monotonic() - start
    finally:
        sim_status = sim.stop()
    assert client.process.returncode == 0, output
    waits = json.loads(re.findall(r"^WAITS (.*)$", output, flags=re.MULTILINE)[-1])
    # Every wait() ended on the console's end of its move (False is a wait run to its timeout); how long each
    # took here (max_s, printed below) is the move plus this machine's delays, so it is not judged.
    assert waits["count"] > 0 and waits["false"] == 0, (waits, output)
    checked = _CLIENT_EXIT_RACE.sub("", output)
    assert "Traceback" not in checked and "failed" not in checked.lower(), output
    assert sim_status == 0, sim.output()
    print(f"{script}: {wall_s:.1f} s wall, {waits}")


@pytest.mark.parametrize("wrench", ["dvrk", "ideal"])
def test_client_reads_the_console_force_estimate_in_free_space(wrench: str) -> None:
    """body.measured_cf in free space: the dvrk model's is finite, not zero and moves with pose; ideal's is ~0."""
    domain = client_domain_id(5 if wrench == "dvrk" else 6)
    sim = start_sim(domain, "--wrench", wrench)
    try:
        output = _finish(run_client(SCRIPTS_HERE / "dvrk_client_wrench.py", domain, "PSM1"), 120.0)
    finally:
        assert sim.stop() == 0, sim.output()
    match = re.search(r"^WRENCH (.*)$", output, flags=re.MULTILINE)
    assert match is not None, output
    forces = {name: np.asarray(value) for name, value in json.loads(match.group(1)).items()}
    assert all(np.all(np.isfinite(f)) for f in forces.values()), forces
    if wrench == "ideal":
        assert all(np.linalg.norm(f) < 0.01 for f in forces.values()), forces
    else:
        assert all(np.linalg.norm(f) > 0.05 for f in forces.values()), forces
        assert np.linalg.norm(forces["first"] - forces["second"]) > 0.05, forces
        assert np.linalg.norm(forces["moving"] - forces["second"]) > 0.01, forces
