"""The live view: a Foxglove WebSocket server on 127.0.0.1 that a client can subscribe to and read the scene from."""

from __future__ import annotations

import json
import struct
import subprocess
import sys
from typing import Any

import numpy as np
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from websockets.sync.client import connect

from psm_control.robot import PsmModel
from sim.scene3d import PsmScene
from sim.scene_stream import ARM_TOPIC, LOG_TOPIC, TASK_TOPIC, TRANSFORMS_TOPIC, LiveScene, SceneStream
from tests.sim.test_scene3d import decode

SUBPROTOCOL = "foxglove.sdk.v1"  # the SDK server's name for the Foxglove WebSocket protocol
MESSAGE_DATA = 0x01  # the protocol's binary opcode of a subscribed message


class Memory:
    """A sink that keeps what it is given."""

    def __init__(self) -> None:
        self.messages: list[tuple[str, Any, float]] = []

    def write_message(self, topic: str, message: Any, t_s: float) -> None:
        self.messages.append((topic, message, t_s))


def test_stream_sends_arm_shapes_once_a_second_and_frames_every_tick() -> None:
    """Frames of both arms each tick; the shapes at the start and again after a second; a hold as a warning."""
    memory = Memory()
    model = PsmModel.from_variant("classic")
    stream = SceneStream(PsmScene(model, "PSM1_base"), [memory])
    for tick in range(25):
        stream.tick(0.1 * tick, model.home(), 0.2, commanded_q=model.home())
    stream.log(2.5, "HOLD: stale measured_js", warning=True)
    topics = [topic for topic, _, _ in memory.messages]
    assert topics.count(TRANSFORMS_TOPIC) == 50 and topics.count(TASK_TOPIC) == 25
    assert [t for topic, _, t in memory.messages if topic == ARM_TOPIC] == [0.0, 0.0, 1.0, 1.0, 2.0, 2.0]
    log = decode(memory.messages[-1][1])
    assert memory.messages[-1][0] == LOG_TOPIC and log.message == "HOLD: stale measured_js" and log.level == 3


def test_stream_skips_ticks_closer_than_its_period() -> None:
    """At a 1 kHz tick and a 50 ms period, one tick in fifty is streamed."""
    memory = Memory()
    model = PsmModel.from_variant("classic")
    stream = SceneStream(PsmScene(model, "PSM1_base"), [memory], period_s=0.05)
    for tick in range(1000):
        stream.tick(0.001 * tick, model.home(), 0.0)
    assert sum(topic == TRANSFORMS_TOPIC for topic, _, _ in memory.messages) == 20


def test_live_server_serves_the_scene_on_loopback() -> None:
    """A client on ws://127.0.0.1 is greeted with every scene channel, before anything was logged on them
    (a channel made after the client connected could not be subscribed to at once), and receives the arm's
    frames."""
    model = PsmModel.from_variant("classic")
    live = LiveScene(port=0)
    try:
        stream = SceneStream(PsmScene(model, "PSM1_base"), [live])
        with connect(f"ws://127.0.0.1:{live.port}", subprotocols=[SUBPROTOCOL], open_timeout=60) as client:
            message = json.loads(client.recv(timeout=60))
            while message["op"] != "advertise":
                message = json.loads(client.recv(timeout=60))
            channels: dict[str, Any] = {c["topic"]: c for c in message["channels"]}
            assert set(channels) == {TRANSFORMS_TOPIC, ARM_TOPIC, TASK_TOPIC, LOG_TOPIC}
            assert channels[TRANSFORMS_TOPIC]["schemaName"] == "foxglove.FrameTransforms"
            assert channels[ARM_TOPIC]["schemaName"] == "foxglove.SceneUpdate"
            subscription = {"id": 7, "channelId": channels[TRANSFORMS_TOPIC]["id"]}
            client.send(json.dumps({"op": "subscribe", "subscriptions": [subscription]}))
            frames = None
            for _ in range(1000):  # a failure guard; each round waits for a message, not for a set time
                # The protocol has no acknowledgement of a subscription: tick until a message comes through.
                stream.tick(1.0, model.home(), 0.0)
                try:
                    data = client.recv(timeout=0.5)
                except TimeoutError:
                    continue
                if isinstance(data, bytes) and data[0] == MESSAGE_DATA:
                    subscription_id, _ = struct.unpack_from("<IQ", data, 1)
                    assert subscription_id == 7
                    frames = data[13:]
                    break
    finally:
        live.close()
    sent = decode(PsmScene(model, "PSM1_base").transforms(1.0, model.home(), 0.0))
    assert frames == sent.SerializeToString()
    insertion = next(t for t in sent.transforms if t.child_frame_id == "insertion_link")
    home = model.configuration(model.home())
    assert np.isclose(insertion.translation.z, home.frame_pose_local("insertion_link")[2, 3])


def test_evaluate_live_serves_the_simulation_scene() -> None:
    """evaluate --live prints its address, and a client subscribed to the task topic sees the tissue flap."""
    command = [sys.executable, "-m", "tissue_retract", "evaluate", "--policy", "scripted", "--task", "lift"]
    # Twenty real-time episodes (minutes of streaming) so the run outlasts the client's subscription by far;
    # the test ends it once a message has come through.
    command += ["--episodes", "20", "--seeds", "1", "--live", "0"]
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as process:
        try:
            assert process.stdout is not None
            line = ""
            while not line.startswith("live: ws://127.0.0.1:"):
                line = process.stdout.readline()
                assert line, process.stderr.read() if process.stderr else "evaluate ended before serving"
            address = line.split()[1]
            with connect(address, subprotocols=[SUBPROTOCOL], open_timeout=120) as client:
                channels: dict[str, Any] = {}
                while TASK_TOPIC not in channels:
                    message = json.loads(client.recv(timeout=120))
                    if message["op"] == "advertise":
                        channels.update({c["topic"]: c for c in message["channels"]})
                client.send(
                    json.dumps(
                        {"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channels[TASK_TOPIC]["id"]}]}
                    )
                )
                data = client.recv(timeout=120)
                while not (isinstance(data, bytes) and data[0] == MESSAGE_DATA):
                    data = client.recv(timeout=120)
        finally:
            process.kill()
    update = PsmScene(PsmModel.from_variant("classic"), "world").task(0.0)  # an empty update, for its schema
    schema = update.get_schema()
    files = descriptor_pb2.FileDescriptorSet.FromString(bytes(schema.data))
    pool = descriptor_pool.DescriptorPool()
    for file in files.file:
        pool.Add(file)
    received = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name)).FromString(data[13:])
    entities = {entity.id: entity for entity in received.entities}
    assert {"tissue", "site", "goal"} <= set(entities)
    assert len(entities["tissue"].triangles[0].points) == 49  # the 7 x 7 flap
