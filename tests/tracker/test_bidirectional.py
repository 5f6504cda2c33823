"""Bidirectional refinement (``refinement.backward``, tracker/bidirectional.py) on a far sparse car that approaches:
its dense frames pull the frames the forward pass lost into place, the whole-sequence solve reaches frames a
10-frame window cannot, and the result is the same for the same seed."""

from __future__ import annotations

import numpy as np
import pytest
from test_reacquire_clusters import REACQUIRE, _iou, _scene, _straight

from tracker import get_preset, refine_fixed_lag, refine_offline, track
from tracker.bidirectional import AnchorDetector, anchors, coasts_that_arrive, fuse_backward, refine_bidirectional
from tracker.geometry import Box, State
from tracker.sotracker import FrameEstimate

BACKWARD = {"refinement.backward": "both", "refinement.offline.gauge_heading_points": 30}


@pytest.fixture(scope="module")
def far_approach():
    """70 m away at the start with no points beyond 50 m, closing head-on at 1.2 m per frame (12 m/s), 17 m away
    at the end with ~150 points: the forward pass (with re-acquisition) holds the start box until it finds the
    car near 48 m, at frame ~18."""
    boxes = _straight(45, (70.0, 3.5), np.pi, 1.2)
    seq = _scene(boxes, 0, density=lambda r: 0.0 if r > 50.0 else 80.0 * (10.0 / r) ** 2, ground_centre=(40.0, 3.5),
                 ground_half=34.0)
    online = track(seq, boxes[0], 0, len(seq) - 1, get_preset("full", seed=0, **REACQUIRE))
    found = next(k for k, e in enumerate(online.estimates) if "reacquired" in e.flags)
    return seq, boxes, online, found


def test_the_dense_frames_pull_the_lost_frames_of_a_far_approach_into_place(far_approach):
    seq, boxes, online, found = far_approach
    gone = slice(4, found)  # the held start box no longer touches the car from frame 4 on (4.8 m travelled)
    assert found > 14 and _iou(online, boxes)[gone].max() < 0.1          # the forward pass lost frames 1..found-1
    plain = refine_offline(seq, online, get_preset("full", seed=0, **REACQUIRE, **{"refinement.backward": "none"}))
    both = refine_offline(seq, online, get_preset("full", seed=0, **REACQUIRE, **BACKWARD))
    iou_plain, iou_both = _iou(plain, boxes), _iou(both, boxes)
    assert iou_both[1:found].min() > 0.7 and iou_both[1:found].mean() > iou_plain[1:found].mean() + 0.2
    assert iou_both[found:].mean() >= iou_plain[found:].mean() - 0.02    # and the rest is not worse
    assert all("backward" in e.flags for e in both.estimates[1:found])
    start = both.estimates[0].box                                        # the start box is kept
    assert np.allclose(start.center, boxes[0].center) and np.isclose(np.cos(start.heading - boxes[0].heading), 1.0)


def test_offline_reaches_lost_frames_that_a_10_frame_window_cannot(far_approach):
    """The fixed-lag window revises only the frames still free when an anchor arrives (the 10 before it)."""
    seq, boxes, online, found = far_approach
    config = get_preset("full", seed=0, **REACQUIRE, **BACKWARD)
    lagged, offline = refine_fixed_lag(seq, online, 10, config), refine_offline(seq, online, config)
    first = anchors(online.estimates, config)[0][1]
    assert first + config.refinement.backward_lag_lead - 10 > 4         # frames the window never revises
    iou_lag, iou_off = _iou(lagged, boxes), _iou(offline, boxes)
    assert iou_off[1:].mean() >= iou_lag[1:].mean()
    lead = config.refinement.backward_lag_lead
    assert iou_lag[4:first + lead - 10].max() < 0.1 and iou_off[4:first + lead - 10].min() > 0.7
    # the window's own frames are revised
    assert np.median(iou_lag[first + lead - 10:first]) > 0.5         # (dead reckoning there: no points)


def test_bidirectional_refinement_is_deterministic_per_seed(far_approach):
    seq, boxes, _, _ = far_approach
    config = get_preset("full", seed=2, **REACQUIRE)
    online = track(seq, boxes[0], 0, len(seq) - 1, config)
    for lag in (None, 10):
        a, b = (refine_bidirectional(seq, online, config, lag=lag) for _ in range(2))
        assert np.array_equal([e.box.to_array() for e in a.estimates], [e.box.to_array() for e in b.estimates])
        assert [e.flags for e in a.estimates] == [e.flags for e in b.estimates]


def _estimate(k: int, points: int, flags: tuple[str, ...] = ()) -> FrameEstimate:
    box = Box(float(k), 0.0, 0.0, 0.0, 4.5, 1.8, 1.5)
    return FrameEstimate(k, State.from_array(box.to_array()[:4]), box, points, 1.0, flags, 0.0, np.zeros((0, 3)))


