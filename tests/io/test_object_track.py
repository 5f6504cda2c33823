"""ObjectTrack, the one per-object time series of sot_apps: rows, columns and the track-file conversion."""

from __future__ import annotations

import numpy as np
import pytest

from sot_apps.io.object_track import ObjectTrack
from sot_apps.io.tracks import FrameRecord, Size, TrackFile, object_track, read_track, write_track
from tracker.geometry import Box, State


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
    with pytest.raises(ValueError, match="scores has 1 entries for 3 frames"):
        ObjectTrack.from_states("a", "Car", (4.0, 2.0, 1.5), [0, 1, 2], [0, 1, 2], states, [True] * 3, scores=[1.0])


def test_a_written_track_file_becomes_an_object_track(tmp_path):
    records = [FrameRecord(5, 1_000, State(1.0, 2.0, 0.0, 0.2), 300, 0.9, ["init"]),
               FrameRecord(6, 1_100, State(1.5, 2.0, 0.0, 0.2), 0, 0.0, ["no_points", "prior_only"]),
               FrameRecord(7, 1_200, State(2.0, 2.0, 0.0, 0.2), 250, 0.8, ["low_points"])]
    init = Box(1.0, 2.0, 0.0, 0.2, 4.0, 1.8, 1.5)
    config = {"preset": "full", "mode": "online"}
    write_track(tmp_path, TrackFile("seq", "car-1", Size(4.0, 1.8, 1.5), 5, 7, init, config, records, label="Car"),
                np.zeros((4, 3)))
    track = object_track(*read_track(tmp_path), source="here")
    assert track.object_id == "car-1" and track.label == "Car" and track.source == "here"
    assert track.frames.tolist() == [5, 6, 7] and track.timestamps_ns.tolist() == [1_000, 1_100, 1_200]
    assert track.valid.tolist() == [True, False, True]   # prior_only is not a measurement; low_points is advisory
    assert track.scores.tolist() == [0.9, 0.0, 0.8] and track.num_points.tolist() == [300, 0, 250]
    assert track.box_at(7) == Box(2.0, 2.0, 0.0, 0.2, 4.0, 1.8, 1.5)
    assert track.config == {"tracker": {"preset": "full", "mode": "online"}} and track.shape_points.shape == (4, 3)
