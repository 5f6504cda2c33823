"""``--detections`` on track / eval / run, and the detect command, on the tiny synthetic sequence."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sot_apps.cli.main import main
from sot_apps.io import open_sequence
from sot_apps.io.detections import write_detections
from tracker.detection import FrameDetections


@pytest.fixture
def dets_file(tiny_dir, tmp_path):
    """Detections = the tiny sequence's ground-truth boxes (score 0.9)."""
    seq = open_sequence(tiny_dir)
    dets = {k: FrameDetections(np.array([a.box.to_array() for a in anns]), np.full(len(anns), 0.9))
            for k, anns in enumerate(seq.annotations)}
    return write_detections(tmp_path / "dets.json", dets, seq.id)


def test_track_with_detections_det_sot_and_det(tiny_dir, dets_file, tmp_path, capsys):
    for preset in ("det_sot", "det"):
        out = tmp_path / preset
        assert main(["track", str(tiny_dir), "--track-id", "car-move", "--preset", preset, "--detections",
                     str(dets_file), "--out", str(out), "--quiet"]) == 0
        doc = json.loads((out / "track.json").read_text())
        assert sum("det" in f["flags"] for f in doc["frames"]) >= len(doc["frames"]) - 2
    # a detection preset without detections is an input error (exit 2, one line)
    assert main(["track", str(tiny_dir), "--track-id", "car-move", "--preset", "det", "--out", str(tmp_path / "x")]) == 2
    assert "needs --detections" in capsys.readouterr().err


def test_eval_rows_with_detections(tiny_dir, dets_file, capsys):
    assert main(["eval", str(tiny_dir), "--tracks", "car-move", "--preset", "det", "det_sot",
                 "--detections", str(dets_file), "--no-per-track"]) == 0
    out = capsys.readouterr().out
    assert "det_sot" in out and "\ndet " in out


def test_run_pipeline_with_detections(tiny_dir, dets_file, tmp_path):
    pipeline = {"version": 1, "out": str(tmp_path / "out"),
                "sequences": [{"path": str(tiny_dir), "objects": {"from": "annotations", "track_ids": ["car-move"]}}],
                "stages": {"track": {"preset": "det_sot"}, "bank": {"enabled": False}, "motion": {"enabled": False},
                           "flow": {"enabled": False}, "scans": {"enabled": False}}}
    (tmp_path / "p.json").write_text(json.dumps(pipeline))
    assert main(["run", str(tmp_path / "p.json"), "--quiet"]) == 2            # det_sot without detections
    assert main(["run", str(tmp_path / "p.json"), "--detections", str(dets_file), "--quiet"]) == 0
    track = next((tmp_path / "out").rglob("track.json"))
    assert any("det" in f["flags"] for f in json.loads(track.read_text())["frames"])


def test_detect_simulated_and_evaluate(tiny_dir, tmp_path, capsys):
    assert main(["detect", str(tiny_dir), "--simulate", "clean", "--out", str(tmp_path / "sim.json"), "--evaluate"]) == 0
    out = capsys.readouterr().out
    assert "| BEV @ 0.7 |" in out
    # clean simulated detections are the ground truth: AP 100 wherever there is ground truth
    row = next(line for line in out.splitlines() if line.startswith("| BEV @ 0.7"))
    assert all(cell.strip().startswith(("100.0", "—")) for cell in row.split("|")[2:-1])


def test_detect_frames_and_operating_point(tiny_dir, tmp_path, capsys):
    n = len(open_sequence(tiny_dir))
    assert main(["detect", str(tiny_dir), "--simulate", "clean", "--frames", f"0:{n}:2", "--out",
                 str(tmp_path / "sim.json"), "--evaluate"]) == 0
    out = capsys.readouterr().out
    assert "precision 1.00" in out                       # clean detections are the ground truth
    frames = [f["frame"] for f in json.loads((tmp_path / "sim.json").read_text())["frames"]]
    assert frames and all(k % 2 == 0 for k in frames)
    assert main(["detect", str(tiny_dir), "--simulate", "clean", "--frames", f"{n + 5}", "--evaluate"]) == 2
    with pytest.raises(SystemExit) as bad:          # argparse: one line, exit 2
        main(["detect", str(tiny_dir), "--simulate", "clean", "--frames", "a:b", "--evaluate"])
    assert bad.value.code == 2