def test_anchors_are_dense_or_relocked_frames_after_a_weak_run_with_a_lost_frame():
    config = get_preset("full")
    counts = [5, 200, 40, 0, 0, 20, 150, 160, 50, 2, 300]
    flags = [("init",), (), (), ("prior_only",), ("waiting",), ("reacquired",), (), (), (), (), ()]
    estimates = [_estimate(k, n, f) for k, (n, f) in enumerate(zip(counts, flags, strict=True))]
    # frames 2-5 are a weak run (3, 4 lost; 5 re-locked: an anchor), 6 is the dense anchor of the same run;
    # 7 is dense after dense (no lost frame between); 8-9: weak, 9 lost (2 < 3 points); 10 dense
    assert anchors(estimates, config) == [(1, 5), (1, 6), (7, 10)]
    detector = AnchorDetector(config)
    assert [detector.add(e) for e in estimates][5] == (1, 5)             # causal: known when frame 5 arrives
    # an anchor's run holds at least backward_lost_frames lost frames: 8-9 holds one, 2-5 two
    two = config.updated({"refinement.backward_lost_frames": 2})
    assert anchors(estimates, two) == [(1, 5), (1, 6)]
    assert anchors(estimates, config.updated({"refinement.backward_lost_frames": 3})) == []


def test_backward_passes_that_move_no_frame_beyond_window_start_moved_leave_the_offline_solve_as_without(
        far_approach):
    """The fused states are the solve's data only where the backward passes moved some frame farther than
    ``window_start_moved`` from the online states (on the far approach they move the lost frames by metres)."""
    seq, boxes, online, found = far_approach
    settings = {**REACQUIRE, "refinement.offline.gauge_heading_points": 30}
    for moved, same in ((0.5, False), (100.0, True)):
        plain, both = (refine_offline(seq, online, get_preset("full", seed=0, **settings, **{
            "refinement.backward": backward, "refinement.offline.window_start_moved": moved}))
            for backward in ("none", "offline"))
        assert np.array_equal([e.box.to_array() for e in plain.estimates],
                              [e.box.to_array() for e in both.estimates]) == same
        assert any("backward" in e.flags for e in both.estimates) != same


def test_the_multi_object_pass_runs_the_backward_passes_of_the_offline_solve(far_approach):
    """sot_apps.tracking.track_objects (the pipeline's pass, regions gathered while tracking) gives the offline
    result of tracking the object alone with backward passes, bit for bit (it reads the lost run's frames again)."""
    from sot_apps.tracking import ObjectRequest, track_objects

    seq, boxes, online, found = far_approach
    config = get_preset("full", seed=0, **REACQUIRE, **{"refinement.backward": "offline"})
    outcomes, _ = track_objects(seq, [ObjectRequest("far", boxes[0], 0, len(seq) - 1)], config, mode="offline",
                                min_points=None)
    got, want = outcomes[0].result, refine_offline(seq, online, config)
    assert sum("backward" in e.flags for e in want.estimates) >= found - 2
    assert np.array_equal([e.box.to_array() for e in got.estimates], [e.box.to_array() for e in want.estimates])
    assert [e.flags for e in got.estimates] == [e.flags for e in want.estimates]
    assert np.array_equal(got.shape, want.shape)


def test_fusion_fills_the_lost_frames_from_the_backward_pass_tied_to_the_held_frames_on_both_sides():
    backward = np.array([[float(k), 0.0, 0.0, 0.0] for k in range(6)])
    forward = backward + np.array([[2.0, 0.0, 0.0, 0.0]] * 6)           # a constant offset between the passes ...
    forward[4:] += np.array([0.0, 1.0, 0.0, 0.1])                        # ... and another one after the stretch
    lost = np.array([False, True, True, True, False, False])
    fused = fuse_backward(forward, backward, lost)
    np.testing.assert_allclose(fused[[0, 4, 5]], forward[[0, 4, 5]])     # held frames keep the forward states
    np.testing.assert_allclose(fused[1:4, 0], backward[1:4, 0] + 2.0)
    np.testing.assert_allclose(fused[1:4, 1], [0.25, 0.5, 0.75])         # blended across the stretch
    np.testing.assert_allclose(fused[1:4, 3], [0.025, 0.05, 0.075])
    lost_start = fuse_backward(forward, backward, np.array([True, True, True, True, False, False]))
    np.testing.assert_allclose(lost_start[:4, 1], 1.0)                   # no held frame before: the other end's


def test_a_coast_that_lands_where_the_object_is_found_again_arrives():
    """``backward_arrival``: a lost stretch the forward pass coasted at 1 m per frame to where it found the object
    (0.3 m off) keeps its coast; one found 2 m ahead of the coast (the car sped up unseen) or never found does not."""
    forward = np.array([[float(k), 0.5 * k, 0.0, 0.1] for k in range(8)])
    lost = np.array([False, False, True, True, True, False, True, True])
    forward[5, 0] += 0.3
    np.testing.assert_array_equal(coasts_that_arrive(forward, lost, 0.5), [0, 0, 1, 1, 1, 0, 0, 0])
    assert not coasts_that_arrive(forward, lost, 0.2).any()
    forward[5, :2] += [1.7, 0.8]
    assert not coasts_that_arrive(forward, lost, 0.5).any()
