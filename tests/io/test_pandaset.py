"""PandaSet reader on the real sequence 002 and on a native-layout (pandas pickle) copy of two frames."""

from __future__ import annotations

import math
import shutil

import numpy as np

from sot_apps.io import detect_format, open_sequence
from sot_apps.io.pandaset import read_pandaset
from tracker.geometry import points_in_box, wrap_angle


def test_open_reads_no_sweep(pandaset_root):
    calls = []
    seq = open_sequence(pandaset_root)
    original = seq.load_sweep
    seq.load_sweep = lambda k: calls.append(k) or original(k)
    tracks = seq.tracks()
    assert len(tracks) > 50 and len(seq) == 56
    seq.resolve_track_id("8ac00bad")
    assert calls == []


def test_pandaset_conventions_on_track_8ac00bad(pandaset):
    tid = pandaset.resolve_track_id("8ac00bad")
    track = pandaset.tracks()[tid]
    box = track.box_at(10)
    before, after = track.box_at(8), track.box_at(12)
    motion = math.atan2(after.y - before.y, after.x - before.x)
    assert math.hypot(after.y - before.y, after.x - before.x) > 0.5  # it really moves
    assert abs(math.degrees(wrap_angle(box.heading - motion))) < 15.0
    assert box.length > box.width
    assert points_in_box(pandaset.points_world(10), box).sum() >= 900


def test_sensor_1_duplicates_dropped_and_times(pandaset):
    # one box per object per frame
    for frame_annotations in pandaset.annotations:
        ids = [a.track_id for a in frame_annotations]
        assert len(ids) == len(set(ids))
    sweep = pandaset.sweep(0)
    # PandaSet's lidar timestamp marks the END of the sweep: offsets span ~0.1 s before it
    assert -0.12e9 < sweep.time_offset_ns.min() < -0.08e9 and sweep.time_offset_ns.max() < 0.01e9
    assert sweep.time_offset_ns.dtype == np.int64 and sweep.xyz.dtype == np.float32
    # cameras fire before the lidar timestamp: front ~50 ms, back ~100 ms
    for name, expected_ms in (("front_camera", -50), ("back_camera", -100)):
        offsets = [(cf.timestamp_ns - f.timestamp_ns) / 1e6
                   for cf, f in zip(pandaset.cameras[name].frames, pandaset.frames, strict=True)]
        assert abs(np.mean(offsets) - expected_ms) < 5


def _native_copy(root, out, frames=(0, 1)):
    """Build the devkit's native layout (pandas pickles) from the npz/csv copy."""
    import pandas as pd
    (out / "lidar").mkdir(parents=True)
    (out / "annotations" / "cuboids").mkdir(parents=True)
    for name in ("poses.json", "timestamps.json"):
        shutil.copy(root / "lidar" / name, out / "lidar" / name)
    for k in frames:
        with np.load(root / "lidar" / f"{k:02d}.npz") as data:
            pd.DataFrame({c: data[c] for c in ("x", "y", "z", "i", "t", "d")}).to_pickle(out / "lidar" / f"{k:02d}.pkl.gz")
        pd.read_csv(root / "annotations" / "cuboids" / f"{k:02d}.csv").to_pickle(
            out / "annotations" / "cuboids" / f"{k:02d}.pkl.gz")
    return out


def test_native_pickles_read_identically(pandaset_root, tmp_path):
    native = _native_copy(pandaset_root, tmp_path / "native")
    assert detect_format(native) == "pandaset"
    ours = read_pandaset(native)
    reference = open_sequence(pandaset_root)
    assert len(ours) == 2
    for k in range(2):
        assert ours.frames[k].timestamp_ns == reference.frames[k].timestamp_ns
        np.testing.assert_array_equal(ours.frames[k].world_from_ego, reference.frames[k].world_from_ego)
        a, b = ours.sweep(k), reference.sweep(k)
        np.testing.assert_array_equal(a.xyz, b.xyz)
        np.testing.assert_array_equal(a.intensity, b.intensity)
        np.testing.assert_array_equal(a.time_offset_ns, b.time_offset_ns)
        assert len(ours.annotations[k]) > 50
        assert ours.annotations[k] == reference.annotations[k]


