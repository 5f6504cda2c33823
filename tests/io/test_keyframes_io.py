"""Keyframe files (``--keyframes FILE``): the JSON schema, KITTI label_02 and AV2 annotations.feather rows as world
boxes, and the CLI's one-line errors. Truth: the raw label rows and calibration / pose files in
../shared/data/readers (matrix algebra written out here), and the tiny sequence's known boxes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.feather as feather
import pytest
from scipy.spatial.transform import Rotation

from sot_apps.cli.main import main
from sot_apps.io import open_sequence
from sot_apps.io.keyframes import keyframes_document, pick_keyframe_track, read_keyframes
from sot_apps.io.tracks import read_track

READERS = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "readers"
KITTI = READERS / "kitti_tracking_labels" / "training"
AV2_LOG = READERS / "av2_sensor_test" / "sensor" / "val" / "7fab2350-7eaf-3b7e-a39d-6937a4c1bede"


def _keyframe_file(tmp_path: Path, tiny_dir: Path, frames=(0, 10, 19), track="car-move") -> Path:
    seq = open_sequence(tiny_dir)
    truth = seq.tracks()[track]
    path = tmp_path / "keyframes.json"
    path.write_text(json.dumps(keyframes_document({track: {k: truth.box_at(k) for k in frames}}, seq.id)))
    return path


def test_json_keyframes_round_trip(tiny_dir, tmp_path):
    seq = open_sequence(tiny_dir)
    path = _keyframe_file(tmp_path, tiny_dir)
    tracks = read_keyframes(path, seq)
    name, boxes = pick_keyframe_track(tracks, None, path)
    assert name == "car-move" and sorted(boxes) == [0, 10, 19]
    for k, box in boxes.items():
        np.testing.assert_array_equal(box.to_array(), seq.tracks()["car-move"].box_at(k).to_array())


def test_kitti_label_rows_become_world_boxes():
    seq = open_sequence(KITTI / "label_02" / "0000.txt")   # no oxts: world = velodyne frame
    tracks = read_keyframes(KITTI / "label_02" / "0000.txt", seq)
    calib = {}
    for line in (KITTI / "calib" / "0000.txt").read_text().splitlines():
        key, _, values = line.replace(":", " ", 1).partition(" ")
        if values.strip():
            calib[key] = np.array([float(v) for v in values.split()])
    rect = np.eye(4)
    rect[:3, :3] = calib["R_rect"].reshape(3, 3) if "R_rect" in calib else calib["R0_rect"].reshape(3, 3)
    velo = np.eye(4)
    velo[:3] = (calib["Tr_velo_cam"] if "Tr_velo_cam" in calib else calib["Tr_velo_to_cam"]).reshape(3, 4)
    rect_from_velo = rect @ velo
    rows = [line.split() for line in (KITTI / "label_02" / "0000.txt").read_text().splitlines() if line.strip()]
    checked = 0
    for row in rows:
        if row[2] == "DontCare":
            continue
        frame, track = int(row[0]), row[1]
        h, w, length, x, y, z = (float(v) for v in row[10:16])
        box = tracks[track][frame]
        centre = rect_from_velo[:3, :3] @ box.center + rect_from_velo[:3, 3]
        np.testing.assert_allclose(centre, [x, y - h / 2, z], atol=1e-4)
        np.testing.assert_allclose([box.length, box.width, box.height], [length, w, h], atol=1e-9)
        checked += 1
    assert checked == sum(len(b) for b in tracks.values()) > 100


def test_av2_rows_become_world_boxes():
    seq = open_sequence(AV2_LOG)
    tracks = read_keyframes(AV2_LOG / "annotations.feather", seq)
    rows = feather.read_table(AV2_LOG / "annotations.feather").to_pandas()
    poses = feather.read_table(AV2_LOG / "city_SE3_egovehicle.feather").to_pandas().set_index("timestamp_ns")
    index = {int(f.timestamp_ns): k for k, f in enumerate(seq.frames)}
    for _, row in rows.iloc[:: max(1, len(rows) // 50)].iterrows():
        pose = poses.loc[int(row.timestamp_ns)]
        rotation = Rotation.from_quat([pose.qx, pose.qy, pose.qz, pose.qw]).as_matrix()
        world = rotation @ np.array([row.tx_m, row.ty_m, row.tz_m]) + np.array([pose.tx_m, pose.ty_m, pose.tz_m])
        box = tracks[row.track_uuid][index[int(row.timestamp_ns)]]
        np.testing.assert_allclose(box.center, world, atol=1e-6)
        assert box.length == pytest.approx(row.length_m)
    assert sum(len(b) for b in tracks.values()) == len(rows)


@pytest.mark.parametrize("entry, problem", [
    ({"track_id": "a", "frame": 0, "box": [1, 2, 0.5, 0.1, 4.5, 1.8]}, "box"),
    ({"track_id": "a", "frame": 0, "box": [1, 2, 0.5, 0.1, 4.5, -1.8, 1.5]}, "box[5]"),
    ({"track_id": "a", "frame": -1, "box": [1, 2, 0.5, 0.1, 4.5, 1.8, 1.5]}, "frame"),
    ({"frame": 0, "box": [1, 2, 0.5, 0.1, 4.5, 1.8, 1.5]}, "track_id"),
    ({"track_id": "a", "frame": 0, "box": [1, 2, 0.5, 0.1, 4.5, 1.8, 1.5], "colour": "red"}, "colour"),
    ({"track_id": "a", "frame": 99, "box": [1, 2, 0.5, 0.1, 4.5, 1.8, 1.5]}, "frame 99"),
])
def test_bad_keyframe_files_fail_with_one_line(tiny_dir, tmp_path, capsys, entry, problem):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"keyframes": [entry]}))
    out = tmp_path / "out"
    assert main(["track", str(tiny_dir), "--keyframes", str(path), "--quiet", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and problem in err[0], err
    assert not (out / "track.json").exists()


def test_nan_and_duplicate_keyframes_are_refused(tiny_dir, tmp_path, capsys):
    path = tmp_path / "bad.json"
    path.write_text('{"keyframes": [{"track_id": "a", "frame": 0, "box": [NaN, 2, 0.5, 0.1, 4.5, 1.8, 1.5]}]}')
    assert main(["track", str(tiny_dir), "--keyframes", str(path), "--out", str(tmp_path / "o")]) == 2
    assert "non-finite" in capsys.readouterr().err
    box = [1, 2, 0.5, 0.1, 4.5, 1.8, 1.5]
    path.write_text(json.dumps({"keyframes": [{"track_id": "a", "frame": 3, "box": box}] * 2}))
    assert main(["track", str(tiny_dir), "--keyframes", str(path), "--out", str(tmp_path / "o")]) == 2
    assert "two keyframes at frame 3" in capsys.readouterr().err


def test_track_keyframes_cli_reproduces_the_keyframes(tiny_dir, tmp_path, capsys):
    path = _keyframe_file(tmp_path, tiny_dir)
    out = tmp_path / "track"
    assert main(["track", str(tiny_dir), "--keyframes", str(path), "--quiet", "--out", str(out)]) == 0, \
        capsys.readouterr().err
    header, track = read_track(out)
    truth = open_sequence(tiny_dir).tracks()["car-move"]
    assert track.object_id == "car-move" and header.config["mode"] == "offline"
    assert track.frames.tolist() == list(range(20))
    for frame, (x, y, z, _), flags in zip(track.frames.tolist(), track.states, track.flags, strict=True):
        box = truth.box_at(frame)
        if frame in (0, 10, 19):
            assert (x, y, z) == (box.x, box.y, box.z) and "keyframe" in flags
        assert np.hypot(x - box.x, y - box.y) < 0.3


def test_autolabel_keyframes_writes_labels_through_the_keyframes(tiny_dir, tmp_path, capsys):
    path = _keyframe_file(tmp_path, tiny_dir, frames=(0, 19))
    out = tmp_path / "labels"
    assert main(["autolabel", str(tiny_dir), "--keyframes", str(path), "--quiet", "--no-sequence",
                 "--out", str(out)]) == 0, capsys.readouterr().err
    seq = open_sequence(tiny_dir)
    written = read_keyframes(out / "av2" / "annotations.feather", seq)   # the AV2 rows read back as keyframes
    (boxes,) = written.values()
    assert sorted(boxes) == list(range(20))
    for k in (0, 19):
        np.testing.assert_allclose(boxes[k].to_array(), seq.tracks()["car-move"].box_at(k).to_array(), atol=1e-6)
