"""Boxes keep the source's full orientation (roll and pitch), through the readers and the canonical format.

Truth: AV2's own ``num_interior_pts`` (counted by Argo in the EGO frame) for world-frame boxes; analytic
rotations for Waymo (a box level in a pitched vehicle frame) and nuScenes (a tilted quaternion).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sot_apps.io import open_sequence
from sot_apps.io.canonical import read_sequence, write_sequence
from sot_apps.io.nuscenes import annotation_box
from sot_apps.io.waymo.common import box_annotation
from tracker.geometry import Box, make_transform, points_in_box, rotation_zyx, transform_points, zyx_angles

from .paths import AV2_LOG_A, AV2_LOG_B


def _world_counts(seq) -> tuple[int, int, float]:
    """(boxes whose world-frame count equals num_points, boxes at frames with a sweep, largest |pitch|)."""
    equal = total = 0
    for info in seq.frames:
        if not info.has_sweep:
            continue
        world = seq.points_world(info.index)
        for ann in seq.annotations[info.index]:
            equal += int(points_in_box(world, ann.box).sum()) == ann.num_points
            total += 1
    tilt = max(abs(a.box.pitch) + abs(a.box.roll) for frame in seq.annotations for a in frame)
    return equal, total, tilt


@pytest.mark.parametrize("log, boxes", [(AV2_LOG_A, 162), (AV2_LOG_B, 47)])
def test_av2_world_boxes_hold_num_interior_pts(readers_root, tmp_path, log, boxes):
    """World points in every world box == AV2's num_interior_pts, from the reader and from its canonical copy
    (upright world boxes got 135 of 162 on 7fab2350)."""
    seq = open_sequence(log)
    assert _world_counts(seq)[:2] == (boxes, boxes)
    assert _world_counts(seq)[2] > 0.01       # the ego pose does tilt these boxes
    write_sequence(seq, tmp_path / "canonical", progress=False)
    copy = read_sequence(tmp_path / "canonical")
    assert _world_counts(copy)[:2] == (boxes, boxes)
    doc = json.loads((tmp_path / "canonical" / "sequence.json").read_text())
    assert doc["schema_version"] == 2
    assert all("roll" in b and "pitch" in b and "num_points" in b for f in doc["frames"] for b in f["boxes"])


def test_av2_upright_world_boxes_miss_counts(readers_root):
    """Negative control: the same boxes made upright lose points on the tilted ego (why roll/pitch matter)."""
    seq = open_sequence(AV2_LOG_A)
    k = next(f.index for f in seq.frames if f.has_sweep)
    world = seq.points_world(k)
    level = [Box(*a.box.to_array()) for a in seq.annotations[k]]
    equal = sum(int(points_in_box(world, b).sum()) == a.num_points
                for b, a in zip(level, seq.annotations[k], strict=True))
    assert equal < len(level) - 5


def test_waymo_box_takes_the_vehicle_pitch():
    """A Waymo box is level in the vehicle frame: in the world it has the vehicle pose's roll and pitch."""
    world_from_ego = make_transform(rotation_zyx(0.7, 0.06, -0.03), [100.0, -50.0, 3.0])
    ann = box_annotation("a", 1, (10.0, 2.0, 1.0), 4.5, 2.0, 1.6, 0.4, world_from_ego, Path("seg.tfrecord"), "frame 0")
    np.testing.assert_allclose(ann.box.rotation(), world_from_ego[:3, :3] @ rotation_zyx(0.4), atol=1e-12)
    assert abs(ann.box.pitch) > 0.03
    # points in the vehicle-frame box are the points in the world box
    rng = np.random.default_rng(0)
    ego_points = rng.uniform(-4, 4, (20000, 3)) + [10.0, 2.0, 1.0]
    in_ego = points_in_box(ego_points, Box(10.0, 2.0, 1.0, 0.4, 4.5, 2.0, 1.6))
    np.testing.assert_array_equal(points_in_box(transform_points(world_from_ego, ego_points), ann.box), in_ego)


def test_nuscenes_box_keeps_its_quaternion():
    rotation = Rotation.from_euler("ZYX", [1.1, -0.04, 0.02])
    x, y, z, w = rotation.as_quat()
    box = annotation_box({"token": "t", "translation": [1.0, 2.0, 3.0], "size": [2.0, 4.5, 1.7],
                          "rotation": [w, x, y, z]})
    np.testing.assert_allclose(box.rotation(), rotation.as_matrix(), atol=1e-12)
    assert (box.length, box.width, box.height) == (4.5, 2.0, 1.7)
    assert zyx_angles(box.rotation()) == pytest.approx((1.1, -0.04, 0.02))


def test_version_1_documents_read_as_level_boxes(tmp_path):
    """A schema-version-1 sequence.json (no roll/pitch) still reads, as roll = pitch = 0."""
    root = tmp_path / "v1"
    (root / "points").mkdir(parents=True)
    np.savez_compressed(root / "points" / "000000.npz", xyz=np.zeros((1, 3), np.float32))
    box = {"track_id": "a", "label": "Car", "x": 1.0, "y": 2.0, "z": 0.5, "heading": 0.3, "length": 4.0,
           "width": 2.0, "height": 1.5}
    doc = {"schema_version": 1, "id": "old", "ego_from_lidar": np.eye(4).tolist(),
           "frames": [{"timestamp_ns": 0, "world_from_ego": np.eye(4).tolist(), "points": "points/000000.npz",
                       "boxes": [box]}]}
    (root / "sequence.json").write_text(json.dumps(doc))
    ann = read_sequence(root).annotations[0][0]
    assert ann.box == Box(1.0, 2.0, 0.5, 0.3, 4.0, 2.0, 1.5) and ann.box.is_level and ann.num_points is None


