"""`sot-apps info` / `convert`: output on the real data, --help, and one-line errors with exit code 2."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sot_apps.cli.main import main
from sot_apps.io import open_sequence

SOT_APPS = shutil.which("sot-apps") or str(Path(sys.executable).with_name("sot-apps"))


def readme_moving_vehicles(root: Path) -> list[str]:
    """The uuid prefixes the data's own README lists as moving vehicle tracks."""
    text = (root / "README.md").read_text()
    section = text.split("## Moving vehicle tracks here", 1)[1]
    return re.findall(r"\b([0-9a-f]{8}) \(", section)


def run_cli(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([SOT_APPS, *args], capture_output=True, text=True, timeout=300,
                          env={**os.environ, **(env or {})})


def assert_one_line_error(stderr: str, *needles: str) -> None:
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("error: ") and "Traceback" not in stderr
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])


@pytest.mark.slow
def test_info_on_pandaset_lists_readme_moving_vehicles(pandaset_root, capsys):
    expected = readme_moving_vehicles(pandaset_root)
    assert len(expected) == 9
    assert main(["info", str(pandaset_root)]) == 0
    out = capsys.readouterr().out
    assert re.search(r"frames\s+56, time span 5\.5\d\d s", out)
    assert re.search(r"points\s+per frame: min \d{5,}, median \d+, max \d+", out)
    assert re.search(r"front_camera\s+1920x1080\s+56\s+-(49|50)\.\d", out)
    rows = {line.split()[0]: line for line in out.splitlines() if re.match(r"^  [0-9a-f]{8}  ", line)}
    for prefix in expected:
        assert prefix in rows, f"{prefix} not listed"
        assert rows[prefix].rstrip().endswith("moving"), rows[prefix]
        assert "Car" in rows[prefix]
    parked = [r for r in rows.values() if r.rstrip().endswith("parked")]
    assert len(parked) > 20  # "many parked vehicles are annotated too"


def test_info_json_and_vehicles_only_on_tiny(tiny_dir, capsys):
    assert main(["info", str(tiny_dir), "--json", "--vehicles-only"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["num_frames"] == 20 and doc["points_min"] == doc["points_max"] == 11201
    motion = {t["track_id"]: t["motion"] for t in doc["tracks"]}
    assert motion == {"car-move": "moving", "car-park": "parked"}
    disp = {t["track_id"]: t["displacement_m"] for t in doc["tracks"]}
    assert disp["car-move"] == pytest.approx(8.0 * 1.9)
    assert doc["cameras"][0]["mean_offset_to_lidar_ms"] == pytest.approx(-50.0)


def test_installed_command_on_tiny(tmp_path):
    result = run_cli("info", "--tiny", env={"XDG_CACHE_HOME": str(tmp_path / "cache")})
    assert result.returncode == 0, result.stderr
    assert "car-move" in result.stdout and "moving" in result.stdout
    assert (tmp_path / "cache" / "sot-apps").is_dir()
    assert run_cli("info").returncode == 2


@pytest.mark.parametrize("command", ["info", "convert"])
def test_help_has_example(command, capsys):
    with pytest.raises(SystemExit) as info:
        main([command, "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert "Examples:" in out and f"sot-apps {command} " in out


def test_convert_round_trip(tiny_dir, tmp_path, capsys):
    assert main(["convert", str(tiny_dir), "--out", str(tmp_path / "c")]) == 0
    assert "wrote" in capsys.readouterr().out
    a, b = open_sequence(tiny_dir), open_sequence(tmp_path / "c")
    np.testing.assert_array_equal(a.sweep(19).xyz, b.sweep(19).xyz)
    assert a.annotations == b.annotations


def _nothing_written(out: Path) -> bool:
    return not (out / "sequence.json").exists() and not list(out.rglob("*.tmp")) if out.exists() else True


# ------------------------------------------------------------------------------------- bad input

def test_truncated_npz(tiny_copy, tmp_path):
    path = tiny_copy / "points" / "000003.npz"
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 3])
    result = run_cli("info", str(tiny_copy))
    assert result.returncode == 2
    assert_one_line_error(result.stderr, str(path), "truncated")
    out = tmp_path / "out"
    result = run_cli("convert", str(tiny_copy), "--out", str(out))
    assert result.returncode == 2
    assert_one_line_error(result.stderr, str(path))
    assert _nothing_written(out)


def test_sequence_json_naming_missing_file(tiny_copy, tmp_path):
    (tiny_copy / "points" / "000011.npz").unlink()
    for args in (["info", str(tiny_copy)], ["convert", str(tiny_copy), "--out", str(tmp_path / "out")]):
        result = run_cli(*args)
        assert result.returncode == 2
        assert_one_line_error(result.stderr, "sequence.json", "frames[11].points", "000011.npz")
    assert not (tmp_path / "out").exists()


def test_nan_in_canonical_pose(tiny_copy, tmp_path):
    doc = json.loads((tiny_copy / "sequence.json").read_text())
    doc["frames"][6]["world_from_ego"][1][3] = float("nan")
    (tiny_copy / "sequence.json").write_text(json.dumps(doc))
    assert "NaN" in (tiny_copy / "sequence.json").read_text()
    for args in (["info", str(tiny_copy)], ["convert", str(tiny_copy), "--out", str(tmp_path / "out")]):
        result = run_cli(*args)
        assert result.returncode == 2
        assert_one_line_error(result.stderr, "sequence.json", "frames[6].world_from_ego[1][3]", "non-finite")
    assert not (tmp_path / "out").exists()


def test_unknown_field_in_sequence_json(tiny_copy, capsys):
    doc = json.loads((tiny_copy / "sequence.json").read_text())
    doc["frames"][0]["pose"] = [0, 0, 0]
    (tiny_copy / "sequence.json").write_text(json.dumps(doc))
    assert main(["info", str(tiny_copy)]) == 2
    assert_one_line_error(capsys.readouterr().err, "sequence.json", "frames[0].pose: unknown field")


def test_nan_in_pandaset_pose(pandaset_root, tmp_path):
    """PandaSet copy: small JSON files copied (one pose made NaN), everything else symlinked."""
    bad = tmp_path / "pandaset"
    (bad / "lidar").mkdir(parents=True)
    for path in (pandaset_root / "lidar").iterdir():
        if path.suffix != ".json":
            (bad / "lidar" / path.name).symlink_to(path)
    shutil.copy(pandaset_root / "lidar" / "timestamps.json", bad / "lidar" / "timestamps.json")
    poses = json.loads((pandaset_root / "lidar" / "poses.json").read_text())
    poses[4]["position"]["y"] = float("nan")
    (bad / "lidar" / "poses.json").write_text(json.dumps(poses))
    for name in ("annotations", "camera", "meta"):
        (bad / name).symlink_to(pandaset_root / name)
    out = tmp_path / "out"
    for args in (["info", str(bad)], ["convert", str(bad), "--out", str(out)]):
        result = run_cli(*args)
        assert result.returncode == 2
        assert_one_line_error(result.stderr, str(bad / "lidar" / "poses.json"), "frame 4", "non-finite")
    assert not out.exists()
