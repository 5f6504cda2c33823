"""Waymo v1 reader: the real one-frame file (no range images) and synthetic segments written by an
independent writer (tests/io/waymo_synth.py) from an analytic scene, compared with its truth."""

from __future__ import annotations

import shutil
from collections import Counter
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np
import pytest
import waymo_synth as ws
from scipy.spatial import cKDTree

from sot_apps.errors import InputError
from sot_apps.io import detect_format, open_sequence
from sot_apps.io.waymo import PointSelection, find_waymo_segment, read_waymo_v1
from sot_apps.io.waymo.messages import messages
from sot_apps.io.waymo.range_image import range_image_points
from sot_apps.io.waymo.tfrecord import TFRecordFile, crc32c
from sot_apps.io.waymo.wire import select
from tracker.geometry import invert_transform, transform_points

REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "readers" / "waymo_v1_one_frame"
REAL_FILE = REAL / "pvps_data_one_frame.tfrecord"
CONTEXT = "1024360143612057520_3580_000_3600_000"


@pytest.fixture(scope="module")
def real():
    if not REAL_FILE.is_file():
        pytest.fail(f"real data not found at {REAL_FILE}")
    return REAL_FILE


@pytest.fixture(scope="module")
def real_seq(real, tmp_path_factory):
    return read_waymo_v1(real, image_cache=tmp_path_factory.mktemp("images"))


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    path = tmp_path_factory.mktemp("v1") / "segment-1234567890_1000_000_1020_000_with_camera_labels.tfrecord"
    truth = ws.write_v1(path)
    return path, truth


# ------------------------------------------------------------------------------------------ real file


def test_crc32c_known_value():
    assert crc32c(b"123456789") == 0xE3069283  # the CRC-32C check value
    data = np.random.default_rng(0).integers(0, 256, 5000, dtype=np.uint8).tobytes()
    for n in (1, 63, 64, 65, 999, 5000):
        assert crc32c(data[:n]) == ws.crc32c(data[:n])


def test_real_frame_boxes_ids_and_counts(real_seq):
    assert detect_format(REAL_FILE) == "waymo_v1"
    assert real_seq.id == CONTEXT and len(real_seq) == 1
    assert real_seq.frames[0].timestamp_ns == 1553735853462203 * 1000
    np.testing.assert_allclose(real_seq.frames[0].world_from_ego[:3, 3], [-25211.259, 42391.081, -160.618], atol=1e-3)
    boxes = real_seq.annotations[0]
    assert len(boxes) == 75 and len({b.track_id for b in boxes}) == 75
    assert Counter(b.label for b in boxes) == {"Vehicle": 37, "Sign": 25, "Pedestrian": 12, "Cyclist": 1}
    assert sum(b.num_points for b in boxes) == 44021
    assert sum(b.num_points > 0 for b in boxes) == 73
    assert all(b.box.length > b.box.width for b in boxes if b.label == "Vehicle")  # length along the heading
    assert len(real_seq.sweep(0)) == 0  # the range images were stripped from this file


def test_real_frame_calibrations(real, real_seq):
    header = messages().FrameHeader.FromString(select(TFRecordFile(real).payload(0), {1}))
    lasers = {c.name: c for c in header.context.laser_calibrations}
    assert sorted(lasers) == [1, 2, 3, 4, 5] and len(header.context.camera_calibrations) == 5
    top = lasers[1]
    assert len(top.beam_inclinations) == 64
    assert top.beam_inclination_min == pytest.approx(-0.3118, abs=1e-4)
    assert top.beam_inclination_max == pytest.approx(0.0453, abs=1e-4)
    np.testing.assert_allclose(real_seq.ego_from_lidar.reshape(-1), top.extrinsic.transform)
    sizes = {name: (c.width, c.height) for name, c in real_seq.cameras.items()}
    assert sizes == {"FRONT": (1920, 1280), "FRONT_LEFT": (1920, 1280), "FRONT_RIGHT": (1920, 1280),
                     "SIDE_LEFT": (1920, 886), "SIDE_RIGHT": (1920, 886)}


