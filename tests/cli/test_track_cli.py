"""``sot-apps track`` through main([...]): outputs, negative --init-box values, one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sot_apps.cli.main import main
from sot_apps.io.tracks import read_track


@pytest.mark.slow
def test_track_by_id_prefix_writes_track_and_shape(pandaset_root, tmp_path, capsys):
    out = tmp_path / "t"
    code = main(["track", str(pandaset_root), "--track-id", "8ac00bad", "--end-frame", "4", "--quiet",
                 "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    header, track = read_track(out)
    assert track.object_id.startswith("8ac00bad") and track.label == "Car"
    assert track.frames.tolist() == [0, 1, 2, 3, 4]
    assert header.config["preset"] == "full" and header.config["seed"] == 0
    assert "init" in track.flags[0] and len(track.shape_points) > 100
    # world states near the annotations (an independent reader: the csv file)
    from sot_apps.io import open_sequence
    truth = open_sequence(pandaset_root).tracks()[track.object_id]
    for frame, (x, y, _, _) in zip(track.frames, track.states, strict=True):
        box = truth.box_at(int(frame))
        assert np.hypot(x - box.x, y - box.y) < 0.5


@pytest.mark.slow
def test_offline_refinement_is_recorded_and_stays_on_the_vehicle(pandaset_root, tmp_path, capsys):
    online, offline = tmp_path / "on", tmp_path / "off"
    base = ["track", str(pandaset_root), "--track-id", "91aa5b5c", "--end-frame", "12", "--quiet"]
    assert main(base + ["--out", str(online)]) == 0, capsys.readouterr().err
    assert main(base + ["--offline", "--out", str(offline)]) == 0, capsys.readouterr().err
    on_header, on = read_track(online)
    off_header, off = read_track(offline)
    assert off_header.config["mode"] == "offline" and off_header.config["refined"] is True
    assert on_header.config["mode"] == "online"
    assert all("offline" in f for f in off.flags) and len(off.shape_points) > 50
    from sot_apps.io import open_sequence
    truth = open_sequence(pandaset_root).tracks()[off.object_id]

    def mean_error(track):
        return np.mean([np.hypot(x - truth.box_at(int(k)).x, y - truth.box_at(int(k)).y)
                        for k, (x, y, _, _) in zip(track.frames, track.states, strict=True)])

    # the refined states differ from the online ones, and stay on the annotated vehicle
    assert on.frames.tolist() == off.frames.tolist()
    assert np.abs(on.states[:, 0] - off.states[:, 0]).max() > 1e-4
    assert mean_error(off) < 0.3


@pytest.mark.slow
def test_fixed_lag_mode_is_recorded(pandaset_root, tmp_path, capsys):
    out = tmp_path / "lag"
    code = main(["track", str(pandaset_root), "--track-id", "91aa5b5c", "--end-frame", "6", "--lag", "3", "--quiet",
                 "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    header, track = read_track(out)
    assert header.config["mode"] == "lag" and header.config["lag"] == 3 and header.config["refined"] is True
    assert header.mode == "lag 3"
    assert track.frames.tolist() == list(range(7)) and all("lag3" in f for f in track.flags[1:])
    with pytest.raises(SystemExit) as usage:   # a usage error: argparse's one line, exit code 2
        main(["track", str(pandaset_root), "--track-id", "91aa5b5c", "--lag", "0", "--out", str(tmp_path / "x")])
    assert usage.value.code == 2 and "--lag" in capsys.readouterr().err


@pytest.mark.slow
def test_init_box_with_negative_first_value(pandaset_root, tmp_path, capsys):
    out = tmp_path / "neg"
    code = main(["track", str(pandaset_root), "--init-box", "-5.485,-6.114,0.427,0.7736,4.726,1.969,1.548",
                 "--end-frame", "2", "--preset", "icp_mp", "--seed", "3", "--no-deskew", "--quiet", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    doc = json.loads((out / "track.json").read_text())
    assert doc["init_box"]["x"] == -5.485 and doc["object_id"] == "custom"
    assert doc["config"]["preset"] == "icp_mp" and doc["config"]["seed"] == 3 and doc["config"]["deskew"] is False
    assert (out / "shape.ply").is_file()


@pytest.mark.parametrize("args, message", [
    (["--track-id", "zzzz"], "no annotated track id"),
    (["--track-id", "8ac00bad", "--start-frame", "99"], "out of range"),
    (["--init-box", "1,2,nan,0,4,2,1.5"], "finite"),
    (["--init-box", "1,2,3"], "7 comma-separated"),
    (["--init-box", "1,2,0,0,4,2,1.5", "--end-frame", "70"], "out of range"),
])
def test_bad_input_is_one_line_error(pandaset_root, tmp_path, capsys, args, message):
    code = main(["track", str(pandaset_root), *args, "--quiet", "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert code == 2
    assert message in err and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "x" / "track.json").exists()


def test_empty_init_box_is_flagged_not_fatal(pandaset_root, tmp_path, capsys):
    out = tmp_path / "empty"
    code = main(["track", str(pandaset_root), "--init-box", "500,500,0,0,4,2,1.5", "--end-frame", "2", "--quiet",
                 "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 0
    assert "no points" in captured.err
    _, track = read_track(out)
    assert all("no_points" in f for f in track.flags) and len(track.shape_points) == 0


def test_implausible_init_box_size_is_refused_unless_allowed(pandaset_root, tmp_path, capsys):
    """Issue 16, defect 7: a 1e6 m init box was tracked without a warning."""
    huge = "-5.49,-6.11,0.43,0.77,1e6,1e6,1e6"
    code = main(["track", str(pandaset_root), "--init-box", huge, "--end-frame", "1", "--quiet",
                 "--out", str(tmp_path / "huge")])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "road vehicle" in err and "--allow-any-size" in err
    assert not (tmp_path / "huge").exists()
    # a 0.05 m box is as implausible as a 1 km one
    assert main(["track", str(pandaset_root), "--init-box", "-5.49,-6.11,0.43,0.77,0.05,1.9,1.5", "--quiet",
                 "--out", str(tmp_path / "tiny")]) == 2
    capsys.readouterr()
    # the flag lets a deliberate oddity through (a 30 x 4 x 4.5 m load), with a warning
    code = main(["track", str(pandaset_root), "--init-box", "-5.49,-6.11,0.43,0.77,40,4,4.5", "--end-frame", "1",
                 "--quiet", "--allow-any-size", "--out", str(tmp_path / "allowed")])
    assert code == 0 and "warning" in capsys.readouterr().err


def test_pipeline_boxes_of_implausible_size_are_refused(tmp_path, pandaset_root):
    from sot_apps.errors import InputError
    from sot_apps.pipeline.config import load_config

    box = {"x": 0.0, "y": 0.0, "z": 1.0, "heading": 0.0, "length": 1e6, "width": 2.0, "height": 1.5}
    doc = {"out": "out", "sequences": [{"path": str(pandaset_root), "objects": {
        "from": "boxes", "boxes": [{"id": "huge", "frame": 0, "box": box}]}}]}
    path = tmp_path / "p.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="huge.*road vehicle"):
        load_config(path)
    doc["sequences"][0]["objects"]["boxes"][0]["allow_any_size"] = True
    path.write_text(json.dumps(doc))
    load_config(path)
