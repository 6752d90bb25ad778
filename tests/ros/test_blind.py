"""A dVRK without perception, over real loopback DDS: ``sim-dvrk --blind``, ``register`` and ``deploy --site``.

``sim-dvrk --task lift --blind`` serves only the console's topics, prints the site and goal an operator
would register and set, reports the jaw stalled on the held flap, and writes its true state with
``--truth``; the tests register the tool's grasp point against that truth, and run a blind Task I episode
whose grasp the deploy senses with the jaw alone.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rclpy
from ros_process import start_sim_dvrk, stop

from hardware_if.recording.recorder import read_recording

#: A Task I seed; the deploy uses the scripted expert, which here reads only the estimate.
SEED = "2"
TIMEOUT_S = 300.0


def _run(env: dict[str, str], *argv: str) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-m", "tissue_retract", *argv, "--domain-id", env["ROS_DOMAIN_ID"]]
    return subprocess.run(command, env=env, capture_output=True, text=True, timeout=TIMEOUT_S)


def _point(lines: list[str], name: str) -> list[str]:
    line = next(line for line in lines if line.startswith(f"{name}: "))
    return line.split()[1:]


def _truth(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


@pytest.fixture(scope="module")
def blind_run(tmp_path_factory: pytest.TempPathFactory, ros_env: dict[str, str]) -> dict[str, Any]:
    """sim-dvrk --blind with the jaws on the site: its start-up lines, a registration, a deploy on it."""
    folder = tmp_path_factory.mktemp("blind")
    truth = folder / "truth.jsonl"
    sim = start_sim_dvrk(
        ros_env, "--task", "lift", "--seed", SEED, "--blind", "--truth", str(truth), "--place-jaws-on", "site"
    )
    assert sim.stdout is not None
    lines: list[str] = []
    try:
        for line in sim.stdout:  # the site, the goal and the goal for a deploy come before the server spins
            lines.append(line)
            if line.startswith("for a deploy: "):
                break
        topics = _task_topics(ros_env)
        registered = _run(ros_env, "register", "--wait", "60", "--out", str(folder / "registration.json"))
        truth_at_registration = _truth(truth)[-1]
        config = folder / "deadman.toml"
        config.write_text("deadman_timeout_s = 0.5\n")  # a shared, loaded machine: see test_deploy.py
        record = folder / "blind.mcap"
        deploy = _run(
            ros_env,
            "deploy",
            "--policy",
            "scripted",
            "--target",
            "dvrk",
            "--task",
            "lift",
            "--registration",
            str(folder / "registration.json"),
            "--goal",
            *_point(lines, "goal"),
            "--record",
            str(record),
            "--wait",
            "60",
            "--safety-config",
            str(config),
            "--policy-budget",
            "600",
        )
    finally:
        output = stop(sim)
    return {
        "lines": lines,
        "topics": topics,
        "registered": registered,
        "truth_at_registration": truth_at_registration,
        "deploy": deploy,
        "record": record,
        "truth": _truth(truth),
        "registration": folder / "registration.json",
        "sim_output": output,
    }


def _task_topics(env: dict[str, str]) -> list[str]:
    """The /PSM1/task/* topics in the ROS graph once the arm's own topics are there."""
    rclpy.init()
    try:
        node = rclpy.create_node(f"blind_graph_{np.random.default_rng().integers(1 << 30)}")
        try:
            names: list[str] = []
            for _ in range(600):  # up to a minute, until discovery shows the console's topics
                names = [name for name, _ in node.get_topic_names_and_types()]
                if "/PSM1/measured_js" in names:
                    break
                rclpy.spin_once(node, timeout_sec=0.1)
            assert "/PSM1/measured_js" in names, names
            return [name for name in names if name.startswith("/PSM1/task/")]
        finally:
            node.destroy_node()
    finally:
        rclpy.shutdown()


def test_blind_sim_dvrk_serves_no_task_topic_and_prints_site_and_goal(blind_run: dict[str, Any]) -> None:
    """--blind serves the console's topics only and prints the settled site and the goal in <arm>_base."""
    assert blind_run["topics"] == []
    site = np.array([float(v) for v in _point(blind_run["lines"], "site")])
    goal = np.array([float(v) for v in _point(blind_run["lines"], "goal")])
    first = blind_run["truth"][0]
    assert np.linalg.norm(site - np.array(first["site"])) < 2e-4, "the printed site is the flap at rest"
    assert np.allclose(goal, first["goal"], atol=1e-5)
    # One goal: the deploy is told to take the scene's, not its own nominal one about the registered site.
    assert blind_run["lines"][-1].startswith(f"for a deploy: --goal {' '.join(_point(blind_run['lines'], 'goal'))} ")


def test_register_records_the_grasp_point_of_the_arm(blind_run: dict[str, Any]) -> None:
    """register on jaws placed on the site: the grasp point within 0.5 mm of PyBullet's, and of the true site."""
    registered = blind_run["registered"]
    assert registered.returncode == 0, registered.stdout + registered.stderr
    assert "warning" not in registered.stderr, registered.stderr
    site = np.array([float(v) for v in _point(registered.stdout.splitlines(), "site")])
    assert np.linalg.norm(site - np.array(blind_run["truth_at_registration"]["grasp_point"])) < 5e-4
    assert np.linalg.norm(site - np.array(blind_run["truth_at_registration"]["site"])) < 5e-4
    saved = json.loads(blind_run["registration"].read_text())
    assert saved["arm"] == "PSM1" and np.allclose(saved["site_m"], site, atol=1e-5)


def test_a_blind_episode_senses_the_grasp_with_the_jaw_and_lifts_the_flap(blind_run: dict[str, Any]) -> None:
    """A blind deploy reads no task topic, its jaw-sensed grasp matches the truth, and the flap is lifted."""
    deploy = blind_run["deploy"]
    output = deploy.stdout + deploy.stderr
    assert deploy.returncode == 0, output
    assert "(no task topics)" in output and "Traceback" not in output
    truth = blind_run["truth"]
    assert any(row["grasped"] for row in truth), "the simulation grasped the flap"
    observed = [
        payload["observation"]["observation"][17]
        for topic, _, payload in read_recording(blind_run["record"])
        if topic == "/deploy/action"
    ]
    assert len(observed) == 50 and sum(observed) >= 10, "the deploy sensed a grasp it held for 10+ steps"
    lifted = truth[-1]["site"][2] - truth[0]["site"][2]
    assert truth[-1]["grasped"] and lifted > 0.005, f"the held site rose {lifted * 1000:.1f} mm"


def test_register_refuses_jaws_that_are_not_on_the_tissue(ros_env: dict[str, str]) -> None:
    """Against sim-dvrk --blind with the arm at its start (14 cm from the site), register refuses in numbers."""
    sim = start_sim_dvrk(ros_env, "--task", "lift", "--seed", SEED, "--blind")
    try:
        registered = _run(ros_env, "register", "--wait", "60")
    finally:
        stop(sim)
    assert registered.returncode == 1, registered.stdout + registered.stderr
    assert "outside the workspace box about the RCM: z = " in registered.stderr, registered.stderr
    assert "not registered: the jaws were at" in registered.stderr and "site:" not in registered.stdout
    assert "Traceback" not in registered.stderr
