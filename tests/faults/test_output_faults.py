"""Issue 16 defect 2: an unwritable output or a full disk gives one line naming the final output path and the
cause, exit code 2, and nothing half-written, for every writer of the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from .conftest import left_files, message_lines, run_cli


@pytest.fixture(scope="session")
def inputs(world, tmp_path_factory) -> dict[str, Path]:
    """A track directory, a vehicle bank and a pipeline file made from the tiny world (written once)."""
    root = tmp_path_factory.mktemp("fault_inputs")
    track = root / "track"
    bank = root / "bank"
    for args in (["track", world, "--track-id", "veh_000", "--out", track],
                 ["bank", "build", track, "--out", bank]):
        done = run_cli(args)
        assert done.returncode == 0, done.stderr
    pipeline = root / "pipeline.json"
    pipeline.write_text(json.dumps({"version": 1, "out": str(root / "unused"),
                                    "sequences": [{"path": str(world), "objects": {"from": "annotations",
                                                                                   "track_ids": ["veh_000"]}}],
                                    "stages": {"bank": {"min_points": 0}, "flow": {"enabled": False},
                                               "scans": {"enabled": False}}}))
    return {"track": track, "bank": bank, "pipeline": pipeline}


# name -> (argv for an output location T, the final output path the error names)
WRITERS = {
    "motion-export mcap": lambda w, i, t: (["motion-export", w, "--from-annotations", "--with-points", "--quiet",
                                            "--out", t / "m.mcap"], t / "m.mcap"),
    "motion-export parquet": lambda w, i, t: (["motion-export", w, "--from-annotations", "--quiet",
                                               "--out", i["ok"] / "m.mcap", "--parquet", t / "m.parquet"], t / "m.parquet"),
    "motion-export npz": lambda w, i, t: (["motion-export", w, "--from-annotations", "--quiet",
                                           "--out", i["ok"] / "m.mcap", "--npz", t / "m.npz"], t / "m.npz"),
    "motion-export csv": lambda w, i, t: (["motion-export", w, "--from-annotations", "--quiet",
                                           "--out", i["ok"] / "m.mcap", "--csv", t / "m.csv"], t / "m.csv"),
    "flow": lambda w, i, t: (["flow", w, "--from-annotations", "--camera", "front_camera", "--quiet",
                              "--out", t / "flow"], t / "flow"),
    "track": lambda w, i, t: (["track", w, "--track-id", "veh_000", "--out", t / "track"], t / "track"),
    "convert": lambda w, i, t: (["convert", w, "--out", t / "conv"], t / "conv"),
    "synth": lambda w, i, t: (["synth", "--frames", "2", "--vehicles", "1", "--sensor", "vlp16",
                               "--out", t / "world"], t / "world"),
    "simulate-lidar": lambda w, i, t: (["simulate-lidar", "--bank", i["bank"], "--random", "1", "--sensor", "vlp16",
                                        "--out", t / "sim"], t / "sim"),
    "eval --json": lambda w, i, t: (["eval", w, "--tracks", "veh_000", "--json", t / "e.json"], t / "e.json"),
    "bank build": lambda w, i, t: (["bank", "build", i["track"], "--out", t / "bank"], t / "bank"),
    "bench --json": lambda w, i, t: (["bench", "motion", w, "--from-annotations", "--ids", "veh_000", "--json", t / "b.json"], t / "b.json"),
    "sensor fit": lambda w, i, t: (["sensor", "fit", w, "--frames", "0,1", "--out", t / "s.json"], t / "s.json"),
    "run": lambda w, i, t: (["run", i["pipeline"], "--quiet", "--out", t / "run"], t / "run"),
}


def _check_one_line(done, target: Path, cause: str) -> str:
    lines = message_lines(done.stderr)
    assert done.returncode == 2, (done.returncode, done.stderr[-2000:])
    assert len(lines) == 1, done.stderr[-3000:]
    line = lines[0]
    assert line.startswith("error: ") and cause in line, line
    assert str(target) in line, f"{line!r} does not name {target}"
    assert ".tmp" not in line and "Traceback" not in done.stderr, line
    return line


@pytest.mark.parametrize("writer", sorted(WRITERS))
def test_unwritable_output_fails_first_with_one_line(writer, world, inputs, readonly_dir, tmp_path):
    ok = tmp_path / "ok"
    argv, target = WRITERS[writer](world, {**inputs, "ok": ok}, readonly_dir)
    done = run_cli(argv)
    _check_one_line(done, target, "Read-only file system")
    # checked before any work: nothing printed, no other output written (e.g. the .mcap beside an unwritable --csv)
    assert done.stdout == ""
    assert not ok.exists(), sorted(ok.rglob("*"))


@pytest.mark.parametrize("writer", sorted(WRITERS))
def test_full_disk_fails_with_one_line_and_no_partial_file(writer, world, inputs, full_disk, tmp_path):
    ok = tmp_path / "ok"
    argv, target = WRITERS[writer](world, {**inputs, "ok": ok}, full_disk)
    done = run_cli(argv)
    line = _check_one_line(done, target if target.suffix else full_disk, "No space left on device")
    # no temporary file, and a single-file output does not exist at all
    left = left_files(full_disk)
    assert not [p for p in left if p.endswith(".tmp")], left
    if target.suffix:
        assert not target.exists(), line


def test_output_path_is_a_directory(world, tmp_path):
    (tmp_path / "m.csv").mkdir()
    done = run_cli(["motion-export", world, "--from-annotations", "--quiet", "--out", tmp_path / "m.mcap",
                    "--csv", tmp_path / "m.csv"])
    _check_one_line(done, tmp_path / "m.csv", "Is a directory")
    assert not (tmp_path / "m.mcap").exists()


def test_output_parent_is_a_file(world, tmp_path):
    (tmp_path / "file").write_text("x")
    done = run_cli(["eval", world, "--tracks", "veh_000", "--json", tmp_path / "file" / "e.json"])
    _check_one_line(done, tmp_path / "file" / "e.json", "Not a directory")
    assert done.stdout == ""
