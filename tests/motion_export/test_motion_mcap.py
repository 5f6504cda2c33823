"""The MCAP file read back with the `mcap` reader and mcap-protobuf-support (independent decoders)."""

from __future__ import annotations

import json
from collections import defaultdict
from itertools import pairwise

import numpy as np
import pytest
from jsonschema import Draft202012Validator, ValidationError
from mcap.decoder import DecoderFactory as McapDecoderFactory
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from sot_apps.motion_export.mcap_writer import METADATA_NAME, write_motion_mcap
from sot_apps.objects.smoother import smooth_track
from sot_apps.schemas import load_schema

from .synthetic import constant_turn, frame_times_ns, make_sequence, make_track


class JsonDecoderFactory(McapDecoderFactory):
    def decoder_for(self, message_encoding, schema):
        if message_encoding == "json":
            return lambda data: json.loads(data)
        return None


N_FRAMES = 12


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    times = frame_times_ns(N_FRAMES, seed=11)
    t = (times - times[0]) * 1e-9
    seq = make_sequence(times)
    a = make_track("car-a", times, constant_turn(t, 8.0, 0.2), shape=True)
    valid_b = np.ones(8, dtype=bool)
    valid_b[3] = False
    b = make_track("car-b", times[2:10], constant_turn(t[2:10], -3.0, 0.0, x0=-10.0), valid=valid_b,
                   frames=np.arange(2, 10))
    kin = [smooth_track(a), smooth_track(b)]
    path = tmp_path_factory.mktemp("mcap") / "motion.mcap"
    summary = write_motion_mcap(path, seq, kin, {"source": "synthetic test", "config": {"k": 1}},
                                with_points=True, progress=False)
    messages = defaultdict(list)
    with open(path, "rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory(), JsonDecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            messages[channel.topic].append((schema.name, message.log_time, decoded))
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    return dict(path=path, seq=seq, kin=kin, summary=summary, messages=messages, metadata=metadata, times=times)


EXPECTED_SCHEMA = {
    "/tf": "foxglove.FrameTransforms",
    "/markers/objects": "foxglove.SceneUpdate",
    "/lidar/points": "foxglove.PointCloud",
    "/objects/car-a/pose": "foxglove.Odometry",
    "/objects/car-b/pose": "foxglove.Odometry",
    "/objects/car-a/kinematics": "sot_apps.Kinematics",
    "/objects/car-b/kinematics": "sot_apps.Kinematics",
    "/objects/car-a/shape": "foxglove.PointCloud",
}


def test_topics_and_schema_names(exported):
    messages = exported["messages"]
    assert set(messages) == set(EXPECTED_SCHEMA)
    for topic, items in messages.items():
        assert {name for name, _, _ in items} == {EXPECTED_SCHEMA[topic]}, topic


def test_message_counts(exported):
    counts = {topic: len(items) for topic, items in exported["messages"].items()}
    assert counts["/tf"] == counts["/markers/objects"] == counts["/lidar/points"] == N_FRAMES
    # kinematics: one per frame of each object (invalid included); pose: one per valid frame
    assert counts["/objects/car-a/kinematics"] == N_FRAMES
    assert counts["/objects/car-b/kinematics"] == 8
    assert counts["/objects/car-a/pose"] == N_FRAMES
    assert counts["/objects/car-b/pose"] == 7
    assert counts["/objects/car-a/shape"] == N_FRAMES  # with its object, at every valid frame
    assert exported["summary"].message_counts == counts
    # one cube per valid object per frame
    cubes = sum(len(e.cubes) for _, _, update in exported["messages"]["/markers/objects"] for e in update.entities)
    assert cubes == N_FRAMES + 7


def test_timestamps_rise_per_channel_and_equal_frame_times(exported):
    frame_times = set(int(t) for t in exported["times"])
    for topic, items in exported["messages"].items():
        stamps = [t for _, t, _ in items]
        assert all(b > a for a, b in pairwise(stamps)), topic
        assert set(stamps) <= frame_times, topic
    for _, log_time, msg in exported["messages"]["/tf"]:
        for tf in msg.transforms:
            assert tf.timestamp.seconds * 1_000_000_000 + tf.timestamp.nanos == log_time


def test_transforms_match_the_inputs(exported):
    seq, kin = exported["seq"], exported["kin"]
    for k, (_, _, msg) in enumerate(exported["messages"]["/tf"]):
        by_child = {tf.child_frame_id: tf for tf in msg.transforms}
        assert all(tf.parent_frame_id == "world" for tf in msg.transforms)
        ego = by_child["ego"]
        w_e = seq.frames[k].world_from_ego
        assert np.allclose([ego.translation.x, ego.translation.y, ego.translation.z], w_e[:3, 3])
        yaw = 2 * np.arctan2(ego.rotation.z, ego.rotation.w)
        assert np.isclose(np.cos(yaw), w_e[0, 0]) and np.isclose(np.sin(yaw), w_e[1, 0])
        a = by_child["object/car-a"]
        assert np.isclose(a.translation.x, kin[0].boxes[k, 0]) and np.isclose(a.translation.y, kin[0].boxes[k, 1])
        # car-b: frames 2..9, its frame 5 (index 3) is invalid and must have no transform
        assert ("object/car-b" in by_child) == (2 <= k <= 9 and k != 5)


def test_odometry_and_markers_carry_the_kinematics(exported):
    kin_a = exported["kin"][0]
    for i, (_, _, odom) in enumerate(exported["messages"]["/objects/car-a/pose"]):
        assert odom.frame_id == "world" and odom.body_frame_id == "object/car-a"
        c, s = np.cos(kin_a.boxes[i, 3]), np.sin(kin_a.boxes[i, 3])
        assert np.isclose(odom.linear_velocity.x, c * kin_a.velocity[i, 0] + s * kin_a.velocity[i, 1])
        assert np.isclose(odom.linear_velocity.y, -s * kin_a.velocity[i, 0] + c * kin_a.velocity[i, 1])
        assert np.isclose(odom.angular_velocity.z, kin_a.yaw_rate[i])
    b_speeds = [float(kv.value) for _, _, update in exported["messages"]["/markers/objects"]
                for e in update.entities if e.id == "car-b" for kv in e.metadata if kv.key == "speed"]
    assert len(b_speeds) == 7 and np.allclose(b_speeds, 3.0, atol=0.01)
    last = exported["messages"]["/markers/objects"][-1][2]
    assert len(last.deletions) == 1  # every update replaces the previous scene
    entity_a = next(e for e in last.entities if e.id == "car-a")
    assert len(entity_a.lines) == 1 and len(entity_a.lines[0].points) == 2 * (N_FRAMES - 1)


def test_point_clouds_decode(exported):
    _, _, cloud = exported["messages"]["/lidar/points"][4]
    assert cloud.frame_id == "ego" and [f.name for f in cloud.fields] == ["x", "y", "z", "intensity"]
    xyzi = np.frombuffer(cloud.data, dtype="<f4").reshape(-1, 4)
    assert np.allclose(xyzi[:, :3], exported["seq"].sweep(4).xyz)
    _, _, shape = exported["messages"]["/objects/car-a/shape"][0]
    assert shape.frame_id == "object/car-a"
    assert np.allclose(np.frombuffer(shape.data, dtype="<f4").reshape(-1, 3), exported["kin"][0].shape_points)


def test_kinematics_messages_validate_against_the_schema(exported):
    validator = Draft202012Validator(load_schema("kinematics"))
    seen_invalid = 0
    for topic in ("/objects/car-a/kinematics", "/objects/car-b/kinematics"):
        for _, _, msg in exported["messages"][topic]:
            validator.validate(msg)
            if not msg["valid"]:
                seen_invalid += 1
                assert msg["flags"] == ["no_points"] and msg["speed"] is None and msg["position"]["x"] is None
    assert seen_invalid == 1
    with pytest.raises(ValidationError):
        validator.validate({**exported["messages"]["/objects/car-a/kinematics"][0][2], "speed": "fast"})


def test_metadata_record_and_atomic_write(exported):
    record = exported["metadata"][METADATA_NAME]
    assert record["source"] == "synthetic test"
    assert json.loads(record["config"]) == {"k": 1}
    assert [o["id"] for o in json.loads(record["objects"])] == ["car-a", "car-b"]
    assert [p.name for p in exported["path"].parent.iterdir()] == ["motion.mcap"]  # no temporary left
