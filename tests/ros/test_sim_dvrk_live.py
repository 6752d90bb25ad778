"""sim-dvrk --live serves the simulated arm and its task scene on ws://127.0.0.1 for the Foxglove app."""

from __future__ import annotations

import json
import signal
import threading
from typing import Any

from websockets.sync.client import connect

from psm_control.robot import PsmModel
from sim.scene3d import PsmScene
from sim.scene_stream import TASK_TOPIC
from tests.ros.ros_process import start_sim_dvrk
from tests.sim.test_scene3d import decode
from tests.sim.test_scene_stream import MESSAGE_DATA, SUBPROTOCOL


def test_sim_dvrk_live_serves_the_task_scene(ros_env: dict[str, str]) -> None:
    """The live address is printed; a client subscribed to the task topic receives the flap of the lift task."""
    process = start_sim_dvrk(ros_env, "--arm", "PSM2", "--task", "lift", "--live", "0")
    try:
        assert process.stdout is not None
        line = ""
        while not line.startswith("live: ws://127.0.0.1:"):
            line = process.stdout.readline()
            assert line, "sim-dvrk ended before serving"
        # Keep reading what it prints, so a full pipe never blocks its loop (and the failure can say it).
        printed: list[str] = []
        reader = threading.Thread(target=lambda: printed.extend(process.stdout or ()), daemon=True)
        reader.start()
        with connect(line.split()[1], subprotocols=[SUBPROTOCOL], open_timeout=120) as client:
            channels: dict[str, Any] = {}
            while TASK_TOPIC not in channels:
                message = json.loads(client.recv(timeout=120))
                if message["op"] == "advertise":
                    channels.update({c["topic"]: c for c in message["channels"]})
            subscribe = {"op": "subscribe", "subscriptions": [{"id": 3, "channelId": channels[TASK_TOPIC]["id"]}]}
            client.send(json.dumps(subscribe))
            data = client.recv(timeout=120)
            while not (isinstance(data, bytes) and data[0] == MESSAGE_DATA):
                data = client.recv(timeout=120)
    finally:
        process.send_signal(signal.SIGINT)
        process.wait(timeout=60)
    reader.join(timeout=60)
    assert process.returncode == 0, "".join(printed)
    empty = decode(PsmScene(PsmModel.from_variant(), "PSM2_base").task(0.0))
    received = type(empty).FromString(data[13:])
    entities = {entity.id: entity for entity in received.entities}
    assert {"tissue", "site", "goal"} <= set(entities)
    assert all(entity.frame_id == "PSM2_base" for entity in received.entities)
