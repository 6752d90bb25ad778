"""A rehearsal through ROS succeeds as often as the simulation says: ``bench rehearsal`` on Task I.

The shipped Task I policy is deployed through real loopback DDS against a ``sim-dvrk`` child process with
task topics, and evaluated in-process on the same seeds with the force the console senses. The ROS path is
not deterministic (its control ticks land at other physics times than the in-process chain's, so goal
distances differ by a few millimetres), so the test states its tolerance on what a user sees: the ROS
success is within the in-process 95 % interval (the bench's exit status), and the two paths agree on the
success of all episodes but at most one. The episodes' own ends are events the bench waits for (the
deploy's exit, the recording), never a sleep; the deadman and the policy budget are widened as in the
other deploys of this folder, since the suite runs on a loaded machine (where a descheduled deploy's
policy step once took 51 ms against the default 50 ms budget, and the run held); a deploy the machine stalled
beyond even the widened deadman holds stale, which the test allows for one episode.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

#: Episodes of the rehearsal (seeds 7400-7403, the first of the rehearsal users run).
EPISODES = 4


def test_a_rehearsal_through_ros_succeeds_as_often_as_in_process(ros_env: dict[str, str], tmp_path: Path) -> None:
    config = tmp_path / "deadman.toml"
    config.write_text("deadman_timeout_s = 0.5\n")
    out = tmp_path / "rehearsal.json"
    command = [sys.executable, "-m", "tissue_retract", "bench", "rehearsal", "--tasks", "lift", "--modes", "topics"]
    command += ["--episodes", str(EPISODES), "--domain-id", ros_env["ROS_DOMAIN_ID"], "--safety-config", str(config)]
    command += ["--policy-budget", "600"]
    done = subprocess.run([*command, "--json", str(out)], env=ros_env, capture_output=True, text=True, timeout=900)
    assert done.returncode in (0, 1), done.stdout + done.stderr
    (row,) = json.loads(out.read_text())["rows"]
    ros, local = row["ros"]["episodes"], row["in_process"]["episodes"]
    assert [e["seed"] for e in ros] == [e["seed"] for e in local] == list(range(7400, 7400 + EPISODES))
    # A hold is a defect of the path, but one: a stale hold is the deadman keeping its promise when the machine
    # stalled the deploy or the console longer than the widened timeout (in the suite beside two busy processes
    # a deploy's tick once came 17 s late). At most one episode may end so, and the rows still have to agree.
    assert all(hold.startswith("stale: ") for hold in row["ros"]["holds"]), done.stdout
    assert len(row["ros"]["holds"]) <= 1, done.stdout
    assert row["in_process_successes"] >= EPISODES - 1, done.stdout  # the policy does the task in-process
    assert row["episodes_agreeing"] >= EPISODES - 1, done.stdout
    assert done.returncode == 0 and not row["ros_below_in_process_interval"], done.stdout
    # The deploy ran every episode to its end and the console's truth scored it; a hold ends the deploy, so
    # the episode it stopped is its last.
    scored = ros[: len(ros) - len(row["ros"]["holds"])]
    for episode in scored:
        assert episode["goal_distance_mm"] is not None and episode["peak_true_force_n"] is not None, ros
