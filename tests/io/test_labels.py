"""Label files for the official tools (``convert --labels kitti|av2``), checked without those tools.

Truth: the original KITTI label_02 and AV2 annotations.feather in ../shared/data/readers, the KITTI devkit's
box-corner formula (written out here), and analytic projections.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.feather as feather
import pytest

from sot_apps.cli.main import main
from sot_apps.io import open_sequence
from sot_apps.io.categories import av2_category, kitti_type
from sot_apps.io.labels import image_box

READERS = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "readers"
KITTI = READERS / "kitti_tracking_labels" / "training"
AV2_LOG = READERS / "av2_sensor_test" / "sensor" / "val" / "7fab2350-7eaf-3b7e-a39d-6937a4c1bede"


def _label_rows(path: Path) -> list[list[str]]:
    return [line.split() for line in path.read_text().splitlines() if line.strip()]


def _calib(path: Path) -> dict[str, np.ndarray]:
    out = {}
    for line in path.read_text().splitlines():
        key, _, values = line.partition(":")
        out[key.strip()] = np.array([float(v) for v in values.split()])
    return out


def _devkit_corners(h, w, l, x, y, z, ry) -> np.ndarray:
    """KITTI devkit compute_box_3d: (3, 8) corners in the rectified camera frame."""
    rotation = np.array([[np.cos(ry), 0, np.sin(ry)], [0, 1, 0], [-np.sin(ry), 0, np.cos(ry)]])
    corners = np.array([[l / 2, l / 2, -l / 2, -l / 2, l / 2, l / 2, -l / 2, -l / 2],
                        [0, 0, 0, 0, -h, -h, -h, -h],
                        [w / 2, -w / 2, -w / 2, w / 2, w / 2, -w / 2, -w / 2, w / 2]])
    return rotation @ corners + np.array([[x], [y], [z]])


def _iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    iw = np.clip(np.minimum(a[:, 2], b[:, 2]) - np.maximum(a[:, 0], b[:, 0]), 0, None)
    ih = np.clip(np.minimum(a[:, 3], b[:, 3]) - np.maximum(a[:, 1], b[:, 1]), 0, None)
    inter = iw * ih
    area = lambda r: (r[:, 2] - r[:, 0]) * (r[:, 3] - r[:, 1])  # noqa: E731
    return inter / (area(a) + area(b) - inter)


@pytest.fixture(scope="module")
def kitti_0000(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("kitti_labels")
    assert main(["convert", str(KITTI / "label_02" / "0000.txt"), "--labels", "kitti", "--out", str(out)]) == 0
    return out


def test_kitti_labels_round_trip_the_original(kitti_0000):
    """The same objects (frame, id, type), 3D boxes within the camera-2 offset, 2D boxes overlapping the
    annotators' 2D boxes (median IoU > 0.95), and no -1 placeholder in the 2D columns."""
    ours = _label_rows(kitti_0000 / "label_02" / "0000.txt")
    original = [r for r in _label_rows(KITTI / "label_02" / "0000.txt") if r[2] != "DontCare"]
    assert len(ours) == len(original) == 711
    assert [r[:3] for r in ours] == [r[:3] for r in original]
    box2d = np.array([[float(v) for v in r[6:10]] for r in ours])
    assert (box2d >= 0).all() and (box2d[:, 2] <= 1241).all() and (box2d[:, 3] <= 374).all()
    assert (box2d[:, 2] > box2d[:, 0]).all() and (box2d[:, 3] > box2d[:, 1]).all()
    iou = _iou(box2d, np.array([[float(v) for v in r[6:10]] for r in original]))
    assert np.median(iou) > 0.95 and (iou > 0.5).mean() > 0.99
    # rotation_y as KITTI's: the reader keeps the box's tilt in the velodyne frame, so it comes back exactly
    np.testing.assert_allclose([float(r[16]) for r in ours], [float(r[16]) for r in original], atol=2e-6)
    hwl = np.array([[float(v) for v in r[10:13]] for r in ours])
    np.testing.assert_allclose(hwl, np.array([[float(v) for v in r[10:13]] for r in original]), atol=1e-5)
    # locations: camera 2's frame is camera 0's shifted along x by -P2[0, 3] / P2[0, 0] (about 6 cm)
    p2 = _calib(KITTI / "calib" / "0000.txt")["P2"].reshape(3, 4)
    offset = np.linalg.solve(p2[:, :3], p2[:, 3])
    xyz = np.array([[float(v) for v in r[13:16]] for r in ours])
    np.testing.assert_allclose(xyz - offset, np.array([[float(v) for v in r[13:16]] for r in original]), atol=2e-3)