def test_real_boxes_project_onto_the_files_projected_labels(real, real_seq):
    """Each 3D box projected with our camera model (OpenCV axes, K, distortion, image pose) lands on
    the 2D box Waymo itself projected (projected_lidar_labels, id '<box id>_<CAMERA>')."""
    header = messages().FrameHeader.FromString(select(TFRecordFile(real).payload(0), {9}))
    names = {1: "FRONT", 2: "FRONT_LEFT", 3: "FRONT_RIGHT", 4: "SIDE_LEFT", 5: "SIDE_RIGHT"}
    boxes = {a.track_id: a.box for a in real_seq.annotations[0]}
    checked = 0
    for camera_labels in header.projected_lidar_labels:
        name = names[camera_labels.name]
        camera = real_seq.cameras[name]
        camera_from_world = invert_transform(camera.frames[0].world_from_camera)
        errors = []
        for label in camera_labels.labels:
            corners = transform_points(camera_from_world, boxes[label.id[: -len(name) - 1]].corners())
            assert (corners[:, 2] > 0).all()  # in front of the camera (OpenCV z forward)
            uv = cv2.projectPoints(corners, np.zeros(3), np.zeros(3), camera.K, camera.distortion)[0][:, 0]
            low = np.clip(uv.min(0), 0, [camera.width, camera.height])
            high = np.clip(uv.max(0), 0, [camera.width, camera.height])
            errors.append(np.hypot(*((low + high) / 2 - [label.box.center_x, label.box.center_y])))
        assert np.median(errors) < 1.0, (name, errors)
        checked += len(errors)
    assert checked == 62


