"""The policy the ``track`` and ``eval`` commands call (sot_apps.tracking.annotated_track_start,
sot_apps.bench.sequence_eval, sot_apps.bench.benchmark_eval.open_benchmark): typed library functions, the CLI
only parses arguments and calls them."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sot_apps.bench.benchmark_eval import open_benchmark
from sot_apps.bench.sequence_eval import checked_overrides, resolve_presets
from sot_apps.errors import InputError
from sot_apps.io import open_sequence
from sot_apps.tracking import MIN_INIT_POINTS, annotated_track_start
from tracker import DETECTION_PRESETS, get_preset, points_in_box, preset_names

REAL_LISTS = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "readers" / "lidar_sot_benchmark"


@pytest.fixture(scope="module")
def pandaset_seq(pandaset_root):
    return open_sequence(pandaset_root)


def _raw_points(seq, k: int, box) -> int:
    """Every LiDAR point in the box, ground included: an upper bound of what the tracker counts."""
    return int(points_in_box(seq.lidar_frame(k).points_world()[:, :3], box).sum())


def test_an_annotated_track_starts_at_its_first_annotated_box_by_default(pandaset_seq):
    start = annotated_track_start(pandaset_seq, "8ac00bad", get_preset("full"))
    truth = pandaset_seq.tracks()[start.object_id]
    assert start.object_id.startswith("8ac00bad") and start.label == truth.label == "Car"
    assert (start.start, start.end) == (truth.frames[0], truth.frames[-1])
    assert start.init_box == truth.box_at(truth.frames[0])
    assert _raw_points(pandaset_seq, start.start, start.init_box) >= MIN_INIT_POINTS


def test_an_annotated_track_whose_first_boxes_are_empty_starts_where_points_are(pandaset_seq):
    """58fd2949 is annotated from frame 0 but its box holds no LiDAR point before frame 4 (4 points, ground
    included, at frame 4): tracking starts at the first box with enough points, as the pipeline does."""
    start = annotated_track_start(pandaset_seq, "58fd2949", get_preset("full"))
    truth = pandaset_seq.tracks()[start.object_id]
    assert truth.frames[0] == 0 and start.start > 0
    assert all(_raw_points(pandaset_seq, k, truth.box_at(k)) < MIN_INIT_POINTS for k in range(start.start))
    assert start.init_box == truth.box_at(start.start)
    # a start frame asked for is taken as it is (the box there may be empty: tracking flags it)
    given = annotated_track_start(pandaset_seq, "58fd2949", get_preset("full"), start=1, end=6)
    assert (given.start, given.end, given.init_box) == (1, 6, truth.box_at(1))


@pytest.mark.parametrize("start, end, message", [(99, None, "start frame 99 is out of range"),
                                                 (5, 3, "end frame 3 is out of range"),
                                                 (None, 80, "end frame 80 is out of range")])
def test_a_start_out_of_range_is_an_input_error(pandaset_seq, start, end, message):
    with pytest.raises(InputError, match=message):
        annotated_track_start(pandaset_seq, "8ac00bad", get_preset("full"), start, end)
    with pytest.raises(InputError, match="zzzz"):
        annotated_track_start(pandaset_seq, "zzzz", get_preset("full"))


def test_preset_names_resolve_with_all_expanded():
    online = [p for p in preset_names() if p not in DETECTION_PRESETS]
    assert resolve_presets(None) == ["full"]
    assert resolve_presets(["all"]) == online
    assert resolve_presets(["faithful", "all", "faithful"])[0] == "faithful"
    assert len(resolve_presets(["faithful", "all"])) == len(online)       # each name once
    assert resolve_presets(["all"], with_detections=True) == list(preset_names())
    with pytest.raises(InputError, match="unknown preset 'nope'"):
        resolve_presets(["nope"])
    det = sorted(DETECTION_PRESETS)[0]
    with pytest.raises(InputError, match="needs detections"):
        resolve_presets([det])


def test_overrides_are_typed_and_checked_against_every_preset():
    assert checked_overrides(["motion.alpha=0.6", "shape.enabled=false"], ["full", "faithful"]) == {
        "motion.alpha": 0.6, "shape.enabled": False}
    assert checked_overrides([], ["full"]) == {}
    with pytest.raises(InputError, match="--set"):
        checked_overrides(["motion.no_such_field=1"], ["full"])
    with pytest.raises(InputError, match="--set"):
        checked_overrides(["motion.alpha=fast"], ["full"])


def test_open_benchmark_reads_the_list_and_resolves_beside_it(tmp_path):
    entries = [{"id": f"t{i}", "type": 1, "segment_name": f"seg{i}", "frame_range": [0, 9]} for i in range(3)]
    listing = tmp_path / "list.json"
    listing.write_text(json.dumps(entries))
    (tmp_path / "seg1").mkdir()
    bench = open_benchmark(str(listing))
    assert bench.source == listing and [t.id for t in bench.tracklets] == ["t0", "t1", "t2"]
    assert bench.resolve(bench.tracklets[1]) == tmp_path / "seg1"           # a sequence beside the list
    with pytest.raises(InputError, match="no DATA_DIR"):
        bench.resolve(bench.tracklets[0])
    assert [t.id for t in open_benchmark(str(listing), first=2).tracklets] == ["t0", "t1"]
    with pytest.raises(InputError, match="--first must be >= 1"):
        open_benchmark(str(listing), first=0)


def test_open_benchmark_lidar_sot_needs_its_lists_and_data_dir(tmp_path):
    with pytest.raises(InputError, match="needs --lists DIR"):
        open_benchmark("lidar-sot", data_dir=tmp_path)
    with pytest.raises(InputError, match="needs --lists DIR"):
        open_benchmark("lidar-sot", lists=REAL_LISTS / "vehicle")
    bench = open_benchmark("lidar-sot", lists=REAL_LISTS / "vehicle", data_dir=tmp_path, first=5)
    assert bench.source == REAL_LISTS / "vehicle" and len(bench.tracklets) == 5