def test_kitti_2d_boxes_are_the_projected_3d_corners(kitti_0000):
    """Each 2D box = the devkit's 8 corners of the written 3D box projected with the written P2, clipped to the
    image (1242 x 375: to [0, 1241] x [0, 374], as KITTI's own boxes)."""
    p2 = _calib(kitti_0000 / "calib" / "0000.txt")["P2"].reshape(3, 4)
    near = 0
    for row in _label_rows(kitti_0000 / "label_02" / "0000.txt"):
        h, w, l, x, y, z, ry = (float(v) for v in row[10:17])
        corners = _devkit_corners(h, w, l, x, y, z, ry)
        if corners[2].min() < 0.11:   # reaches the camera plane: cut there (test below); leaves the image
            near += 1
            assert row[3] != "0" and min(float(c) for c in row[6:10]) >= 0
            continue
        uvw = p2 @ np.vstack([corners, np.ones(8)])
        u, v = uvw[0] / uvw[2], uvw[1] / uvw[2]
        expected = [np.clip(u.min(), 0, 1241), np.clip(v.min(), 0, 374), np.clip(u.max(), 0, 1241), np.clip(v.max(), 0, 374)]
        np.testing.assert_allclose([float(c) for c in row[6:10]], expected, atol=1e-3)  # label values have 6 decimals
        truncated = u.min() < 0 or v.min() < 0 or u.max() > 1241 or v.max() > 374
        assert (row[3] != "0") == truncated
    assert near <= 10   # 8 of the 711 boxes of 0000 reach the camera plane


def test_image_box_cuts_at_the_near_plane_and_drops_unseen_boxes():
    K = np.array([[100.0, 0.0, 50.0], [0.0, 100.0, 40.0], [0.0, 0.0, 1.0]])
    ahead = _devkit_corners(2.0, 2.0, 4.0, 0.0, 1.0, 10.0, 0.0).T   # x in [-2, 2], y in [-1, 1], z in [9, 11]
    clipped, raw = image_box(ahead, K, 100, 80)
    np.testing.assert_allclose(raw, [50 - 100 * 2 / 9, 40 - 100 / 9, 50 + 100 * 2 / 9, 40 + 100 / 9])
    np.testing.assert_allclose(clipped, [50 - 100 * 2 / 9, 40 - 100 / 9, 50 + 100 * 2 / 9, 40 + 100 / 9])
    # a cube x, y, z in [-1, 1] straddling the camera plane: only its part at z >= 0.1 is projected
    straddling = _devkit_corners(2.0, 2.0, 2.0, 0.0, 1.0, 0.0, 0.0).T
    clipped, raw = image_box(straddling, K, 100, 80)
    np.testing.assert_allclose(raw, [50 - 100 / 0.1, 40 - 100 / 0.1, 50 + 100 / 0.1, 40 + 100 / 0.1])
    np.testing.assert_allclose(clipped, [0, 0, 99, 79])
    behind = _devkit_corners(2.0, 2.0, 4.0, 0.0, 1.0, -10.0, 0.0).T
    assert image_box(behind, K, 100, 80) is None
    beside = _devkit_corners(2.0, 2.0, 4.0, 40.0, 1.0, 10.0, 0.0).T
    assert image_box(beside, K, 100, 80) is None


def test_kitti_0001_has_447_frames_as_the_devkit_seqmap(tmp_path):
    """0001's label file spans frames 0..446 (426..446 hold only DontCare rows): KITTI's seqmap gives 447."""
    seq = open_sequence(KITTI / "label_02" / "0001.txt")
    assert len(seq) == 447
    last = max(int(line.split()[0]) for line in (KITTI / "label_02" / "0001.txt").read_text().splitlines())
    assert last == 446
    assert all(not seq.annotations[k] for k in range(426, 447)) and seq.annotations[425]


