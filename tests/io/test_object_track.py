"""ObjectTrack, the one per-object time series of sot_apps: rows, columns and the track-file conversion."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sot_apps.io.object_track import ObjectTrack
from sot_apps.io.ply import write_ply_points
from sot_apps.io.tracks import TrackHeader, read_track, write_track
from tracker.geometry import Box


def test_boxes_by_frame_come_back_exactly_in_frame_order_with_their_tilt():
    level, tilted = Box(1.0, 2.0, 0.5, 0.3, 4.5, 1.9, 1.6), Box(3.0, 2.5, 0.6, 0.4, 4.5, 1.9, 1.6, 0.02, -0.05)
    track = ObjectTrack.from_boxes("car", "Car", {7: tilted, 3: level}, scores={3: 0.5, 7: 0.9},
                                   num_points={7: 120})
    assert track.frames.tolist() == [3, 7] and track.boxes.shape == (2, 9)
    assert track.box_at(3) == level and track.box_at(7) == tilted and track.box_at(5) is None
    assert track.scores.tolist() == [0.5, 0.9] and track.num_points.tolist() == [-1, 120]
    np.testing.assert_array_equal(track.tilts, [[0.0, 0.0], [0.02, -0.05]])
    assert track.size == (4.5, 1.9, 1.6) and track.valid.all() and track.flags == ((), ())
    assert ObjectTrack.from_boxes("car", "Car", {0: level}).tilts is None


def test_states_rows_with_nan_are_invalid_and_rows_must_increase():
    states = np.array([[0.0, 0.0, 0.0, 0.1], [np.nan] * 4, [2.0, 0.0, 0.0, 0.1]])
    track = ObjectTrack.from_states("a", "Car", (4.0, 2.0, 1.5), [0, 1, 2], [0, 100, 200], states, [True] * 3,
                                    [[], ["no_points"], []])
    assert track.valid.tolist() == [True, False, True]
    assert track.box(2) == Box(2.0, 0.0, 0.0, 0.1, 4.0, 2.0, 1.5)
    picked = track.select(track.valid)
    assert picked.frames.tolist() == [0, 2] and picked.timestamps_ns.tolist() == [0, 200]
    assert picked.flags == ((), ())
    with pytest.raises(ValueError, match="strictly increasing"):
        ObjectTrack.from_states("a", "Car", (4.0, 2.0, 1.5), [0, 0], [0, 100], states[:2], [True, True])
    assert track.between(1, 5).frames.tolist() == [1, 2] and track.between(1, 5).flags == (("no_points",), ())
    assert len(track.between(3, 9)) == 0
    with pytest.raises(ValueError, match="scores has 1 entries for 3 frames"):
        ObjectTrack.from_states("a", "Car", (4.0, 2.0, 1.5), [0, 1, 2], [0, 1, 2], states, [True] * 3, scores=[1.0])


def _previous_writer_doc() -> dict:
    """A track.json as the writer before ObjectTrack (TrackFile / FrameRecord.to_json) laid it out: key order, a
    label, time_ms on two of three frames, an integer in the config."""
    state = {5: (1.0, 2.0, 0.0, 0.2), 6: (1.5, 2.0, 0.0, 0.2), 7: (2.0, 2.0, 0.0, 0.25)}
    rows = [(5, 1_000, 300, 0.9, ["init"], 12.25), (6, 1_100, 0, 0.0, ["no_points", "prior_only"], None),
            (7, 1_200, 250, 0.8, ["low_points"], 3.0)]
    frames = []
    for frame, stamp, points, quality, flags, time_ms in rows:
        x, y, z, heading = state[frame]
        frames.append({"frame": frame, "timestamp_ns": stamp, "state": {"x": x, "y": y, "z": z, "heading": heading},
                       "num_points": points, "quality": quality, "flags": flags}
                      | ({} if time_ms is None else {"time_ms": time_ms}))
    return {"schema_version": 1, "sequence": "seq", "object_id": "car-1", "label": "Car",
            "size": {"length": 4.0, "width": 1.8, "height": 1.5}, "start_frame": 5, "end_frame": 7,
            "init_box": {"x": 1.0, "y": 2.0, "z": 0.0, "heading": 0.2, "length": 4.0, "width": 1.8, "height": 1.5},
            "config": {"preset": "full", "mode": "lag", "lag": 3, "refined": True}, "shape": "shape.ply",
            "frames": frames}


def test_a_track_file_of_the_previous_writer_reads_as_an_object_track_and_writes_back_byte_for_byte(tmp_path):
    doc = _previous_writer_doc()
    text = json.dumps(doc, indent=1) + "\n"     # the previous writer: write_json, indent 1, newline
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "track.json").write_text(text)
    shape = np.random.default_rng(2).normal(size=(40, 3))
    write_ply_points(tmp_path / "old" / "shape.ply", shape)
    header, track = read_track(tmp_path / "old")
    assert header == TrackHeader("seq", 5, 7, Box(1.0, 2.0, 0.0, 0.2, 4.0, 1.8, 1.5), doc["config"])
    assert header.mode == "lag 3"
    assert track.object_id == "car-1" and track.label == "Car" and track.source == str(tmp_path / "old" / "track.json")
    assert track.frames.tolist() == [5, 6, 7] and track.timestamps_ns.tolist() == [1_000, 1_100, 1_200]
    assert track.valid.tolist() == [True, False, True]   # prior_only is not a measurement; low_points is advisory
    assert track.flags == (("init",), ("no_points", "prior_only"), ("low_points",))
    assert track.scores.tolist() == [0.9, 0.0, 0.8] and track.num_points.tolist() == [300, 0, 250]
    np.testing.assert_array_equal(track.time_ms, [12.25, np.nan, 3.0])
    assert track.box_at(7) == Box(2.0, 2.0, 0.0, 0.25, 4.0, 1.8, 1.5) and track.size == (4.0, 1.8, 1.5)
    assert track.config == {"tracker": doc["config"]}
    np.testing.assert_allclose(track.shape_points, shape, atol=1e-5)
    # other invalid flags make other frames invalid
    assert read_track(tmp_path / "old", invalid_flags={"low_points"})[1].valid.tolist() == [True, True, False]
    write_track(tmp_path / "new", header, track)
    assert (tmp_path / "new" / "track.json").read_text() == text
    assert (tmp_path / "new" / "shape.ply").read_bytes() == (tmp_path / "old" / "shape.ply").read_bytes()
    # without a label, without time_ms, with frames listed out of order: rows in frame order, written back sorted
    del doc["label"]
    for row in doc["frames"]:
        row.pop("time_ms", None)
    doc["frames"] = doc["frames"][::-1]
    (tmp_path / "old" / "track.json").write_text(json.dumps(doc, indent=1) + "\n")
    header, track = read_track(tmp_path / "old")
    assert track.label == "" and track.time_ms is None and track.frames.tolist() == [5, 6, 7]
    write_track(tmp_path / "sorted", header, track)
    doc["frames"] = doc["frames"][::-1]
    assert (tmp_path / "sorted" / "track.json").read_text() == json.dumps(doc, indent=1) + "\n"