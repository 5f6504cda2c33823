"""Issue 26 items 9, 10 and 13: non-finite or out-of-range options and boxes are usage errors naming the option or
file (exit code 2, nothing written); the smaller defects of a newcomer's run."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sot_apps.cli.main import build_parser, main

CLI = [sys.executable, "-m", "sot_apps.cli.main"]
ROOT = Path(__file__).resolve().parents[2]   # the CLI subprocesses run this checkout's code


@pytest.fixture(scope="module")
def cam_world(tmp_path_factory) -> Path:
    """3 frames, 2 moving vehicles (veh_000, veh_001), 16-beam LiDAR, a 320x240 front camera."""
    from sot_apps.synth import write_world

    return write_world(tmp_path_factory.mktemp("trusted") / "world", frames=3, vehicles=2, sensor="vlp16", seed=4,
                       cameras=True, camera_size=(320, 240))


@pytest.fixture(scope="module")
def bank(cam_world) -> Path:
    from sot_apps.io import open_sequence
    from sot_apps.objects.bank import entries_from_annotations, read_bank, write_bank_index

    root = cam_world.parent / "bank"
    bank = read_bank(root, must_exist=False)
    for entry in entries_from_annotations(root, open_sequence(cam_world), ["veh_000", "veh_001"], min_points=20)[0]:
        bank.upsert(entry)
    write_bank_index(bank)
    return root


def _usage_error(capsys, argv: list) -> str:
    with pytest.raises(SystemExit) as info:
        main([str(a) for a in argv])
    err = capsys.readouterr().err.strip()
    assert info.value.code == 2 and len(err.splitlines()) == 1, err
    return err


# ------------------------------------------------------------------ items 9 and 10: numbers

@pytest.mark.parametrize("argv, option", [
    (["track", "{w}", "--track-id", "veh_000", "--end-frame", "-5"], "--end-frame"),
    (["benchmark", "make", "--background", "{w}", "--bank", "{b}", "--drop", "nan"], "--drop"),
    (["benchmark", "make", "--background", "{w}", "--bank", "{b}", "--drop", "2"], "--drop"),
    (["benchmark", "make", "--background", "{w}", "--bank", "{b}", "--frames", "5:2"], "--frames"),
    (["benchmark", "make", "--background", "{w}", "--bank", "{b}", "--range", "5:inf"], "--range"),
    (["simulate-lidar", "--bank", "{b}", "--random", "1", "--ground-z", "nan"], "--ground-z"),
    (["simulate-lidar", "--bank", "{b}", "--random", "1", "--extent", "nan"], "--extent"),
    (["simulate-lidar", "--bank", "{b}", "--random", "1", "--extent", "-5"], "--extent"),
    (["flow", "{w}", "--from-annotations", "--camera", "front_camera", "--dilate-px", "-4"], "--dilate-px"),
    (["eval", "{w}", "--tracks", "veh_000", "--seeds", "0"], "--seeds"),
    (["sensor", "fit", "{w}", "--min-separation", "inf"], "--min-separation"),
])
def test_non_finite_or_out_of_range_options_are_usage_errors(argv, option, cam_world, bank, tmp_path, capsys):
    out = tmp_path / "out"
    argv = [a.format(w=cam_world, b=bank) for a in argv]
    if argv[0] != "eval" and argv[:2] != ["sensor", "fit"]:
        argv += ["--out", str(out)]
    err = _usage_error(capsys, argv)
    assert f"argument {option}" in err
    assert not out.exists()


def test_absurd_boxes_are_refused_naming_the_option_or_file(cam_world, bank, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["track", str(cam_world), "--init-box", "1e300,0,0,0,4.5,1.8,1.5", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.startswith("error: --init-box") and "coordinate bound" in err and not out.exists()
    for x in ("1e12", "NaN"):
        scene = tmp_path / f"scene_{x}.json"
        scene.write_text('{"version": 1, "sensor": "vlp16", "ground_z": -1.8, "objects": [{"bank_id": "%s", '
                         '"x": %s, "y": 0, "z": null, "heading": 0}]}' % (json.loads((bank / "index.json")
                                                                                     .read_text())["entries"][0]["id"], x))
        code = main(["simulate-lidar", "--bank", str(bank), "--scene", str(scene), "--out", str(out)])
        err = capsys.readouterr().err.strip()
        assert code == 2 and err.startswith(f"error: {scene}: object") and "error: error" not in err, err
        assert not out.exists()


def test_a_sequence_box_beyond_the_coordinate_bound_is_refused(cam_world, tmp_path, capsys):
    seq = Path(shutil.copytree(cam_world, tmp_path / "w"))
    doc = json.loads((seq / "sequence.json").read_text())
    box = next(f for f in doc["frames"] if f.get("boxes"))["boxes"][0]
    box["x"] = 1e300 if "x" in box else box.setdefault("center", [1e300, 0, 0])
    if "center" in box:
        box["center"][0] = 1e300
    (seq / "sequence.json").write_text(json.dumps(doc))
    assert main(["info", str(seq), "--no-point-stats"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"error: {seq}: frame ") and "coordinate bound" in err and "inf" not in err


def test_a_truncated_camera_image_is_an_error_naming_it(cam_world, tmp_path, capsys):
    import cv2

    seq = Path(shutil.copytree(cam_world, tmp_path / "w"))
    image = next((seq / "cameras").rglob("000000.*"))
    ok, data = cv2.imencode(".jpg", cv2.imread(str(image)))
    image.write_bytes(data.tobytes()[: len(data) // 2])   # a JPEG cut in the middle (OpenCV decodes it: grey rows)
    code = main(["flow", str(seq), "--from-annotations", "--camera", "front_camera", "--quiet", "--vis",
                 "--out", str(tmp_path / "flow")])   # the pictures (vis/) are what reads the image
    err = capsys.readouterr().err.strip()
    assert code == 2 and err == f"error: {image}: truncated JPEG ({len(data) // 2} bytes, no end-of-image marker): " \
                                "the camera image is damaged"
    assert not list((tmp_path / "flow").rglob("*overlay*"))


# ------------------------------------------------------------------ item 13: the smaller defects

@pytest.mark.parametrize("action", ["make", "build", "realism"])
def test_benchmark_actions_have_a_description_and_examples(action):
    parser = build_parser()._subparsers._group_actions[0].choices["benchmark"]
    text = parser._subparsers._group_actions[0].choices[action].format_help()
    assert "Examples:" in text and f"sot-apps benchmark {action} " in text
    assert len(text.split("options:")[0].split("\n\n")[1]) > 150   # a paragraph, not the usage line only


def test_demo_help_states_the_exit_rule_once():
    text = build_parser()._subparsers._group_actions[0].choices["demo"].format_help()
    assert text.count("Exit code 1 when any unit failed") == 1 and "Exit code: as sot-apps run" not in text


def test_sensor_fit_without_out_prints_the_fit_and_writes_nothing(cam_world, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["sensor", "fit", str(cam_world), "--frames", "0,1"]) == 0
    out = capsys.readouterr().out
    assert "beams" in out and "not written (give --out" in out and os.listdir(tmp_path) == []


def test_detect_writes_given_detections_to_out(cam_world, tmp_path, capsys):
    first, second = tmp_path / "d.json", tmp_path / "g.json"
    assert main(["detect", str(cam_world), "--simulate", "clean", "--out", str(first)]) == 0
    assert main(["detect", str(cam_world), "--detections", str(first), "--out", str(second)]) == 0
    assert f"read from --detections {first}" in capsys.readouterr().out
    a, b = json.loads(first.read_text()), json.loads(second.read_text())
    assert a["frames"] == b["frames"]


def test_benchmark_build_with_no_qualifying_tracklet_exits_2(cam_world, tmp_path, capsys):
    out = tmp_path / "lists"
    assert main(["benchmark", "build", str(cam_world), "--min-frames", "50", "--quiet", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "no tracklet" in err and "--min-frames 50" in err and not out.exists()


def test_flow_shape_frames_out_of_range_is_a_range_error(cam_world, tmp_path, capsys):
    assert main(["flow", str(cam_world), "--from-annotations", "--camera", "front_camera", "--shape-frames",
                 "500:900", "--out", str(tmp_path / "f")]) == 2
    err = capsys.readouterr().err.strip()
    assert "--shape-frames 500:900 is out of range" in err and "frames 0..2" in err


def test_a_directory_in_place_of_a_points_file_is_named_as_such(cam_world, tmp_path, capsys):
    seq = Path(shutil.copytree(cam_world, tmp_path / "w"))
    points = sorted((seq / "points").iterdir())[1]
    points.unlink()
    points.mkdir()
    assert main(["info", str(seq)]) == 2
    assert "is a directory, not a file" in capsys.readouterr().err


def test_pandaset_frame_with_only_a_native_pickle_is_read(pandaset_root, tmp_path):
    """A PandaSet folder whose lidar/ holds NN.npz copies and, for one frame, only the native NN.pkl.gz."""
    import pandas as pd

    from sot_apps.io import open_sequence

    root = tmp_path / "pandaset"
    (root / "lidar").mkdir(parents=True)
    for name in ("poses.json", "timestamps.json"):
        shutil.copy(pandaset_root / "lidar" / name, root / "lidar" / name)
    for k in (0, 2):
        shutil.copy(pandaset_root / "lidar" / f"{k:02d}.npz", root / "lidar" / f"{k:02d}.npz")
    with np.load(pandaset_root / "lidar" / "01.npz") as arrays:
        pd.DataFrame({name: arrays[name] for name in arrays.files}).to_pickle(root / "lidar" / "01.pkl.gz")
    copy, original = open_sequence(root), open_sequence(pandaset_root)
    assert len(copy) == 3 and copy.missing_sweeps() == []
    np.testing.assert_array_equal(copy.sweep(1).xyz, original.sweep(1).xyz)


def test_benchmark_make_shows_progress_when_stderr_is_not_a_terminal(cam_world, bank, tmp_path):
    done = subprocess.run([*CLI, "benchmark", "make", "--background", str(cam_world), "--bank", str(bank),
                           "--frames", "0:3", "--tracklets", "1", "--per-copy", "1", "--sensor", "vlp16", "--range",
                           "5:30", "--bands", "15", "--out", str(tmp_path / "b")],
                          capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert "copies: 100%" in done.stderr.replace("\r", "\n")
