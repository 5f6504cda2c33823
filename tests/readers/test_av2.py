"""Argoverse 2 reader on the av2-api test logs: cuboid conventions reproduce num_interior_pts exactly."""

from __future__ import annotations

import numpy as np
import pyarrow.feather as feather
import pytest

from sot_apps.io import detect_format, open_sequence
from sot_apps.io.av2 import cuboid_box_in_ego, read_cuboids
from tracker.geometry import Box, invert_transform, points_in_box

from .paths import AV2_LOG_A, AV2_LOG_B


@pytest.mark.parametrize("log, boxes", [(AV2_LOG_A, 162), (AV2_LOG_B, 47)])
def test_points_in_each_cuboid_equal_num_interior_pts(readers_root, log, boxes):
    seq = open_sequence(log)
    assert detect_format(log) == "av2"
    cols = read_cuboids(log / "annotations.feather")
    exact = world_ok = total = 0
    for info in seq.frames:
        if not info.has_sweep:
            continue
        xyz = seq.sweep(info.index).xyz
        ego_from_world = invert_transform(info.world_from_ego)
        by_id = {a.track_id: a for a in seq.annotations[info.index]}
        for i in np.flatnonzero(cols["timestamp_ns"] == info.timestamp_ns):
            truth = int(cols["num_interior_pts"][i])
            exact += int(points_in_box(xyz, cuboid_box_in_ego(cols, i, log)).sum()) == truth
            # the sequence's world boxes are the same solids
            world_box = by_id[str(cols["track_uuid"][i])].box.transformed(ego_from_world, keep_tilt=True)
            world_ok += int(points_in_box(xyz, world_box).sum()) == truth
            total += 1
    assert total == boxes
    assert exact == boxes and world_ok == boxes


def test_negative_control_length_along_y_fails(readers_root):
    """Swapping length and width (length along the object's y) breaks the counts, as SOURCE.md says."""
    cols = read_cuboids(AV2_LOG_B / "annotations.feather")
    seq = open_sequence(AV2_LOG_B)
    info = next(f for f in seq.frames if f.has_sweep)
    xyz = seq.sweep(info.index).xyz
    rows = np.flatnonzero(cols["timestamp_ns"] == info.timestamp_ns)
    swapped = 0
    for i in rows:
        b = cuboid_box_in_ego(cols, i, AV2_LOG_B)
        box = Box(b.x, b.y, b.z, b.heading, b.width, b.length, b.height)
        swapped += int(points_in_box(xyz, box).sum()) == int(cols["num_interior_pts"][i])
    assert swapped < 0.5 * len(rows)


def test_frames_poses_times_tracks_and_cameras(readers_root):
    seq = open_sequence(AV2_LOG_A)
    # 156 annotated timestamps, 2 with a sweep: the other 154 are frames without a sweep
    assert len(seq) == 156 and len(seq.missing_sweeps()) == 154
    swept = [f for f in seq.frames if f.has_sweep]
    assert [f.timestamp_ns for f in swept] == [315966265259836000, 315966265360032000]
    sweep = seq.sweep(swept[0].index)
    assert len(sweep) == 99229 and sweep.time_offset_ns.dtype == np.int64
    assert 2e6 < sweep.time_offset_ns.min() and sweep.time_offset_ns.max() < 1.1e8
    # world_from_ego is the pose row at the frame time (an independent read with pyarrow)
    poses = feather.read_table(AV2_LOG_A / "city_SE3_egovehicle.feather").to_pydict()
    row = poses["timestamp_ns"].index(swept[0].timestamp_ns)
    np.testing.assert_allclose(swept[0].world_from_ego[:3, 3], [poses[k][row] for k in ("tx_m", "ty_m", "tz_m")])
    assert len(seq.tracks()) == 114
    cam = seq.cameras["ring_front_center"]
    assert cam.frames == [] and cam.K[0, 0] > 1000 and (cam.width, cam.height) == (1550, 2048)  # portrait
    # the front camera looks along ego +x (OpenCV z axis forward)
    assert cam.ego_from_camera[:3, 2] @ np.array([1.0, 0.0, 0.0]) > 0.99


def test_truncated_sweep_is_named(readers_root, tmp_path, capsys):
    """A copy of a log with a truncated sweep file: one line naming the file, exit 2."""
    from sot_apps.cli.main import main

    log = tmp_path / AV2_LOG_B.name
    log.mkdir()
    for name in ("annotations.feather", "city_SE3_egovehicle.feather"):
        (log / name).symlink_to(AV2_LOG_B / name)
    (log / "sensors" / "lidar").mkdir(parents=True)
    source = next((AV2_LOG_B / "sensors" / "lidar").glob("*.feather"))
    bad = log / "sensors" / "lidar" / source.name
    bad.write_bytes(source.read_bytes()[:5000])
    assert main(["info", str(log)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(bad) in err[0] and "cannot read feather file" in err[0], err
