"""The track stage's shape-growth record: the same track as tracker.track, and snapshots of a growing shape."""

from __future__ import annotations

import numpy as np

from sot_apps.io import open_sequence
from sot_apps.tracking import read_shape_growth, track_with_shape_growth, write_shape_growth
from tracker import TrackerConfig, track


def test_recording_the_shape_growth_does_not_change_the_track(tiny_dir, tmp_path):
    seq = open_sequence(tiny_dir)
    init = seq.tracks()["car-move"].box(0)
    config = TrackerConfig()
    plain = track(seq, init, 0, 12, config)
    result, growth = track_with_shape_growth(seq, init, 0, 12, config, "car-move", shots=4)
    assert [e.state.to_array().tolist() for e in result.estimates] == [e.state.to_array().tolist() for e in plain.estimates]
    np.testing.assert_array_equal(result.shape, plain.shape)
    assert growth.frames[0] == 0 and 2 <= len(growth.frames) <= 4
    assert list(growth.frames) == sorted(growth.frames)
    counts = [len(p) for p in growth.points]
    assert counts[-1] > counts[0]                       # the shape grows
    np.testing.assert_array_equal(growth.points[-1], result.shape)   # the last snapshot is the final shape
    back = read_shape_growth(write_shape_growth(tmp_path, growth).parent)
    assert back.frames == growth.frames and [len(p) for p in back.points] == counts
    np.testing.assert_allclose(back.points[1], growth.points[1], atol=5e-4)
