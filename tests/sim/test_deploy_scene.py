"""A deploy recording holds the 3-D scene in Foxglove's schemas, and it agrees with the recorded commands."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader

from hardware_if.recording.recorder import CHANNELS, read_recording
from psm_control.robot import PsmModel
from sim.scene3d import COMMANDED_PREFIX, RCM_FRAME
from sim.scene_stream import ARM_TOPIC, LOG_TOPIC, TASK_TOPIC, TRANSFORMS_TOPIC
from tests.conftest import run_cli
from tests.sim.test_scene3d import _matrix

LAYOUT = Path(__file__).resolve().parents[2] / "docs" / "foxglove" / "tissue-retract-layout.json"


def _decoder(schema: object) -> object:
    files = descriptor_pb2.FileDescriptorSet.FromString(schema.data)  # type: ignore[attr-defined]
    pool = descriptor_pool.DescriptorPool()
    for file in files.file:
        pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))  # type: ignore[attr-defined]


def test_deploy_recording_has_the_scene_and_its_arm_follows_the_commands(tmp_path: Path) -> None:
    """Foxglove schemas on the scene topics; every commanded arm's frames are the FK of the last recorded command."""
    record = tmp_path / "run.mcap"
    # The recording is under test, not the policy's speed (the fault matrix tests overruns): on a loaded
    # machine a step can take longer than the default 0.05 s budget, so the budget here is a hang guard.
    deploy = ("deploy", "--policy", "scripted", "--target", "sim", "--task", "lift", "--policy-budget", "600")
    result = run_cli(*deploy, "--record", str(record))
    assert result.returncode == 0, result.stderr
    model = PsmModel.from_variant("classic")
    configuration = model.configuration()
    schemas: dict[str, str] = {}
    last_command: dict[str, object] | None = None
    checked = 0
    with record.open("rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            schemas[channel.topic] = schema.name if schema is not None else ""
            if channel.topic == "/deploy/command":
                last_command = json.loads(message.data)
            if channel.topic != TRANSFORMS_TOPIC:
                continue
            frames = {t.child_frame_id: t for t in _decoder(schema).FromString(message.data).transforms}
            assert frames[RCM_FRAME].parent_frame_id == "world"
            if COMMANDED_PREFIX + "insertion_link" not in frames or last_command is None:
                continue
            configuration.update(np.asarray(last_command["q"]), float(last_command["jaw"]))
            for link in ("insertion_link", "wrist_pitch_link", "jaw_left_link"):
                t = frames[COMMANDED_PREFIX + link]
                expected = configuration.frame_pose_local(link)
                np.testing.assert_allclose(_matrix(t.translation, t.rotation), expected, atol=1e-9)
            checked += 1
    assert checked >= 40  # one per policy step of the episode
    assert schemas[TRANSFORMS_TOPIC] == "foxglove.FrameTransforms"
    assert schemas[ARM_TOPIC] == schemas[TASK_TOPIC] == "foxglove.SceneUpdate"
    assert schemas[LOG_TOPIC] == "foxglove.Log"
    # The JSON channels read as before, and the scene's channels do not get in their way.
    topics = {topic for topic, _, _ in read_recording(record)}
    assert topics <= set(CHANNELS) and "/deploy/measured" in topics


def test_the_foxglove_layout_shows_recorded_topics() -> None:
    """Every topic the documented Foxglove layout shows is one a recording has."""
    layout = json.loads(LAYOUT.read_text(encoding="utf-8"))
    shown = set(re.findall(r'"(/(?:deploy|scene)/[a-z_]+)', json.dumps(layout)))
    assert shown and shown <= set(CHANNELS) | {TRANSFORMS_TOPIC, ARM_TOPIC, TASK_TOPIC, LOG_TOPIC}
    assert layout["layout"]["first"].startswith("3D!")
