"""KITTI readers: tracking labels projected with the calibration match the 2D boxes (real files); View-of-Delft
boxes contain their points (real files); velodyne + oxts written from the synthetic world read back exactly."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sot_apps.cli.main import main
from sot_apps.io import detect_format, open_sequence
from sot_apps.io.tiny import TINY_NUM_FRAMES
from tracker.geometry import invert_transform, points_in_box, transform_points

from .paths import KITTI_TRACKING, VOD


def _label_2d_boxes(path: Path) -> dict[tuple[int, str], np.ndarray]:
    """(frame, track id) -> labelled 2D box, parsed independently of the reader."""
    out = {}
    for line in path.read_text().splitlines():
        p = line.split()
        if p and p[2] != "DontCare":
            out[(int(p[0]), p[1])] = np.array([float(v) for v in p[6:10]])
    return out


def _iou_2d(a: np.ndarray, b: np.ndarray) -> float:
    w = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    h = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = w * h
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


@pytest.mark.parametrize("seq_name, boxes", [("0000", 711), ("0001", 3030), ("0012", 249)])
def test_tracking_boxes_project_onto_the_labelled_2d_boxes(readers_root, seq_name, boxes):
    label_path = KITTI_TRACKING / "label_02" / f"{seq_name}.txt"
    seq = open_sequence(label_path)
    assert seq.format == "kitti_tracking" and len(seq.missing_sweeps()) == len(seq)  # labels only: no velodyne
    cam = seq.cameras["image_02"]
    truth = _label_2d_boxes(label_path)
    ious = []
    for k, frame_boxes in enumerate(seq.annotations):
        camera_from_world = invert_transform(seq.frames[k].world_from_ego @ cam.ego_from_camera)
        for ann in frame_boxes:
            corners = transform_points(camera_from_world, ann.box.corners())
            if (corners[:, 2] <= 0.1).any():
                continue
            uv = corners[:, :2] / corners[:, 2:] * np.diag(cam.K)[:2] + cam.K[:2, 2]
            box = np.array([*uv.min(axis=0), *uv.max(axis=0)])
            box = np.clip(box, 0, [1241, 374, 1241, 374])
            ious.append(_iou_2d(box, truth[(k, ann.track_id)]))
    assert sum(len(a) for a in seq.annotations) == boxes
    assert len(ious) > 0.95 * boxes
    assert np.median(ious) >= 0.95, np.median(ious)


def test_tracking_track_ids_and_first_van(readers_root):
    seq = open_sequence(f"{KITTI_TRACKING}#0000")
    tracks = seq.tracks()
    assert len(tracks) == 15 and tracks["0"].label == "Van"
    first = tracks["0"].box(0)
    np.testing.assert_allclose([first.x, first.y, first.z], [13.69, 4.56, -0.74], atol=0.01)  # SOURCE.md


def test_tracking_calib_accepts_both_key_spellings(readers_root, tmp_path):
    root = tmp_path / "training"
    (root / "calib").mkdir(parents=True)
    (root / "label_02").mkdir()
    text = (KITTI_TRACKING / "calib" / "0012.txt").read_text()
    official = (text.replace("R0_rect:", "R_rect").replace("Tr_velo_to_cam:", "Tr_velo_cam")
                .replace("Tr_imu_to_velo:", "Tr_imu_velo"))
    (root / "calib" / "0012.txt").write_text(official)
    (root / "label_02" / "0012.txt").symlink_to(KITTI_TRACKING / "label_02" / "0012.txt")
    a = open_sequence(KITTI_TRACKING / "label_02" / "0012.txt")
    b = open_sequence(root / "label_02" / "0012.txt")
    assert [x.box for x in a.annotations[5]] == [x.box for x in b.annotations[5]]


def test_vod_boxes_contain_their_points(readers_root):
    seq = open_sequence(VOD)
    assert detect_format(VOD) == "kitti_object" and len(seq) == 3
    assert [len(seq.sweep(k)) for k in range(3)] == [167772, 189088, 182450]
    counts = []
    for k in range(3):
        world = seq.points_world(k)
        counts += [int(points_in_box(world, a.box).sum()) for a in seq.annotations[k]]
    assert len(counts) == 62
    # SOURCE.md: 59 of 62 boxes hold points, 18,432 points in all with heading = -rotation - pi/2
    assert sum(c > 0 for c in counts) >= 59 and sum(counts) >= 18000, (sum(c > 0 for c in counts), sum(counts))
    labels = {a.label for frame in seq.annotations for a in frame}
    assert {"Pedestrian", "Cyclist", "Car"} <= labels and "DontCare" not in labels
    # the odometry poses put the three frames at different places, z up
    assert all(f.world_from_ego[2, 2] > 0.99 for f in seq.frames)
    assert len(seq.cameras["image_2"].frames) == 3


# -------------------------------------------------------- velodyne + oxts from the synthetic world

def _write_kitti_tracking(tiny, root: Path, lat0: float = 48.98, lon0: float = 8.39) -> dict:
    """KITTI tracking files of the tiny world (an independent writer: the format's documentation)."""
    rng = np.random.default_rng(0)
    name = "0003"
    for sub in ("calib", "label_02", "oxts", f"velodyne/{name}"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    # a velodyne mounted 0.3 m ahead of the IMU, rotated 2 degrees; camera looking forward (KITTI axes)
    a = math.radians(2.0)
    velo_from_imu = np.eye(4)
    velo_from_imu[:3, :3] = [[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]]
    velo_from_imu[:3, 3] = [-0.3, 0.1, -0.8]
    cam_from_velo = np.array([[0.0, -1, 0, 0.02], [0, 0, -1, -0.07], [1, 0, 0, -0.27], [0, 0, 0, 1]])
    r0 = np.eye(3)
    p2 = np.array([[700.0, 0, 600, 45], [0, 700, 180, 0.2], [0, 0, 1, 0.003]])
    fmt = lambda m: " ".join(f"{v:.12e}" for v in np.asarray(m).ravel())  # noqa: E731
    (root / "calib" / f"{name}.txt").write_text(
        f"P0: {fmt(p2)}\nP1: {fmt(p2)}\nP2: {fmt(p2)}\nP3: {fmt(p2)}\nR_rect {fmt(r0)}\n"
        f"Tr_velo_cam {fmt(cam_from_velo[:3])}\nTr_imu_velo {fmt(velo_from_imu[:3])}\n")
    # oxts: the IMU pose in east/north/up -> latitude/longitude by inverting the Mercator projection
    er = 6378137.0
    scale = math.cos(math.radians(lat0))
    mx0 = scale * math.radians(lon0) * er
    my0 = scale * er * math.log(math.tan(math.radians(90 + lat0) / 2))
    lines, labels = [], []
    yaw_offset = 0.4  # the tiny world rotated about z, so that east/north differ from its x/y
    turn = np.eye(4)
    turn[:2, :2] = [[math.cos(yaw_offset), -math.sin(yaw_offset)], [math.sin(yaw_offset), math.cos(yaw_offset)]]
    for k in range(TINY_NUM_FRAMES):
        world_from_imu = turn @ tiny.frames[k].world_from_ego @ velo_from_imu  # ego = velodyne
        x, y, z = world_from_imu[:3, 3]
        lon = math.degrees((mx0 + x) / (scale * er))
        lat = math.degrees(2 * math.atan(math.exp((my0 + y) / (scale * er)))) - 90
        yaw = math.atan2(world_from_imu[1, 0], world_from_imu[0, 0])
        lines.append(" ".join(f"{v:.12f}" for v in [lat, lon, z, 0.0, 0.0, yaw] + [0.0] * 24))
        pts = tiny.sweep(k).xyz  # ego = velodyne
        data = np.column_stack([pts, rng.uniform(0, 1, len(pts))]).astype("<f4")
        if k != 7:  # frame 7's sweep was dropped
            data.tofile(root / "velodyne" / name / f"{k:06d}.bin")
        for tid_index, ann in enumerate(tiny.annotations[k]):
            box_velo = ann.box.transformed(invert_transform(tiny.frames[k].world_from_ego))
            bottom = transform_points(cam_from_velo, np.array([[box_velo.x, box_velo.y, box_velo.z - box_velo.height / 2]]))[0]
            ry = -box_velo.heading - math.pi / 2  # cam_from_velo above: camera x = -velo y, z = velo x
            labels.append(f"{k} {tid_index} Car 0 0 0.0 0 0 10 10 {box_velo.height:.6f} {box_velo.width:.6f} "
                          f"{box_velo.length:.6f} {bottom[0]:.6f} {bottom[1]:.6f} {bottom[2]:.6f} {ry:.6f}")
        labels.append(f"{k} -1 DontCare -1 -1 -10 1 1 5 5 -1000 -1000 -1000 -10 -1 -1 -10")
    (root / "oxts" / f"{name}.txt").write_text("\n".join(lines) + "\n")
    (root / "label_02" / f"{name}.txt").write_text("\n".join(labels) + "\n")
    return {"name": name, "turn": turn, "world_from_imu0": turn @ tiny.frames[0].world_from_ego @ velo_from_imu}


def test_velodyne_and_oxts_from_the_synthetic_world(tmp_path):
    from sot_apps.io.tiny import make_tiny_sequence

    tiny = open_sequence(make_tiny_sequence(tmp_path / "tiny"))
    info = _write_kitti_tracking(tiny, tmp_path / "training")
    seq = open_sequence(tmp_path / "training" / "velodyne" / info["name"])
    assert len(seq) == TINY_NUM_FRAMES and seq.missing_sweeps() == [7]
    # the reader's world: east/north/up with the origin at the first IMU position
    offset = info["world_from_imu0"][:3, 3]
    for k in (0, 5, 19):
        expected = info["turn"] @ tiny.frames[k].world_from_ego
        expected[:3, 3] -= offset
        np.testing.assert_allclose(seq.frames[k].world_from_ego, expected, atol=2e-6)
        np.testing.assert_allclose(seq.sweep(k).xyz, tiny.sweep(k).xyz, atol=1e-6)
        for got, ann in zip(seq.annotations[k], tiny.annotations[k], strict=True):
            want = ann.box.transformed(info["turn"])
            assert got.label == "Car"
            np.testing.assert_allclose([got.box.x, got.box.y, got.box.z], np.array([want.x, want.y, want.z]) - offset, atol=2e-5)
            assert abs(math.remainder(got.box.heading - want.heading, 2 * math.pi)) < 1e-5
            np.testing.assert_allclose(got.box.size, want.size, atol=1e-5)
    assert len(seq.tracks()) == 2 and sum(len(a) for a in seq.annotations) == 2 * TINY_NUM_FRAMES


@pytest.mark.parametrize("case, message", [
    ("truncated_bin", "not a multiple of 16"),
    ("missing_calib_key", "Tr_velo_to_cam / Tr_velo_cam is missing"),
    ("malformed_label", "line 3: expected 17 fields"),
])
def test_bad_input_names_the_file(tmp_path, capsys, case, message):
    from sot_apps.io.tiny import make_tiny_sequence

    tiny = open_sequence(make_tiny_sequence(tmp_path / "tiny"))
    root = tmp_path / "training"
    info = _write_kitti_tracking(tiny, root)
    name = info["name"]
    if case == "truncated_bin":
        path = root / "velodyne" / name / "000002.bin"
        path.write_bytes(path.read_bytes()[:-5])
        args = ["info", str(root / "label_02" / f"{name}.txt")]
    elif case == "missing_calib_key":
        path = root / "calib" / f"{name}.txt"
        path.write_text("\n".join(l for l in path.read_text().splitlines() if not l.startswith("Tr_velo")))
        args = ["info", str(root / "label_02" / f"{name}.txt"), "--no-point-stats"]
    else:
        path = root / "label_02" / f"{name}.txt"
        lines = path.read_text().splitlines()
        lines[2] = " ".join(lines[2].split()[:9])
        path.write_text("\n".join(lines))
        args = ["info", str(path), "--no-point-stats"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and message in err[0], err
