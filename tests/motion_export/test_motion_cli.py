"""`sot-apps motion-export` end to end on the real PandaSet sequence (ground-truth boxes)."""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
from mcap.reader import make_reader

from sot_apps.cli.main import main


def test_motion_export_from_annotations(tmp_path, pandaset_root, pandaset):
    out = tmp_path / "gt.mcap"
    code = main(["motion-export", str(pandaset_root), "--from-annotations", "--track-id", "8ac00bad", "20d13d1d",
                 "--out", str(out), "--parquet", str(tmp_path / "gt.parquet"), "--npz", str(tmp_path / "gt.npz"),
                 "--csv", str(tmp_path / "gt.csv"), "--quiet"])
    assert code == 0
    with open(out, "rb") as handle:
        reader = make_reader(handle)
        summary = reader.get_summary()
        topics = {c.topic: summary.statistics.channel_message_counts[cid] for cid, c in summary.channels.items()}
        record = next(m for m in reader.iter_metadata())
    ids = [pandaset.resolve_track_id(p) for p in ("8ac00bad", "20d13d1d")]
    n = len(pandaset.frames)
    assert topics["/tf"] == n and topics["/markers/objects"] == n
    for tid in ids:
        assert topics[f"/objects/{tid}/pose"] == len(pandaset.tracks()[tid].frames)
    assert record.metadata["source"] == "annotations" and record.metadata["sequence"] == pandaset.id
    table = pq.read_table(tmp_path / "gt.parquet")
    assert set(table.column("track_id").to_pylist()) == set(ids)
    # exported centres of ground truth stay within a few cm of the annotated centres
    rows = table.to_pylist()
    tracks = pandaset.tracks()
    errors = [np.hypot(r["position_x"] - tracks[r["track_id"]].box_at(r["frame"]).x,
                       r["position_y"] - tracks[r["track_id"]].box_at(r["frame"]).y) for r in rows]
    assert np.median(errors) < 0.05
    with np.load(tmp_path / "gt.npz") as z:
        assert z["valid"].shape == (2, n) and z["valid"].all()


def test_motion_export_usage_errors(tmp_path, pandaset_root, capsys):
    code = main(["motion-export", str(pandaset_root), "--tracks", str(tmp_path / "missing"), "--track-id", "x",
                 "--out", str(tmp_path / "a.mcap")])
    assert code == 2
    assert "--track-id" in capsys.readouterr().err
    code = main(["motion-export", str(pandaset_root), "--tracks", str(tmp_path / "missing"),
                 "--out", str(tmp_path / "a.mcap")])
    err = capsys.readouterr().err
    assert code == 2 and "missing" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "a.mcap").exists()


def _write_flagged_track(directory, pandaset, prefix: str, last: int, flags: dict[int, list[str]]):
    from sot_apps.io.object_track import ObjectTrack
    from sot_apps.io.tracks import TrackHeader, write_track

    tid = pandaset.resolve_track_id(prefix)
    gt = pandaset.tracks()[tid]
    n = last + 1
    track = ObjectTrack.from_states(tid, gt.label, gt.boxes[0, 4:7], range(n),
                                    [int(pandaset.frames[k].timestamp_ns) for k in range(n)], gt.states[:n], None,
                                    [flags.get(k, []) for k in range(n)], scores=[0.9] * n, num_points=[100] * n,
                                    shape_points=np.zeros((5, 3)))
    write_track(directory, TrackHeader(pandaset.id, 0, last, gt.box(0), {"preset": "test"}), track)
    return tid


def test_motion_export_from_track_files_marks_flagged_frames(tmp_path, pandaset_root, pandaset):
    flags = {0: ["init"], 5: ["no_points", "prior_only"], 6: ["prior_only"], 8: ["low_points"]}
    tid = _write_flagged_track(tmp_path / "t1", pandaset, "8ac00bad", 20, flags)
    code = main(["motion-export", str(pandaset_root), "--tracks", str(tmp_path / "t1"), "--out",
                 str(tmp_path / "m.mcap"), "--parquet", str(tmp_path / "m.parquet"), "--quiet"])
    assert code == 0
    rows = pq.read_table(tmp_path / "m.parquet").to_pylist()
    assert [r["frame"] for r in rows] == list(range(21)) and {r["track_id"] for r in rows} == {tid}
    assert [r["frame"] for r in rows if not r["valid"]] == [5, 6]
    assert all(np.isnan(r["position_x"]) for r in rows if not r["valid"])
    assert rows[8]["flags"] == "low_points" and rows[8]["valid"]
    with open(tmp_path / "m.mcap", "rb") as handle:
        summary = make_reader(handle).get_summary()
    counts = {c.topic: summary.statistics.channel_message_counts[cid] for cid, c in summary.channels.items()}
    assert counts[f"/objects/{tid}/pose"] == 19 and counts[f"/objects/{tid}/kinematics"] == 21
    assert counts["/objects/" + tid + "/shape"] == 19


def test_track_of_another_sequence_is_refused(tmp_path, pandaset_root, pandaset, capsys):
    import json as _json

    _write_flagged_track(tmp_path / "t", pandaset, "8ac00bad", 5, {0: ["init"]})
    doc = _json.loads((tmp_path / "t" / "track.json").read_text())
    doc["sequence"] = "some_other_sequence"
    (tmp_path / "t" / "track.json").write_text(_json.dumps(doc))
    code = main(["motion-export", str(pandaset_root), "--tracks", str(tmp_path / "t"), "--out",
                 str(tmp_path / "m.mcap"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "some_other_sequence" in err
    assert not (tmp_path / "m.mcap").exists()
