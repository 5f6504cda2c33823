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
