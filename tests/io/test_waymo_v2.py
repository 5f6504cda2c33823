"""Waymo v2 reader: the real vehicle_pose parquet, plus the other components written for the same
segment by an independent writer (tests/io/waymo_synth.py) and compared with its truth."""

from __future__ import annotations

import shutil
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import waymo_synth as ws
from scipy.spatial import cKDTree

from sot_apps.errors import InputError
from sot_apps.io import detect_format, open_sequence
from sot_apps.io.waymo import PointSelection, find_waymo_segment, read_waymo_v2
from tracker.geometry import invert_transform, transform_points

REAL = (Path(__file__).resolve().parents[3] / "shared" / "data" / "readers" / "waymo_v1_one_frame" / "v2_vehicle_pose"
        / "10023947602400723454_1120_000_1140_000.parquet")
SEGMENT = REAL.stem


@pytest.fixture(scope="module")
def real_pose():
    if not REAL.is_file():
        pytest.fail(f"real data not found at {REAL}")
    return REAL


@pytest.fixture(scope="module")
def synthetic(real_pose, tmp_path_factory):
    root = tmp_path_factory.mktemp("v2")
    truth = ws.write_v2(root, real_pose)
    return root, truth


def test_real_vehicle_poses_alone(real_pose, tmp_path):
    (tmp_path / "vehicle_pose").mkdir()
    shutil.copyfile(real_pose, tmp_path / "vehicle_pose" / real_pose.name)
    assert detect_format(tmp_path) == "waymo_v2"
    seq = open_sequence(tmp_path / "vehicle_pose" / real_pose.name)
    assert seq.format == "waymo_v2" and seq.id == SEGMENT and len(seq) == 199
    stamps = seq.timestamps_ns
    assert (stamps[-1] - stamps[0]) * 1e-9 == pytest.approx(19.8, abs=0.05)
    assert np.median(np.diff(stamps)) * 1e-6 == pytest.approx(100.0, abs=0.5)
    table = pq.read_table(real_pose)
    first = int(np.argmin(table.column("key.frame_timestamp_micros").to_numpy()))
    expected = np.asarray(table.column(2).to_pylist()[first], dtype=np.float64).reshape(4, 4)
    np.testing.assert_allclose(seq.frames[0].world_from_ego, expected, atol=1e-6)  # rotation snapped to orthonormal
    rotation = seq.frames[0].world_from_ego[:3, :3]
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
    assert seq.annotations is None and seq.cameras == {} and len(seq.sweep(0)) == 0


def test_synthetic_components_match_truth(synthetic):
    root, truth = synthetic
    seq = open_sequence(root)
    assert seq.id == SEGMENT and len(seq) == 199
    for k in range(len(seq)):
        assert seq.frames[k].timestamp_ns == truth.timestamps_us[k] * 1000
    for k, points in truth.points.items():
        sweep = seq.sweep(k)
        assert len(sweep) == len(points) > 1000
        distance, index = cKDTree(sweep.xyz).query(points)
        # the real poses are float32 at ~15.6 km from the origin: the reader snaps their rotations to
        # orthonormal (~1e-7 change), which moves points by ~1.5 mm there; a convention error would be metres off
        assert distance.max() < 3e-3
        np.testing.assert_allclose(sweep.intensity[index], truth.intensity[k], atol=1e-6)
    assert len(seq.sweep(2)) == 0  # frames without lidar rows are empty sweeps
    for k, boxes in truth.boxes.items():
        got = {a.track_id: a for a in seq.annotations[k]}
        for b in boxes:
            a = got[b.track_id]
            assert a.num_points == 55
            np.testing.assert_allclose(a.box.to_array()[[0, 1, 2, 4, 5, 6]], np.array(b.world)[[0, 1, 2, 4, 5, 6]],
                                       atol=1e-3)
            assert np.cos(a.box.heading - b.world[3]) == pytest.approx(1.0)
    assert seq.annotations[2] == []
    assert list(seq.tracks()["car-7"].frames) == [0, 1, 50]


def test_choosing_a_lidar(synthetic):
    root, truth = synthetic
    front = ws.cast_lidar(ws.FRONT, ws.Scene.around(truth.world_from_ego[0]), truth.world_from_ego[0], (1.0, 0.03))
    sweep = read_waymo_v2(root, points=PointSelection(lidars=("FRONT",))).sweep(0)
    assert len(sweep) == len(front.points_ego)
    assert cKDTree(front.points_ego).query(sweep.xyz)[0].max() < 3e-3


def test_synthetic_camera(synthetic):
    root, truth = synthetic
    seq = open_sequence(root / "lidar" / f"{SEGMENT}.parquet")
    camera = seq.cameras["FRONT"]
    assert len(camera.frames) == 2 and (camera.width, camera.height) == ws.CAMERA_SIZE
    point = transform_points(truth.world_from_ego[0], np.array([[20.0, -1.5, 0.5]]))[0]
    for k in range(2):
        frame = camera.frames[k]
        assert frame.timestamp_ns == round(Fraction(truth.image_times_s[k]) * 10 ** 9)
        assert frame.image_path.read_bytes() == ws.jpeg(k)
        uv = cv2.projectPoints(transform_points(invert_transform(frame.world_from_camera), point[None]),
                               np.zeros(3), np.zeros(3), camera.K, camera.distortion)[0][0, 0]
        np.testing.assert_allclose(uv, ws.waymo_project(point, truth.image_world_from_vehicle[k]), atol=1e-3)


def test_find_segment_v2(synthetic):
    root, _ = synthetic
    found = find_waymo_segment(root, f"segment-{SEGMENT}_with_camera_labels")
    assert found == root / "vehicle_pose" / f"{SEGMENT}.parquet"
    assert open_sequence(found).id == SEGMENT


def test_bad_components_are_named(synthetic, tmp_path):
    root, _ = synthetic
    shutil.copytree(root, tmp_path / "data")
    lidar = tmp_path / "data" / "lidar" / f"{SEGMENT}.parquet"
    table = pq.read_table(lidar).drop_columns(["key.laser_name"])
    pq.write_table(table, lidar)
    with pytest.raises(InputError, match=r"missing columns \['key.laser_name'\]") as info:
        open_sequence(tmp_path / "data")
    assert str(lidar) in info.value.one_line()
    lidar.write_bytes(b"PAR1 not really")
    with pytest.raises(InputError, match="cannot read parquet"):
        open_sequence(tmp_path / "data")
    box = tmp_path / "data" / "lidar_box" / f"{SEGMENT}.parquet"
    table = pq.read_table(box)
    table = table.set_column(0, "key.segment_context_name", pa.array(["other"] * len(table)))
    pq.write_table(table, box)
    lidar.unlink()
    with pytest.raises(InputError, match="rows of other segments"):
        open_sequence(tmp_path / "data")