@pytest.fixture(scope="module")
def av2_labels(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("av2_labels")
    assert main(["convert", str(AV2_LOG), "--labels", "av2", "--out", str(out)]) == 0
    return out / "annotations.feather"


def test_av2_feather_matches_the_original_schema_and_rows(av2_labels):
    """Readable with pyarrow, AV2's column names and dtypes, the same rows (boxes, categories, uuids), and
    num_interior_pts equal to AV2's: counted from the sweep where the log has one, the source's count elsewhere."""
    ours = feather.read_table(av2_labels)
    original = feather.read_table(AV2_LOG / "annotations.feather")
    assert [(f.name, f.type) for f in ours.schema] == [(f.name, f.type) for f in original.schema]
    a = ours.to_pandas().sort_values(["timestamp_ns", "track_uuid"]).reset_index(drop=True)
    b = original.to_pandas().sort_values(["timestamp_ns", "track_uuid"]).reset_index(drop=True)
    assert len(a) == len(b) == 11364
    for column in ("timestamp_ns", "track_uuid", "category", "num_interior_pts"):
        assert (a[column] == b[column]).all(), column
    for column in ("length_m", "width_m", "height_m", "tx_m", "ty_m", "tz_m"):
        np.testing.assert_allclose(a[column], b[column], atol=1e-6)
    sign = np.sign((a[["qw", "qx", "qy", "qz"]].to_numpy() * b[["qw", "qx", "qy", "qz"]].to_numpy()).sum(axis=1))
    np.testing.assert_allclose(a[["qw", "qx", "qy", "qz"]].to_numpy() * sign[:, None], b[["qw", "qx", "qy", "qz"]],
                               atol=1e-6)


def test_av2_counts_come_from_the_sweep(av2_labels, tmp_path):
    """Through the canonical format without the source's counts: frames with a sweep still get AV2's counts
    (counted), frames without one get 0."""
    canonical = tmp_path / "canonical"
    assert main(["convert", str(AV2_LOG), "--out", str(canonical)]) == 0
    doc = json.loads((canonical / "sequence.json").read_text())
    for frame in doc["frames"]:
        for box in frame["boxes"]:
            box.pop("num_points")
    (canonical / "sequence.json").write_text(json.dumps(doc))
    assert main(["convert", str(canonical), "--labels", "av2", "--out", str(tmp_path / "av2")]) == 0
    ours = feather.read_table(tmp_path / "av2" / "annotations.feather").to_pandas()
    truth = feather.read_table(AV2_LOG / "annotations.feather").to_pandas()
    swept = {f["timestamp_ns"] for f in doc["frames"] if "points" in f}
    merged = ours.merge(truth, on=["timestamp_ns", "track_uuid"], suffixes=("", "_truth"))
    at_sweeps = merged.timestamp_ns.isin(swept)
    assert at_sweeps.sum() == 162
    assert (merged.num_interior_pts[at_sweeps] == merged.num_interior_pts_truth[at_sweeps]).all()
    assert (merged.num_interior_pts[~at_sweeps] == 0).all()


def test_category_mapping():
    assert av2_category("Car") == "REGULAR_VEHICLE" and kitti_type("REGULAR_VEHICLE") == "Car"
    assert av2_category("vehicle.car") == "REGULAR_VEHICLE" and kitti_type("vehicle.car") == "Car"
    assert av2_category("Vehicle") == "REGULAR_VEHICLE" and av2_category("Pedestrian") == "PEDESTRIAN"
    assert kitti_type("Van") == "Van" and av2_category("Van") == "REGULAR_VEHICLE"
    assert kitti_type("Pickup Truck") == "Car" and av2_category("Pickup Truck") == "REGULAR_VEHICLE"
    assert kitti_type("Cyclist") == "Cyclist" and av2_category("Cyclist") == "BICYCLIST"
    assert av2_category("BOX_TRUCK") == "BOX_TRUCK" and kitti_type("BOX_TRUCK") == "Truck"
    assert kitti_type("BOLLARD") is None and av2_category("Unknown") is None and kitti_type("Sign") is None


def test_labels_never_overwrite_the_input(tmp_path, capsys):
    """An AV2 log written into itself would replace its annotations.feather: refused, exit 2, file unchanged."""
    log = tmp_path / "log"
    log.mkdir()
    for name in ("annotations.feather", "city_SE3_egovehicle.feather"):
        (log / name).symlink_to(AV2_LOG / name)
    before = (AV2_LOG / "annotations.feather").read_bytes()
    assert main(["convert", str(log), "--labels", "av2", "--out", str(log)]) == 2
    err = capsys.readouterr().err   # the command-wide output rule (sot_apps.io.outputs) refuses it first
    assert err.startswith(f"error: {log}: --out is the input SEQUENCE") and "never overwrites an input" in err
    assert err.count("\n") == 1
    assert (AV2_LOG / "annotations.feather").read_bytes() == before


def test_kitti_labels_need_a_camera(tiny_dir, tmp_path, capsys):
    assert main(["convert", str(tiny_dir), "--out", str(tmp_path / "seq")]) == 0
    doc = json.loads((tmp_path / "seq" / "sequence.json").read_text())
    del doc["cameras"]
    (tmp_path / "seq" / "sequence.json").write_text(json.dumps(doc))
    assert main(["convert", str(tmp_path / "seq"), "--labels", "kitti", "--out", str(tmp_path / "k")]) == 2
    assert "need a camera" in capsys.readouterr().err
    assert not (tmp_path / "k" / "label_02").exists()


def test_kitti_labels_use_the_front_camera_of_pandaset():
    """PandaSet's ego frame looks along +y: its front camera is found by name, not by the ego +x direction
    (which would pick the back camera)."""
    from sot_apps.io.labels import kitti_camera

    seq = open_sequence(Path(__file__).resolve().parents[2].parent / "shared" / "data" / "pandaset_002")
    assert kitti_camera(seq).name == "front_camera"
