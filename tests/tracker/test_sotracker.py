"""SOTracker on a synthetic sequence with a known rigid trajectory: accuracy, API agreement, determinism, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from tracker_synthetic import make_sequence

from tracker.config import PRESETS, get_preset
from tracker.detection import FrameDetections
from tracker.metrics import iou_3d
from tracker.sotracker import Tracker, track


@pytest.fixture(scope="module")
def sequence():
    return make_sequence(n_frames=24, seed=3)


@pytest.fixture(scope="module")
def full_result(sequence):
    return track(sequence, sequence.boxes[0], 0, len(sequence) - 1, get_preset("full"))


def test_known_trajectory_is_recovered(sequence, full_result):
    ious = [iou_3d(b, g) for b, g in zip(full_result.boxes[1:], sequence.boxes[1:], strict=True)]
    errors = [np.linalg.norm(b.center - g.center)
              for b, g in zip(full_result.boxes[1:], sequence.boxes[1:], strict=True)]
    assert np.mean(ious) >= 0.9, np.round(ious, 3)
    assert np.mean(errors) < 0.1, np.round(errors, 3)
    # the turn (last frames) is followed too, not only the straight part
    assert np.mean(errors[-5:]) < 0.15
    assert full_result.frames == list(range(len(sequence)))
    assert len(full_result.shape) > 100 and full_result.shape.shape[1] == 3
    # the shape lies in the object frame: inside the (slightly grown) box centred at the origin
    assert np.all(np.abs(full_result.shape) <= np.array([4.5, 1.8, 1.5]) * 0.5 * 1.1 + 0.05)


def test_streaming_api_agrees_with_track(sequence, full_result):
    tracker = Tracker(get_preset("full"))
    first = tracker.start(sequence.lidar_frame(0), sequence.boxes[0])
    assert "init" in first.flags and first.state == sequence.boxes[0].state
    estimates = [tracker.step(sequence.lidar_frame(k)) for k in range(1, len(sequence))]
    assert [e.state for e in estimates] == full_result.states[1:]
    np.testing.assert_array_equal(tracker.shape_points(), full_result.shape)
    for e in estimates:
        assert 0.0 <= e.quality <= 1.0 and e.time_ms > 0 and e.points.shape == (e.num_points, 3)


def test_same_seed_gives_identical_output(sequence):
    config = get_preset("full", seed=7)
    a = track(sequence, sequence.boxes[0], 0, 12, config)
    b = track(sequence, sequence.boxes[0], 0, 12, config)
    assert a.states == b.states
    np.testing.assert_array_equal(a.shape, b.shape)


def test_frame_without_points_continues_on_the_prior():
    seq = make_sequence(n_frames=10, seed=1, empty_frames=(6,))
    result = track(seq, seq.boxes[0], 0, 9, get_preset("full"))
    est = result.estimates[6]
    assert "no_points" in est.flags and "prior_only" in est.flags and est.num_points == 0
    # constant velocity before the gap: the prior carries the box about one frame's motion forward
    step = np.linalg.norm(result.boxes[6].center[:2] - result.boxes[5].center[:2])
    assert 0.8 < step < 1.2
    assert iou_3d(result.boxes[6], seq.boxes[6]) > 0.7
    assert iou_3d(result.boxes[9], seq.boxes[9]) > 0.8  # and it picks the object up again
    assert not result.estimates[7].flags


def test_nan_points_are_dropped_and_flagged():
    seq = make_sequence(n_frames=8, seed=2, nan_frames=(3,))
    result = track(seq, seq.boxes[0], 0, 7, get_preset("full"))
    assert "nan_points" in result.estimates[3].flags
    assert all(np.isfinite(b.to_array()).all() for b in result.boxes)
    with_nan = np.mean([iou_3d(b, g) for b, g in zip(result.boxes[1:], seq.boxes[1:], strict=True)])
    clean_seq = make_sequence(n_frames=8, seed=2)
    clean = track(clean_seq, clean_seq.boxes[0], 0, 7, get_preset("full"))
    without = np.mean([iou_3d(b, g) for b, g in zip(clean.boxes[1:], clean_seq.boxes[1:], strict=True)])
    assert with_nan > 0.75 and with_nan > without - 0.05  # losing 1/7 of one frame's points costs little


def test_init_box_without_points_never_crashes():
    seq = make_sequence(n_frames=5, seed=4)
    far = seq.boxes[0].with_state(seq.boxes[0].state.__class__(500.0, 500.0, 0.0, 0.0))
    result = track(seq, far, 0, 4, get_preset("full"))
    assert "no_points" in result.estimates[0].flags
    assert all("no_points" in e.flags for e in result.estimates[1:])
    assert [b.center.tolist() for b in result.boxes] == [far.center.tolist()] * 5  # zero prior: stays put
    assert len(result.shape) == 0


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_every_preset_runs(name):
    seq = make_sequence(n_frames=7, seed=5)
    # the detection presets (det, det_sot) get the true boxes as detections; the others ignore them
    detections = {k: FrameDetections(b.to_array()[None], np.array([0.9])) for k, b in enumerate(seq.boxes)}
    result = track(seq, seq.boxes[0], 0, 6, get_preset(name), detections=detections)
    assert result.config.preset == name
    ious = [iou_3d(b, g) for b, g in zip(result.boxes[1:], seq.boxes[1:], strict=True)]
    assert np.mean(ious) > 0.75, (name, np.round(ious, 3))


def test_track_checks_its_frame_range(sequence):
    with pytest.raises(IndexError):
        track(sequence, sequence.boxes[0], 30, None, get_preset("full"))
    with pytest.raises(ValueError):
        Tracker(get_preset("full")).start(sequence.lidar_frame(0), sequence.boxes[0].__class__(
            np.nan, 0, 0, 0, 4, 2, 1.5))


def test_every_flag_a_coasting_and_refined_track_writes_is_a_known_tracker_flag():
    """``sot_apps.io.tracks.TRACKER_FLAGS`` (what `motion-export --invalid-flags` accepts) names every flag the
    tracker writes: a track that loses its points for four frames (coasting) and its offline refinement."""
    from sot_apps.io.tracks import TRACKER_FLAGS
    from tracker import refine_offline

    seq = make_sequence(n_frames=14, seed=6, empty_frames=(5, 6, 7, 8))
    result = track(seq, seq.boxes[0], 0, 13, get_preset("full"))
    online = {f for e in result.estimates for f in e.flags}
    assert {"coasting", "prior_only", "no_points"} <= online
    refined = {f for e in refine_offline(seq, result, get_preset("full")).estimates for f in e.flags}
    assert "offline" in refined
    assert online | refined <= TRACKER_FLAGS, sorted((online | refined) - TRACKER_FLAGS)