def _varint(data: bytes, i: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        byte = data[i]
        i += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if byte < 0x80:
            return value, i


def _fields(data: bytes) -> dict[int, list]:
    """A protobuf message's fields by number (varints as ints, the rest as bytes), decoded here by hand,
    independently of the reader's message definitions."""
    out: dict[int, list] = {}
    i = 0
    while i < len(data):
        key, i = _varint(data, i)
        wire = key & 7
        if wire == 0:
            value, i = _varint(data, i)
        elif wire == 1:
            value, i = data[i:i + 8], i + 8
        elif wire == 2:
            length, i = _varint(data, i)
            value, i = data[i:i + length], i + length
        elif wire == 5:
            value, i = data[i:i + 4], i + 4
        else:
            raise ValueError(f"wire type {wire}")
        out.setdefault(key >> 3, []).append(value)
    return out


def test_real_camera_image_times_are_the_records_exact_ns(real, real_seq):
    """Frame.images[i].pose_timestamp (Frame field 4 -> CameraImage field 5, a double in seconds) becomes the
    nearest integer ns of its exact value; rounding to the microsecond was off by up to 544 ns here."""
    import struct

    names = {1: "FRONT", 2: "FRONT_LEFT", 3: "FRONT_RIGHT", 4: "SIDE_LEFT", 5: "SIDE_RIGHT"}
    images = [_fields(image) for image in _fields(TFRecordFile(real).payload(0))[4]]
    times = {names[image[1][0]]: struct.unpack("<d", image[5][0])[0] for image in images}
    assert len(times) == 5
    off_by = []
    for name, seconds in times.items():
        exact = Fraction(seconds) * 10 ** 9
        ns = real_seq.cameras[name].frames[0].timestamp_ns
        assert isinstance(ns, int) and abs(ns - exact) <= Fraction(1, 2), name
        off_by.append(float(abs(round(seconds * 1e6) * 1000 - exact)))
    assert max(off_by) > 100   # what the microsecond rounding lost on this record


def test_real_camera_images_are_extracted_lazily(real_seq):
    camera = real_seq.cameras["FRONT"]
    frame = camera.frames[0]
    assert frame.timestamp_ns - real_seq.frames[0].timestamp_ns == pytest.approx(52.4e6, abs=0.1e6)
    cached = frame._path
    assert not cached.exists()  # nothing extracted until the path is used
    path = frame.image_path
    assert path == cached and path.is_file()
    image = cv2.imread(str(path))
    assert image.shape == (1280, 1920, 3)


# ------------------------------------------------------------------------------------------ synthetic segment


def test_synthetic_points_match_the_ray_cast_truth(synthetic):
    path, truth = synthetic
    seq = open_sequence(path)
    assert seq.format == "waymo_v1" and seq.id == truth.context and len(seq) == 3
    for k in range(len(seq)):
        sweep = seq.sweep(k)
        assert len(sweep) == len(truth.points[k]) > 1000
        distance, index = cKDTree(sweep.xyz).query(truth.points[k])
        assert distance.max() < 1e-4
        assert len(np.unique(index)) == len(index)
        np.testing.assert_allclose(sweep.intensity[index], truth.intensity[k], atol=1e-6)
        np.testing.assert_allclose(seq.frames[k].world_from_ego, truth.world_from_ego[k])
        assert seq.frames[k].timestamp_ns == truth.timestamps_us[k] * 1000


def test_choosing_lidars_and_returns(synthetic):
    path, truth = synthetic
    pose = truth.world_from_ego[0]
    cast = ws.cast_lidar(ws.TOP, ws.Scene.around(truth.world_from_ego[0]), pose, (1.0, 0.03))
    first = np.isfinite(cast.range_images[0][..., 0]) & (cast.range_images[0][..., 0] > 0)
    seq = read_waymo_v1(path, points=PointSelection(lidars=("TOP",), returns=(1,)))
    sweep = seq.sweep(0)
    assert len(sweep) == int(first.sum())
    assert cKDTree(cast.points_ego).query(sweep.xyz)[0].max() < 1e-4
    second_only = read_waymo_v1(path, points=PointSelection(returns=(2,))).sweep(0)
    assert 0 < len(second_only) < len(open_sequence(path).sweep(0)) - len(sweep)
    with pytest.raises(InputError, match="unknown Waymo lidar"):
        PointSelection(lidars=("LEFT",))


def test_top_lidar_pixel_poses_matter():
    """Control: the same TOP range image read without its per-pixel poses misses the truth by
    decimetres, so the comparison above does check the pixel-pose path."""
    pose = ws.synthetic_poses(1)[0]
    cast = ws.cast_lidar(ws.TOP, ws.Scene.around(pose), pose, (1.0, 0.03))
    rows = ws.TOP.row_inclinations()
    right, _ = range_image_points(cast.range_images[0], ws.TOP.vehicle_from_lidar, rows, cast.pose_image,
                                  invert_transform(pose))
    wrong, _ = range_image_points(cast.range_images[0], ws.TOP.vehicle_from_lidar, rows)
    n = len(right)
    assert np.abs(right - cast.points_ego[:n]).max() < 1e-4
    assert np.abs(wrong - cast.points_ego[:n]).max() > 0.2


def test_synthetic_boxes_tracks_and_camera(synthetic):
    path, truth = synthetic
    seq = open_sequence(path)
    for k in range(len(seq)):
        got = {a.track_id: a for a in seq.annotations[k]}
        assert set(got) == {"car-7", "ped-2"}
        for b in truth.boxes[k]:
            a = got[b.track_id]
            assert a.label == {1: "Vehicle", 2: "Pedestrian"}[b.type_code] and a.num_points == 123
            np.testing.assert_allclose(a.box.to_array()[[0, 1, 2, 4, 5, 6]], np.array(b.world)[[0, 1, 2, 4, 5, 6]],
                                       atol=1e-6)
            assert np.cos(a.box.heading - b.world[3]) == pytest.approx(1.0)
    tracks = seq.tracks()
    assert list(tracks["car-7"].frames) == [0, 1, 2] and tracks["car-7"].label == "Vehicle"

    camera = seq.cameras["FRONT"]
    assert (camera.width, camera.height) == ws.CAMERA_SIZE and len(camera.frames) == 3
    point = transform_points(truth.world_from_ego[0], np.array([[20.0, 2.0, 1.0]]))[0]
    for k in range(3):
        frame = camera.frames[k]
        assert frame.timestamp_ns == round(Fraction(truth.image_times_s[k]) * 10 ** 9)
        assert frame.image_path.read_bytes() == ws.jpeg(k)
        uv = cv2.projectPoints(transform_points(invert_transform(frame.world_from_camera), point[None]),
                               np.zeros(3), np.zeros(3), camera.K, camera.distortion)[0][0, 0]
        np.testing.assert_allclose(uv, ws.waymo_project(point, truth.image_world_from_vehicle[k]), atol=1e-6)


def test_lidar_sot_segment_is_found_and_its_ids_are_the_readers_track_ids(real, tmp_path):
    """LiDAR-SOT names this frame's segment; find_waymo_segment finds it under its official file name and
    11 of the 14 LiDAR-SOT tracklet ids of the segment are track ids of the frame (the others start later)."""
    import json

    lists = REAL.parent / "lidar_sot_benchmark"
    tracklets = [t for kind in ("vehicle", "pedestrian") for t in json.loads((lists / kind / "bench_list.json").read_text())
                 if CONTEXT in t["segment_name"]]
    assert len(tracklets) == 14
    name = tracklets[0]["segment_name"]
    (tmp_path / f"{name}.tfrecord").symlink_to(real)
    path = find_waymo_segment(tmp_path, name)
    assert path == tmp_path / f"{name}.tfrecord"
    seq = read_waymo_v1(path, image_cache=tmp_path / "images")
    ids = set(seq.tracks())
    assert sum(t["id"] in ids for t in tracklets) == 11
    types = {t["id"]: t["type"] for t in tracklets}
    labels = {1: "Vehicle", 2: "Pedestrian"}
    assert all(seq.tracks()[i].label == labels[types[i]] for i in ids & set(types))


def test_directory_with_one_tfrecord_and_find_segment(synthetic, tmp_path):
    path, truth = synthetic
    assert detect_format(path.parent) == "waymo_v1"
    assert find_waymo_segment(path.parent, path.stem) == path
    assert find_waymo_segment(path.parent, truth.context) == path
    (tmp_path / "validation").mkdir()
    shutil.copyfile(path, tmp_path / "validation" / path.name)
    assert find_waymo_segment(tmp_path, path.stem) == tmp_path / "validation" / path.name
    with pytest.raises(InputError, match="segment 999_1_000_2_000 not found"):
        find_waymo_segment(tmp_path, "segment-999_1_000_2_000_with_camera_labels")
    with pytest.raises(InputError, match="does not exist"):
        find_waymo_segment(tmp_path / "nope", path.stem)


# ------------------------------------------------------------------------------------------ bad input


def test_truncated_file_is_named_at_open(synthetic, tmp_path):
    path, _ = synthetic
    data = path.read_bytes()
    bad = tmp_path / "cut.tfrecord"
    bad.write_bytes(data[: len(data) - 100])
    with pytest.raises(InputError, match="truncated TFRecord: record 2") as info:
        open_sequence(bad)
    assert str(bad) in info.value.one_line()


def test_bad_length_crc_is_named_at_open(synthetic, tmp_path):
    path, _ = synthetic
    data = bytearray(path.read_bytes())
    data[8] ^= 0xFF
    bad = tmp_path / "crc.tfrecord"
    bad.write_bytes(bytes(data))
    with pytest.raises(InputError, match="record 0 at byte 0 fails its length CRC"):
        open_sequence(bad)


def test_bad_data_crc_is_named_when_the_frame_is_read(synthetic, tmp_path):
    path, _ = synthetic
    data = bytearray(path.read_bytes())
    (length,) = np.frombuffer(bytes(data[:8]), "<u8")
    data[12 + int(length) - 10] ^= 0x01  # inside record 0's last label
    bad = tmp_path / "data.tfrecord"
    bad.write_bytes(bytes(data))
    seq = open_sequence(bad)  # framing is fine; the data CRC is checked on first use
    with pytest.raises(InputError, match="record 0 .* fails its data CRC"):
        seq.sweep(0)
    assert len(seq.sweep(1)) > 0
    data[12] = 0x07  # the first tag: wire type 7 does not exist, the record no longer parses
    bad.write_bytes(bytes(data))
    with pytest.raises(InputError, match="record 0 .* fails its data CRC"):
        open_sequence(bad)


def test_not_a_frame(tmp_path):
    bad = tmp_path / "x.tfrecord"
    bad.write_bytes(ws.tfrecord([b"\x0a\xff\xff\xff\xff\x0f"]))
    with pytest.raises(InputError, match="record 0 is not a Waymo Frame"):
        open_sequence(bad)
