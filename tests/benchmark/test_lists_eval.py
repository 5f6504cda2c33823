"""Tracklet lists (LiDAR-SOT's real ones, built ones, generated ones) and ``sot-apps eval --benchmark``."""

from __future__ import annotations

import json
import sys
import types
from pathlib import Path

import pytest

from sot_apps.benchmark.lists import ListCriteria, build_lists, read_list, read_lists
from sot_apps.cli.main import main
from sot_apps.errors import InputError
from sot_apps.io import open_sequence
from sot_apps.schemas import validate

REAL_LISTS = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "readers" / "lidar_sot_benchmark"


def test_real_lidar_sot_lists_parse_with_the_papers_counts():
    folder = REAL_LISTS / "vehicle"
    tracklets = read_lists(folder)
    assert len(tracklets) == 1121
    counts = {level: sum(t.difficulty == level for t in tracklets) for level in ("easy", "medium", "hard")}
    assert counts == {"easy": 374, "medium": 374, "hard": 373}
    assert len(read_list(folder / "easy.json")) == 374
    assert all(t.type == 1 and 100 <= t.frame_range[1] - t.frame_range[0] + 1 <= 200 for t in tracklets)
    assert all(t.segment_name.startswith("segment-") for t in tracklets)


def test_a_bad_list_is_one_input_error(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps([{"id": "a", "type": 1, "segment_name": "s", "frame_range": [5]}]))
    with pytest.raises(InputError) as err:
        read_list(path)
    assert "bad.json" in str(err.value)


def test_build_lists_applies_the_papers_criteria(background, tmp_path):
    seq = open_sequence(background)
    entries = build_lists([(seq, "../world")], ListCriteria(min_frames=5))
    validate("benchmark", entries, None)
    moving = {tid for tid in seq.tracks() if tid.startswith("veh_")}
    assert {e["id"] for e in entries} <= moving and entries  # parked cars are static throughout: never listed
    assert not build_lists([(seq, "x")], ListCriteria(min_frames=7))  # longer than the sequence
    assert not build_lists([(seq, "x")], ListCriteria(min_frames=5, min_points=10 ** 6))
    out = tmp_path / "lists"
    assert main(["benchmark", "build", str(background), "--min-frames", "5", "--out", str(out)]) == 0
    built = read_lists(out)
    assert [t.id for t in built] == [e["id"] for e in entries]
    assert all((out / t.sequence).resolve() == background.resolve() for t in built)


def test_eval_lidar_sot_resolves_waymo_segments_through_the_reader(background, tmp_path, monkeypatch, capsys):
    """The real protocol with the Waymo reader replaced by a resolver to a canonical sequence."""
    seq = open_sequence(background)
    tid = sorted(t for t in seq.tracks() if t.startswith("veh_"))[0]
    lists = tmp_path / "vehicle"
    lists.mkdir()
    entry = {"id": tid, "type": 1, "segment_name": "segment-fake_with_camera_labels", "frame_range": [1, 5]}
    for name in ("bench_list.json", "medium.json"):
        (lists / name).write_text(json.dumps([entry]))
    (lists / "easy.json").write_text("[]")
    (lists / "hard.json").write_text("[]")
    asked = []
    fake = types.ModuleType("sot_apps.io.waymo")
    fake.find_waymo_segment = lambda data_dir, name: asked.append((Path(data_dir), name)) or background
    monkeypatch.setitem(sys.modules, "sot_apps.io.waymo", fake)
    data_dir = tmp_path / "waymo"
    assert main(["eval", "--benchmark", "lidar-sot", "--lists", str(lists), str(data_dir), "--preset", "full"]) == 0
    assert asked == [(data_dir, "segment-fake_with_camera_labels")]
    out = capsys.readouterr().out
    assert "medium" in out and "1 tracklets" in out
    assert main(["eval", "--benchmark", "lidar-sot", "--preset", "full"]) == 2  # needs --lists and DATA_DIR


def test_eval_benchmark_prints_difficulty_and_profile_rows(small_benchmark, capsys, tmp_path):
    report = tmp_path / "report.json"
    assert main(["eval", "--benchmark", str(small_benchmark / "benchmark.json"), "--preset", "full",
                 "--json", str(report)]) == 0
    out = capsys.readouterr().out
    for profile in ("hard_brake", "u_turn", "occluded", "lane_change"):
        assert f"profile {profile}" in out
    doc = json.loads(report.read_text())
    table = doc["tables"]["full"]
    assert table["all"]["n"] == 8
    assert sum(table[d]["n"] for d in ("easy", "medium", "hard") if d in table) == 8
    assert 0.0 <= table["all"]["acc"] <= 1.0


def test_eval_benchmark_with_simulated_detections_and_set(small_benchmark, capsys, tmp_path):
    """The benchmark's exact ground truth gives simulated detections; clean ones make the Det row exact, and
    ``--set`` replaces a tracker setting in every preset (reported in the title)."""
    listing = str(small_benchmark / "benchmark.json")
    report = tmp_path / "det.json"
    assert main(["eval", "--benchmark", listing, "--first", "2", "--preset", "det", "--simulate-detections", "clean",
                 "--json", str(report)]) == 0
    assert json.loads(report.read_text())["tables"]["det"]["all"]["acc"] > 0.85
    capsys.readouterr()
    assert main(["eval", "--benchmark", listing, "--first", "2", "--preset", "det_sot", "--simulate-detections",
                 "learned", "--set", "detection.weight=0.1", "--set", "detection.min_iou=0.2"]) == 0
    assert "set detection.weight=0.1 detection.min_iou=0.2" in capsys.readouterr().out
    assert main(["eval", "--benchmark", listing, "--preset", "det"]) == 2  # a detection preset needs detections
    assert main(["eval", "--benchmark", listing, "--set", "detection.weightt=0.1"]) == 2
    assert "detection.weightt: unknown tracker setting; did you mean detection.weight" in capsys.readouterr().err
    assert main(["eval", "--benchmark", listing, "--set", "search.max_points=many"]) == 2
    assert "search.max_points: expected an integer, got 'many'" in capsys.readouterr().err


def test_eval_benchmark_adds_fixed_lag_and_offline_rows(small_benchmark, capsys, tmp_path):
    """--lag and --offline on a tracklet list give a row each per preset, as on a sequence (they were ignored)."""
    report = tmp_path / "modes.json"
    assert main(["eval", "--benchmark", str(small_benchmark / "benchmark.json"), "--first", "2", "--preset", "full",
                 "--lag", "3", "--offline", "--json", str(report)]) == 0
    out = capsys.readouterr().out
    for row in ("preset full ", "preset full+lag3 ", "preset full+offline "):
        assert row in out
    doc = json.loads(report.read_text())
    assert doc["presets"] == ["full", "full+lag3", "full+offline"]
    online, lag, offline = (doc["tables"][r]["all"] for r in doc["presets"])
    assert online["n"] == lag["n"] == offline["n"] == 2
    # each fixed-lag frame pays the online step and the window solve; the offline row adds its refinement
    assert lag["ms"] > online["ms"] and offline["ms"] > online["ms"]
    assert (lag["acc"], offline["acc"]) != (online["acc"], online["acc"])  # the states were refined