def test_pandaset_converts_to_canonical(pandaset_root, tmp_path):
    """PandaSet -> canonical keeps points, poses, times and boxes (incl. the stationary flag) exactly."""
    from sot_apps.io.canonical import write_sequence

    native = read_pandaset(_native_copy(pandaset_root, tmp_path / "native"))
    write_sequence(native, tmp_path / "canonical", progress=False)
    canonical = open_sequence(tmp_path / "canonical")
    assert canonical.format == "sequence" and canonical.id == "native"
    for k in range(2):
        assert canonical.frames[k].timestamp_ns == native.frames[k].timestamp_ns
        np.testing.assert_array_equal(canonical.frames[k].world_from_ego, native.frames[k].world_from_ego)
        np.testing.assert_array_equal(canonical.sweep(k).xyz, native.sweep(k).xyz)
        np.testing.assert_array_equal(canonical.sweep(k).time_offset_ns, native.sweep(k).time_offset_ns)
    assert canonical.annotations == native.annotations
    assert {a.stationary for a in canonical.annotations[0]} == {True, False}


def test_cuboids_csv_that_is_not_utf8_is_one_line_exit_2(tmp_path, pandaset_root, capsys):
    """Issue 16, defect 3: a non-UTF-8 cuboids CSV gave exit 1 and an unnamed UnicodeDecodeError."""
    import shutil

    from sot_apps.cli.main import main

    root = tmp_path / "pandaset_bad"
    root.mkdir()
    for name in ("camera", "lidar", "meta"):
        (root / name).symlink_to((pandaset_root / name).resolve())
    shutil.copytree(pandaset_root / "annotations", root / "annotations")
    bad = root / "annotations" / "cuboids" / "03.csv"
    bad.write_bytes(bad.read_bytes().replace(b"Car", b"C\xe9\xff", 1))
    code = main(["info", str(root)])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "03.csv" in err and "UTF-8" in err


def test_pose_quaternions_match_scipy_bit_for_bit(pandaset_root):
    """pose_to_matrix computes the rotation without scipy (start-up): the same bits as scipy's Rotation, on every
    pose of the sequence (LiDAR and cameras) and on random quaternions of norms 0.6-1.6."""
    import json

    from scipy.spatial.transform import Rotation

    from sot_apps.io.pandaset import pose_to_matrix

    files = [pandaset_root / "lidar" / "poses.json", *sorted((pandaset_root / "camera").glob("*/poses.json"))]
    poses = [p for f in files for p in json.loads(f.read_text())]
    rng = np.random.default_rng(7)
    for q in rng.normal(size=(3000, 4)):
        x, y, z, w = (float(v) for v in q / np.linalg.norm(q) * rng.uniform(0.6, 1.6))
        poses.append({"position": {"x": 1.0, "y": 2.0, "z": 3.0}, "heading": {"w": w, "x": x, "y": y, "z": z}})
    assert len(poses) > 1000
    for pose in poses:
        h = pose["heading"]
        truth = Rotation.from_quat([float(h[k]) for k in ("x", "y", "z", "w")]).as_matrix()
        matrix = pose_to_matrix(pose, files[0], "pose")
        assert np.array_equal(matrix[:3, :3], truth)
        assert matrix[:3, 3].tolist() == [float(pose["position"][k]) for k in ("x", "y", "z")]


def test_cuboid_rows_are_csv_dictreaders_rows(pandaset_root, tmp_path):
    """The cuboid CSVs are read in one loop (not csv.DictReader's per-row method): the same rows, blank rows
    skipped, missing values None and extra ones under None, for the real files and for ragged ones."""
    import csv

    from sot_apps.io.pandaset import _cuboid_rows

    files = sorted((pandaset_root / "annotations" / "cuboids").glob("*.csv"))
    ragged = tmp_path / "00.csv"
    ragged.write_text('uuid,label,yaw\r\na,"Car, big",0.5\n\nb,Bus\nc,Car,1,extra,more\n', encoding="utf-8")
    empty = tmp_path / "01.csv"
    empty.write_text("", encoding="utf-8")
    for path in [*files, ragged, empty]:
        with open(path, newline="", encoding="utf-8") as handle:
            assert _cuboid_rows(path) == list(csv.DictReader(handle)), path
    assert len(files) > 50
