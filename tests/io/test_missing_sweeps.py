"""Frames without a sweep: PandaSet copies without some NN.npz, canonical frames without "points",
``info`` reporting them, the tracker predicting across a gap, motion export skipping them."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sot_apps.cli.main import main
from sot_apps.io import open_sequence
from sot_apps.io.canonical import write_sequence
from tracker.metrics import iou_3d


def pandaset_copy_without(root: Path, out: Path, missing: range) -> Path:
    """A PandaSet-layout copy of ``root`` (symlinks) without ``lidar/NN.npz`` for the frames in ``missing``."""
    out.mkdir()
    for entry in root.iterdir():
        if entry.name != "lidar":
            (out / entry.name).symlink_to(entry.resolve())
    (out / "lidar").mkdir()
    for f in (root / "lidar").iterdir():
        if not (f.name.endswith(".npz") and int(f.name[:2]) in missing):
            (out / "lidar" / f.name).symlink_to(f.resolve())
    return out


@pytest.fixture(scope="module")
def gap_copy(pandaset_root, tmp_path_factory) -> Path:
    return pandaset_copy_without(pandaset_root, tmp_path_factory.mktemp("gap") / "p002", range(20, 24))


def test_pandaset_missing_npz_are_frames_without_sweep(gap_copy, pandaset):
    seq = open_sequence(gap_copy)
    assert len(seq) == len(pandaset) and seq.missing_sweeps() == [20, 21, 22, 23]
    assert not seq.frames[21].has_sweep and seq.frames[21].points_path is None and len(seq.sweep(21)) == 0
    # poses, times and boxes continue through the gap
    np.testing.assert_array_equal(seq.frames[21].world_from_ego, pandaset.frames[21].world_from_ego)
    assert seq.frames[21].timestamp_ns == pandaset.frames[21].timestamp_ns
    assert len(seq.annotations[21]) == len(pandaset.annotations[21]) > 0
    assert len(seq.sweep(24)) == len(pandaset.sweep(24))
    assert not seq.lidar_frame(22).has_sweep and seq.lidar_frame(24).has_sweep


def test_info_lists_missing_sweeps(gap_copy, capsys):
    assert main(["info", str(gap_copy), "--no-point-stats"]) == 0
    out = capsys.readouterr().out
    assert "missing: 20-23" in out
    assert main(["info", str(gap_copy), "--json", "--no-point-stats"]) == 0
    assert json.loads(capsys.readouterr().out)["missing_sweeps"] == [20, 21, 22, 23]


def test_canonical_frames_without_points_and_empty_sweeps(tiny_copy, tmp_path, capsys):
    doc = json.loads((tiny_copy / "sequence.json").read_text())
    for k in (5, 6, 7):
        (tiny_copy / doc["frames"][k].pop("points")).unlink()
    np.savez(tiny_copy / doc["frames"][9]["points"], xyz=np.zeros((0, 3), np.float32))  # empty, not missing
    (tiny_copy / "sequence.json").write_text(json.dumps(doc))
    seq = open_sequence(tiny_copy)
    assert seq.missing_sweeps() == [5, 6, 7] and len(seq.sweep(9)) == 0 and seq.frames[9].has_sweep
    assert main(["info", str(tiny_copy)]) == 0
    out = capsys.readouterr().out
    assert "missing: 5-7; empty: 9" in out
    # convert keeps them missing (no point file, no "points" entry)
    write_sequence(seq, tmp_path / "out", progress=False)
    again = open_sequence(tmp_path / "out")
    assert again.missing_sweeps() == [5, 6, 7] and not (tmp_path / "out" / "points" / "000006.npz").exists()
    assert [len(b) for b in again.annotations] == [len(b) for b in seq.annotations]


@pytest.fixture(scope="module")
def gap_track(gap_copy, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("gap_track") / "t"
    code = main(["track", str(gap_copy), "--track-id", "8ac00bad", "--start-frame", "12", "--end-frame", "30",
                 "--quiet", "--out", str(out)])
    assert code == 0
    return out


def test_track_across_a_4_frame_gap_keeps_the_vehicle(gap_track, pandaset):
    from sot_apps.io.tracks import read_track

    _, track = read_track(gap_track)
    truth = pandaset.tracks()[track.object_id]
    flags = dict(zip(track.frames.tolist(), track.flags, strict=True))
    assert [k for k, f in flags.items() if "no_sweep" in f] == [20, 21, 22, 23]
    assert all(n == 0 for k, n in zip(track.frames, track.num_points, strict=True) if 20 <= k <= 23)
    ious = {k: iou_3d(box, truth.box_at(k)) for k, box in track.boxes_by_frame().items()}
    assert min(ious[k] for k in range(24, 31)) > 0.5, ious


def test_motion_export_marks_frames_without_sweep(gap_track, gap_copy, tmp_path):
    import pyarrow.parquet as pq
    from mcap.reader import make_reader

    code = main(["motion-export", str(gap_copy), "--tracks", str(gap_track), "--out", str(tmp_path / "m.mcap"),
                 "--with-points", "--parquet", str(tmp_path / "m.parquet"), "--quiet"])
    assert code == 0
    rows = pq.read_table(tmp_path / "m.parquet").to_pylist()
    assert [r["frame"] for r in rows if not r["valid"]] == [20, 21, 22, 23]
    with open(tmp_path / "m.mcap", "rb") as handle:
        summary = make_reader(handle).get_summary()
    counts = {c.topic: summary.statistics.channel_message_counts[cid] for cid, c in summary.channels.items()}
    assert counts["/lidar/points"] == 19 - 4  # frames 12..30 minus the four without a sweep


def test_flow_marks_pairs_without_a_sweep(gap_copy, tmp_path):
    from sot_apps.schemas import validate

    out = tmp_path / "flow"
    args = [str(gap_copy), "--from-annotations", "--track-id", "8ac00bad", "--camera", "front_camera",
            "--pairs", "19:21", "--shape-frames", "10:30", "--mode", "sparse", "--no-vis", "--out", str(out), "--quiet"]
    assert main(["flow", *args]) == 0
    stats = json.loads((out / "front_camera" / "stats.json").read_text())
    validate("flow_stats", stats, out / "stats.json")
    assert [p.get("no_lidar_sweep") for p in stats["pairs"]] == [[20], [20, 21]]
    assert all(p["pixels"] > 0 for p in stats["pairs"])  # the flow comes from the object states


def test_tracker_prior_scales_with_elapsed_time():
    """A frame twice as far in time is predicted twice as far (no sweep: prediction only; the motion model
    keeps its prior per second, ``prior_per_second``, as ``full`` does)."""
    from tracker import Box, LidarFrame, Tracker, TrackerConfig

    tracker = Tracker(TrackerConfig().with_overrides(["motion.per_second=true"]))
    eye = np.eye(4)
    # 1 m per 0.1 s frame as the known initial motion
    tracker.start(LidarFrame(0, 0, np.zeros((0, 3)), eye), Box(0, 0, 0.8, 0, 4, 2, 1.6),
                  initial_motion=np.array([1.0, 0.0, 0.0, 0.0]))
    one = tracker.step(LidarFrame(1, 100_000_000, np.zeros((0, 3)), eye, has_sweep=False))
    three = tracker.step(LidarFrame(2, 300_000_000, np.zeros((0, 3)), eye, has_sweep=False))
    assert one.flags == ("no_sweep", "prior_only") and one.box.x == pytest.approx(1.0)
    assert three.box.x == pytest.approx(3.0)
