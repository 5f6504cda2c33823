"""Canonical sequence format: round trip, resumable writing, and bad files named at the right time."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from sot_apps.errors import InputError
from sot_apps.io import detect_format, open_sequence
from sot_apps.io.canonical import read_points_file, read_sequence, write_sequence
from sot_apps.io.tiny import TINY_NUM_FRAMES, TINY_TRACKS, _sweep, make_tiny_sequence
from tracker.geometry import points_in_box


def assert_sequences_equal(a, b) -> None:
    assert len(a) == len(b)
    assert a.id == b.id
    np.testing.assert_array_equal(a.ego_from_lidar, b.ego_from_lidar)
    for fa, fb in zip(a.frames, b.frames, strict=True):
        assert fa.timestamp_ns == fb.timestamp_ns and isinstance(fb.timestamp_ns, int)
        np.testing.assert_array_equal(fa.world_from_ego, fb.world_from_ego)
    for k in range(len(a)):
        sa, sb = a.sweep(k), b.sweep(k)
        for name in ("xyz", "intensity", "time_offset_ns"):
            va, vb = getattr(sa, name), getattr(sb, name)
            assert (va is None) == (vb is None)
            if va is not None:
                assert va.dtype == vb.dtype
                np.testing.assert_array_equal(va, vb)
    assert a.cameras.keys() == b.cameras.keys()
    for name, ca in a.cameras.items():
        cb = b.cameras[name]
        np.testing.assert_array_equal(ca.K, cb.K)
        np.testing.assert_array_equal(ca.distortion, cb.distortion)
        assert (ca.width, ca.height, len(ca.frames)) == (cb.width, cb.height, len(cb.frames))
        for fa, fb in zip(ca.frames, cb.frames, strict=True):
            assert fa.timestamp_ns == fb.timestamp_ns
            np.testing.assert_array_equal(fa.world_from_camera, fb.world_from_camera)
            assert Path(fa.image_path).read_bytes() == Path(fb.image_path).read_bytes()
    assert a.annotations == b.annotations


def test_tiny_matches_its_generator(tiny_dir):
    """The written sequence holds exactly what the generator produced (independent of the reader)."""
    seq = open_sequence(tiny_dir)
    assert detect_format(tiny_dir) == "sequence" and seq.format == "sequence"
    assert len(seq) == TINY_NUM_FRAMES
    truth = _sweep(7)
    np.testing.assert_array_equal(seq.sweep(7).xyz, truth.xyz)
    np.testing.assert_array_equal(seq.sweep(7).time_offset_ns, truth.time_offset_ns)
    tracks = seq.tracks()
    assert set(tracks) == set(TINY_TRACKS)
    moving = tracks["car-move"]
    assert moving.box(10).x - moving.box(0).x == pytest.approx(8.0, abs=1e-9)  # 8 m/s for 1 s
    # every car point the generator made lies in its GT box
    inside = points_in_box(seq.points_world(7), moving.box_at(7))
    assert inside.sum() >= 600
    # the camera is rigid and fires 50 ms early: its pose is the ego pose 50 ms earlier
    cam = seq.cameras["front_camera"]
    assert cam.frames[3].timestamp_ns == seq.frames[3].timestamp_ns - 50_000_000
    np.testing.assert_allclose(cam.frames[3].world_from_camera[:3, 3], seq.frames[3].world_from_ego[:3, 3] + [1.25, 0, 1.5])


def test_round_trip(tiny_dir, tmp_path):
    original = open_sequence(tiny_dir)
    write_sequence(original, tmp_path / "copy", progress=False)
    copy = read_sequence(tmp_path / "copy")
    assert_sequences_equal(original, copy)
    # and a second generation is byte-identical in its JSON
    write_sequence(copy, tmp_path / "copy2", progress=False)
    assert json.loads((tmp_path / "copy" / "sequence.json").read_text())["frames"] == \
        json.loads((tmp_path / "copy2" / "sequence.json").read_text())["frames"]


def test_generation_is_deterministic(tiny_dir, tmp_path):
    make_tiny_sequence(tmp_path / "again")
    for path in sorted(tiny_dir.rglob("*")):
        if path.is_file():
            assert (tmp_path / "again" / path.relative_to(tiny_dir)).read_bytes() == path.read_bytes(), path


def test_rewrite_resumes_and_keeps_good_files(tiny_dir, tmp_path):
    seq = open_sequence(tiny_dir)
    out = tmp_path / "out"
    write_sequence(seq, out, progress=False)
    good, bad = out / "points" / "000001.npz", out / "points" / "000002.npz"
    os.utime(good, ns=(1, 1))
    bad.write_bytes(bad.read_bytes()[:100])  # a damaged leftover
    (out / "sequence.json").unlink()         # as after a crash
    write_sequence(seq, out, progress=False)
    assert good.stat().st_mtime_ns == 1                       # kept
    np.testing.assert_array_equal(read_points_file(bad).xyz, seq.sweep(2).xyz)  # rewritten
    assert not list(out.rglob("*.tmp"))


def test_write_validates_before_writing_anything(tiny_dir, tmp_path):
    seq = open_sequence(tiny_dir)
    seq.frames[4] = type(seq.frames[4])(4, seq.frames[4].timestamp_ns, np.full((4, 4), np.nan), seq.frames[4].points_path)
    with pytest.raises(InputError, match=r"frames\[4\]\.world_from_ego\[0\]\[0\]: non-finite"):
        write_sequence(seq, tmp_path / "out", progress=False)
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").rglob("*"))


def test_missing_point_file_is_named_at_open(tiny_copy):
    (tiny_copy / "points" / "000005.npz").unlink()
    with pytest.raises(InputError) as info:
        open_sequence(tiny_copy)
    assert info.value.path == str(tiny_copy / "sequence.json")
    assert "frames[5].points" in info.value.problem and "000005.npz" in info.value.problem


def test_missing_image_is_named_at_open(tiny_copy):
    (tiny_copy / "cameras" / "front_camera" / "000002.png").unlink()
    with pytest.raises(InputError, match=r"cameras\.front_camera\.frames\[2\]\.image"):
        open_sequence(tiny_copy)


def test_truncated_point_file_is_named_when_loaded(tiny_copy):
    path = tiny_copy / "points" / "000003.npz"
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    seq = open_sequence(tiny_copy)  # lazy: opening works
    seq.sweep(2)
    with pytest.raises(InputError, match="truncated or corrupt") as info:
        seq.sweep(3)
    assert info.value.path == str(path)


@pytest.mark.parametrize("arrays,message", [
    ({"xyz": np.zeros((5, 3))}, "'xyz' must be float32"),
    ({"xyz": np.zeros((5, 2), np.float32)}, "shape (N, 3)"),
    ({"xyz": np.array([[0, 0, np.nan]], np.float32)}, "non-finite"),
    ({"xyz": np.zeros((5, 3), np.float32), "intensity": np.zeros(4, np.float32)}, "'intensity' must have shape (5,)"),
    ({"xyz": np.zeros((5, 3), np.float32), "time_offset_ns": np.zeros(5, np.float64)}, "'time_offset_ns' must be int64"),
    ({"xyz": np.zeros((5, 3), np.float32), "rgb": np.zeros(5)}, "unknown arrays ['rgb']"),
    ({"points": np.zeros((5, 3), np.float32)}, "unknown arrays"),
])
def test_bad_point_files(tmp_path, arrays, message):
    path = tmp_path / "p.npz"
    np.savez(path, **arrays)
    with pytest.raises(InputError) as info:
        read_points_file(path)
    assert info.value.path == str(path) and message in info.value.problem


def test_non_rigid_pose_rejected(tiny_copy):
    doc = json.loads((tiny_copy / "sequence.json").read_text())
    doc["frames"][1]["world_from_ego"][0][0] = 2.0
    (tiny_copy / "sequence.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"frames\[1\]\.world_from_ego: rotation part"):
        open_sequence(tiny_copy)