def test_tilted_points_in_box_is_exact_on_an_analytic_case():
    """A box pitched by 30 degrees: a point just inside its tilted top face is outside the level box, and
    vice versa."""
    box = Box(0.0, 0.0, 0.0, 0.0, 4.0, 2.0, 1.0, pitch=math.radians(30))
    top = np.array([[0.0, 0.0, 0.0]]) + 0.49 * box.rotation()[:, 2]   # inside, near the tilted top face
    corner_level = np.array([[1.9, 0.0, 0.45]])                     # inside the level box only
    assert points_in_box(top, box).all()
    assert not points_in_box(corner_level, box).any()
    assert points_in_box(corner_level, Box(0.0, 0.0, 0.0, 0.0, 4.0, 2.0, 1.0)).all()
    # transformed(keep_tilt=True) is the same solid in another frame
    target_from_source = make_transform(rotation_zyx(-0.5, 0.1, 0.2), [3.0, 1.0, -2.0])
    moved = box.transformed(target_from_source, keep_tilt=True)
    np.testing.assert_allclose(moved.corners(), transform_points(target_from_source, box.corners()), atol=1e-12)


def test_trajectories_place_tilted_boxes_as_given(readers_root):
    """Flow places objects with objects.trajectory: its poses and object-frame points follow the boxes' roll and
    pitch (AV2 boxes on a tilted ego); a level trajectory is unchanged."""
    from sot_apps.io.object_track import ObjectTrack
    from sot_apps.objects.shapes import ShapeParams, object_points_by_frame
    from sot_apps.objects.trajectory import Trajectory

    seq = open_sequence(AV2_LOG_A)
    k = next(f.index for f in seq.frames if f.has_sweep)
    tracks = {a.track_id: ObjectTrack.from_boxes(a.track_id, a.label, {k: a.box})
              for a in seq.annotations[k] if a.num_points > 50}
    points, stamped = object_points_by_frame(seq, tracks, ShapeParams(capture_time=False, ground_clearance=None))
    assert tracks and points
    for tid, track in stamped.items():
        trajectory = Trajectory.from_track(track)
        box = tracks[tid].box(0)
        np.testing.assert_allclose(trajectory.world_from_object_at(seq.frames[k].timestamp_ns), box.world_from_object(),
                                   atol=1e-12)
        corners = box.corners()
        local = trajectory.object_from_world_points(corners, np.full(8, seq.frames[k].timestamp_ns))
        np.testing.assert_allclose(np.abs(local), np.tile(box.size / 2, (8, 1)), atol=1e-9)
    level = Trajectory.from_samples([0, 10], [[0, 0, 0, 0.1], [1, 0, 0, 0.2]], tilts=[(0, 0), (0, 0)])
    assert level.tilts is None
    np.testing.assert_array_equal(level.world_from_object_at(5), Trajectory.from_samples(
        [0, 10], [[0, 0, 0, 0.1], [1, 0, 0, 0.2]]).world_from_object_at(5))


def test_motion_export_from_av2_annotations_keeps_the_tilt(readers_root, tmp_path):
    """``motion-export --from-annotations`` on an AV2 log, read back with the mcap reader: every object transform
    and box marker has the roll and pitch of the sequence's box at that frame, and the smoothed heading of the
    object's kinematics message (the MCAP wrote level boxes before)."""
    import json

    from mcap.decoder import DecoderFactory as McapDecoderFactory
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory
    from scipy.spatial.transform import Rotation as R

    from sot_apps.cli.main import main

    class JsonDecoderFactory(McapDecoderFactory):
        def decoder_for(self, message_encoding, schema):
            return (lambda data: json.loads(data)) if message_encoding == "json" else None

    seq = open_sequence(AV2_LOG_A)
    tracks = seq.tracks()
    ids = sorted((t for t in tracks if tracks[t].label in ("REGULAR_VEHICLE", "BOX_TRUCK", "BUS")),
                 key=lambda t: (-len(tracks[t].frames), t))[:3]
    assert main(["motion-export", str(AV2_LOG_A), "--from-annotations", "--track-id", *ids,
                 "--out", str(tmp_path / "gt.mcap"), "--quiet"]) == 0
    frame_of = {int(f.timestamp_ns): f.index for f in seq.frames}
    boxes = {(k, tid): box for tid in ids for k, box in tracks[tid].boxes_by_frame().items()}
    orientations, headings = [], {}
    with open(tmp_path / "gt.mcap", "rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory(), JsonDecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages():
            k = frame_of[message.log_time]
            if channel.topic == "/tf":
                orientations += [(k, t.child_frame_id.removeprefix("object/"), t.rotation) for t in decoded.transforms
                                 if t.child_frame_id.startswith("object/")]
            elif channel.topic == "/markers/objects":
                orientations += [(k, e.id, e.cubes[0].pose.orientation) for e in decoded.entities]
            elif channel.topic.endswith("/kinematics"):
                headings[(k, decoded["object_id"])] = decoded["heading"]
    assert len(orientations) == 2 * len(boxes) and len(headings) == len(boxes)
    tilt = 0.0
    for k, tid, q in orientations:
        box = boxes[(k, tid)]
        heading, pitch, roll = zyx_angles(R.from_quat([q.x, q.y, q.z, q.w]).as_matrix())
        assert (roll, pitch) == pytest.approx((box.roll, box.pitch), abs=1e-9)
        assert math.remainder(heading - headings[(k, tid)], 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
        tilt = max(tilt, abs(box.roll) + abs(box.pitch))
    assert tilt > 0.01
