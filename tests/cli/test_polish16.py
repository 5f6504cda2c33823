"""Issue 16, defect 9: progress, messages, help examples, exit codes, accepted nonsense."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from sot_apps.cli.main import build_parser, main


def _subparser(*names):
    parser = build_parser()
    for name in names:
        parser = parser._subparsers._group_actions[0].choices[name]
    return parser


@pytest.mark.parametrize("path", [("bank", "build"), ("bank", "list"), ("sensor", "fit")])
def test_nested_subcommands_take_debug_and_show_examples(path, tmp_path, capsys):
    assert "Examples:" in _subparser(*path).format_help()
    argv = {"build": ["bank", "build", str(tmp_path / "missing_track"), "--out", str(tmp_path / "b")],
            "list": ["bank", "list", str(tmp_path / "no_bank")],
            "fit": ["sensor", "fit", str(tmp_path / "no_seq"), "--out", str(tmp_path / "s.json")]}[path[1]]
    code = main(argv + ["--debug"])
    err = capsys.readouterr().err
    assert code == 2 and "unrecognized arguments" not in err and "Traceback" in err


def test_help_examples_chain():
    """The track example writes where the flow, motion-export and bank examples read; convert's example
    output is what the other examples open."""
    track = _subparser("track").format_help()
    assert "--out out/tracks/8ac00bad" in track
    for path in (("flow",), ("motion-export",), ("bank",)):
        text = _subparser(*path).format_help()
        assert "out/track/" not in text, path
    canonical = [p for p in ("out/pandaset_002",) if p in _subparser("convert").format_help()]
    for name in ("info", "track", "flow", "motion-export", "sensor", "simulate-lidar"):
        text = _subparser(name).format_help()
        assert "pandaset_002_canonical" not in text, name
    assert canonical


def test_demo_and_run_share_one_exit_code_rule():
    from sot_apps.pipeline.runner import PipelineResult, UnitRecord

    text = " ".join(_subparser("demo").format_help().split())
    assert "Exit code 1 when any unit failed" in text
    plan = type("P", (), {"objects": [type("O", (), {"key": "s/a", "annotated": ((0, None),)})(),
                                      type("O", (), {"key": "s/b", "annotated": ()})()]})()
    no_points = UnitRecord("track", "track/s/a", "s", "a", "failed",
                           error="TrackingFailed: s/a: fewer than 5 LiDAR points in every annotated box")
    broken = UnitRecord("flow", "flow/s/cam", "s", None, "failed", error="ValueError: boom")
    box_in_empty_space = UnitRecord("track", "track/s/b", "s", "b", "failed", error="TrackingFailed: s/b: 0 LiDAR points")
    result = lambda units: PipelineResult(None, plan, units, 0.0, None, None)  # noqa: E731
    assert result([no_points]).exit_code() == 0
    assert result([no_points, broken]).exit_code() == 1
    assert result([box_in_empty_space]).exit_code() == 1


def test_random_bytes_npz_does_not_suggest_allow_pickle(tmp_path, tiny_copy, capsys):
    bad = sorted((tiny_copy / "points").glob("*.npz"))[0]
    bad.write_bytes(np.random.default_rng(0).bytes(4096))
    code = main(["track", str(tiny_copy), "--init-box", "10,0,0.8,0,4,2,1.5", "--quiet", "--out", str(tmp_path / "t")])
    err = capsys.readouterr().err
    assert code == 2 and bad.name in err and "pickle" not in err and "not an npz" in err


def test_invalid_flags_must_be_tracker_flags(tmp_path, pandaset_root, capsys):
    code = main(["motion-export", str(pandaset_root), "--tracks", str(tmp_path), "--invalid-flags", "bogus",
                 "--out", str(tmp_path / "m.mcap")])
    err = capsys.readouterr().err
    assert code == 2 and "bogus" in err and "no_points" in err


def test_bank_build_that_adds_nothing_is_an_error(tmp_path, pandaset_root, capsys):
    code = main(["bank", "build", "--from-annotations", str(pandaset_root), "--track-id", "8ac00bad",
                 "--min-points", "1000000000", "--out", str(tmp_path / "bank")])
    err = capsys.readouterr().err
    assert code == 2 and "no entry" in err
    assert not (tmp_path / "bank" / "index.json").exists()


def test_overlapping_objects_in_a_scene_file_are_refused(tmp_path, capsys):
    from sot_apps.objects.bank import Bank, entry_from_mesh_file, write_bank_index

    mesh = tmp_path / "car.ply"
    trimesh.creation.box(extents=(4.0, 2.0, 1.6)).export(mesh)
    bank = Bank(tmp_path / "bank")
    entry = entry_from_mesh_file(bank.root, mesh, label="Car")
    bank.upsert(entry)
    write_bank_index(bank)
    scene = {"version": 1, "sensor": "vlp16", "ground_z": -1.8, "objects": [
        {"bank_id": entry.id, "x": 10.0, "y": 0.0, "heading": 0.0},
        {"bank_id": entry.id, "x": 12.0, "y": 0.5, "heading": 0.3}]}
    (tmp_path / "scene.json").write_text(json.dumps(scene))
    code = main(["simulate-lidar", "--bank", str(bank.root), "--scene", str(tmp_path / "scene.json"),
                 "--out", str(tmp_path / "sim")])
    err = capsys.readouterr().err
    assert code == 2 and "scene.json" in err and "overlap" in err and "0" in err and "1" in err


def test_writing_bar_reaches_100_percent_with_cameras(tmp_path, capsys):
    from sot_apps.synth import write_world

    write_world(tmp_path / "w", frames=2, vehicles=1, sensor="vlp16", seed=0, cameras=True, camera_size=(64, 48),
                progress=True)
    err = capsys.readouterr().err
    writing = [part for part in err.replace("\r", "\n").splitlines() if part.startswith("writing")]
    assert writing and "100%" in writing[-1]


def test_info_reports_empty_sweeps(tmp_path, tiny_copy, capsys):
    doc = json.loads((tiny_copy / "sequence.json").read_text())
    points = tiny_copy / doc["frames"][2]["points"]
    with np.load(points) as data:
        arrays = {k: data[k][:0] for k in data.files}
    np.savez(points, **arrays)
    assert main(["info", str(tiny_copy)]) == 0
    out = capsys.readouterr().out
    assert "empty: 2" in out


def test_convert_says_what_it_is_doing_before_the_long_part(tmp_path, tiny_dir, capsys):
    assert main(["convert", str(tiny_dir), "--out", str(tmp_path / "c")]) == 0
    out = capsys.readouterr().out
    assert out.startswith("reading ") and "converting" in out and "point files" in out


def test_corrupt_camera_image_is_an_error_naming_it(tmp_path, capsys):
    """Issue 16 made this a warning (the flow itself does not use the image); issue 26 item 10: a damaged camera
    image is an error naming it, as a truncated JPEG is (never drawn into the overlay)."""
    from sot_apps.synth import write_world

    world = write_world(tmp_path / "w", frames=3, vehicles=2, sensor="vlp16", seed=4, cameras=True, camera_size=(96, 64))
    image = sorted((world / "cameras" / "front_camera").glob("*.png"))[0]
    image.write_bytes(b"\x89PNG garbage")
    code = main(["flow", str(world), "--from-annotations", "--camera", "front_camera", "--pairs", "0:1",
                 "--box-time", "frame", "--quiet", "--vis", "--out", str(tmp_path / "F")])
    err = capsys.readouterr().err.strip()   # the overlay (vis/, asked for) is what reads the image
    assert code == 2 and err.startswith(f"error: {image}: cannot decode the camera image")



def test_sensor_fit_warns_when_the_beam_count_is_implausible(tmp_path, pandaset_root, capsys):
    """Defect 9: without --align the PandaSet pose origin is not the optical centre and the fit finds far more
    beams than the Pandar64 has (162-166); the command must say so instead of reporting the count silently."""
    out = tmp_path / "fit.json"
    assert main(["sensor", "fit", str(pandaset_root), "--frames", "0", "--compare", "pandar64", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "warning: fitted" in err and "pandar64 has 64" in err and "--align" in err, err
