"""`sot-apps info` / `convert` on Waymo v1 and v2 files: the real one-frame file (no points), synthetic
segments, and one-line errors with exit code 2 for corrupt input."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import waymo_synth as ws

from sot_apps.cli.main import main
from sot_apps.io import open_sequence

READERS = Path(__file__).resolve().parents[3] / "shared" / "data" / "readers" / "waymo_v1_one_frame"
REAL_FILE = READERS / "pvps_data_one_frame.tfrecord"
REAL_POSES = READERS / "v2_vehicle_pose" / "10023947602400723454_1120_000_1140_000.parquet"


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    """Extracted camera images go to a temporary cache, not the user's."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))


def test_info_on_the_real_frame_says_it_has_no_points(capsys):
    assert main(["info", str(REAL_FILE)]) == 0
    out = capsys.readouterr().out
    assert "waymo_v1" in out and "frames    1," in out
    assert "points    per frame: min 0, median 0, max 0" in out
    assert "no points in any frame" in out
    assert "annotated tracks: 75 (37 vehicles" in out
    assert "SIDE_LEFT    1920x886" in out


def test_convert_the_real_frame(tmp_path, capsys):
    out_dir = tmp_path / "canonical"
    assert main(["convert", str(REAL_FILE), "--out", str(out_dir)]) == 0
    assert "1 frames, 5 cameras, 75 annotated tracks" in capsys.readouterr().out
    source, copy = open_sequence(REAL_FILE), open_sequence(out_dir)
    assert copy.format == "sequence" and len(copy.sweep(0)) == 0
    np.testing.assert_allclose(copy.frames[0].world_from_ego, source.frames[0].world_from_ego)
    assert {a.track_id for a in copy.annotations[0]} == {a.track_id for a in source.annotations[0]}
    for name, camera in source.cameras.items():
        assert copy.cameras[name].frames[0].image_path.read_bytes() == camera.frames[0].image_path.read_bytes()
        np.testing.assert_allclose(copy.cameras[name].K, camera.K)


def test_info_and_convert_synthetic_v1_and_v2(tmp_path, capsys):
    v1 = tmp_path / "seg.tfrecord"
    truth = ws.write_v1(v1, num_frames=2)
    v2 = tmp_path / "v2"
    ws.write_v2(v2, REAL_POSES, lidar_frames=(0,), camera_frames=1)
    for source, frames in ((v1, 2), (v2, 199)):
        assert main(["info", str(source), "--json"]) == 0
        assert f'"num_frames": {frames}' in capsys.readouterr().out
        out_dir = tmp_path / f"out_{source.name}"
        assert main(["convert", str(source), "--out", str(out_dir)]) == 0
        capsys.readouterr()
        copy = open_sequence(out_dir)
        original = open_sequence(source)
        assert len(copy) == frames
        np.testing.assert_array_equal(copy.sweep(0).xyz, original.sweep(0).xyz)
        assert copy.tracks().keys() == {"car-7", "ped-2"}
    assert len(open_sequence(tmp_path / "out_seg.tfrecord").sweep(1)) == len(truth.points[1])


def test_corrupt_tfrecord_gives_one_line_and_exit_2(tmp_path, capsys):
    data = REAL_FILE.read_bytes()
    cut = tmp_path / "cut.tfrecord"
    cut.write_bytes(data[:100_000])
    assert main(["info", str(cut)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {cut}: truncated TFRecord")

    flipped = bytearray(data)
    flipped[1_000_000] ^= 0x10
    bad = tmp_path / "bad.tfrecord"
    bad.write_bytes(bytes(flipped))
    assert main(["convert", str(bad), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {bad}: corrupt TFRecord: record 0") and "data CRC" in err[0]
    assert not (tmp_path / "out" / "sequence.json").exists()


def test_v2_directory_without_vehicle_pose_is_not_a_sequence(tmp_path, capsys):
    (tmp_path / "lidar").mkdir()
    shutil.copyfile(REAL_POSES, tmp_path / "lidar" / REAL_POSES.name)
    assert main(["info", str(tmp_path)]) == 2
    assert "unknown sequence format" in capsys.readouterr().err
