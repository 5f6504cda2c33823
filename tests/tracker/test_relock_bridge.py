"""The bridge before a re-lock (``refinement.relock_bridge``, tracker/relock_bridge.py): the frames a lost track spent
following someone else's points before it was re-locked elsewhere are a prediction for the refinements, not data."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_reacquire_clusters import _iou, _scene, _straight

from sot_apps.io.tracks import frame_is_valid
from tracker import get_preset, refine_fixed_lag, refine_offline
from tracker.geometry import Box, State
from tracker.relock_bridge import bridge_start, bridged_estimates, bridged_result
from tracker.sotracker import FrameEstimate, TrackResult, _search_flags

HIDDEN = range(6, 12)   # the target has no points; the lost track follows a car 3 m to its left meanwhile
DECOY_OFFSET = 3.0
RELOCK = HIDDEN.stop    # found again on its own points


def _estimate(k: int, box: Box, points: int, flags: tuple[str, ...] = ()) -> FrameEstimate:
    return FrameEstimate(k, State.from_array(box.to_array()[:4]), box, points, 1.0, flags, 0.0, np.zeros((0, 3)))


def _at(k: int, flags: tuple[str, ...], points: int = 50, across: float | None = None) -> FrameEstimate:
    """A box at x = k along +x; searching boxes 3 m to the left (beside the track) unless ``across`` says."""
    y = across if across is not None else 3.0 if "searching" in flags else 0.0
    return _estimate(k, Box(float(k), y, 0.0, 0.0, 4.5, 1.8, 1.5), points, flags)


def test_a_stretch_before_a_relock_is_bridged_only_when_the_track_followed_points_while_lost():
    searched = [_at(0, ("init",)), _at(1, ()), _at(2, ("prior_only", "coasting"), 0), _at(3, ("searching",)),
                _at(4, ("searching",)), _at(5, ("reacquired",)), _at(6, ())]
    assert bridge_start(searched, 5, 3) == 2          # the coast and the searching frames, back to the held frame 1
    assert bridge_start(searched, 6, 3) is None       # not re-locked
    coasted = [_at(0, ("init",)), _at(1, ()), _at(2, ("prior_only", "coasting"), 0), _at(3, ("reacquired",))]
    assert bridge_start(coasted, 3, 3) is None        # only coasted: no one else's points held it
    from_start = [_at(0, ("init",)), _at(1, ("searching",)), _at(2, ("searching",)), _at(3, ("reacquired",))]
    assert bridge_start(from_start, 3, 3) == 1        # frame 0, the given box, is never bridged
    came_back = [_at(0, ("init",)), _at(1, ()), _at(2, ("prior_only", "coasting"), 0), _at(3, ("searching",), 4),
                 _at(4, ("reacquired",))]
    assert bridge_start(came_back, 4, 3) is None      # the frame before the re-lock saw the object come back
    sparse = [_at(0, ("init",)), _at(1, ()), _at(2, ("prior_only", "coasting"), 0), _at(3, ("searching", "low_points"), 4),
              _at(4, ("searching", "low_points"), 6), _at(5, ("reacquired",))]
    assert bridge_start(sparse, 5, 3) is None         # a handful of points: the sparse car's own, coming back
    in_line = [_at(0, ("init",)), _at(1, ()), _at(2, ("prior_only", "coasting"), 0), _at(3, ("searching",), across=0.9),
               _at(4, ("searching",), across=1.5), _at(5, ("reacquired",))]
    assert bridge_start(in_line, 5, 3) is None        # held within a box width across: the object's own points
    in_line[3] = _at(3, ("searching",), across=-1.9)
    assert bridge_start(in_line, 5, 3) == 2           # the last box held on points decides (frame 4 is k - 1)
    twice = [_at(0, ("init",)), _at(1, ("searching",)), _at(2, ("searching",)), _at(3, ("reacquired",)),
             _at(4, ("searching",)), _at(5, ("searching",)), _at(6, ("reacquired",))]
    assert bridge_start(twice, 6, 3) == 4             # a stretch ends at the re-lock before it


def test_bridged_frames_turn_the_shorter_way():
    before = Box(0.0, 0.0, 0.0, np.pi - 0.1, 4.5, 1.8, 1.5)
    after = Box(4.0, 2.0, 1.0, -np.pi + 0.1, 4.5, 1.8, 1.5)
    out = bridged_estimates([_at(k, ("searching",)) for k in (1, 2, 3)], before, after)
    assert np.allclose([e.box.center for e in out], [[1.0, 0.5, 0.25], [2.0, 1.0, 0.5], [3.0, 1.5, 0.75]])
    assert np.allclose(np.cos([e.box.heading for e in out] - np.array([np.pi - 0.05, np.pi, -np.pi + 0.05])), 1.0)


def test_the_tracker_flags_frames_held_on_points_while_lost_as_searching():
    assert _search_flags(("low_points",), True, False) == ("low_points", "searching")
    assert _search_flags(("no_points", "prior_only"), True, False) == ("no_points", "prior_only", "coasting")
    assert _search_flags(("no_points", "prior_only"), False, False) == ("no_points", "prior_only")
    assert _search_flags((), False, True) == ()      # the candidate is where the track is: it holds its object


@pytest.fixture(scope="module")
def decoyed():
    """A car along +x at 0.5 m per frame, 12 m ahead of the parked ego, hidden in frames 6-11 while another car
    drives 3 m to its left; an online result that held the car to frame 5, followed the other car over the hidden
    frames (``searching``) and was re-locked on the car at frame 12 (as the tracker's re-acquisition does)."""
    truth = _straight(24, (12.0, 4.0), 0.0, 0.5)
    far = Box(60.0, -30.0, 0.0, 0.0, *truth[0].size)
    decoy = [dataclasses.replace(b, y=b.y + DECOY_OFFSET) if k in HIDDEN else far for k, b in enumerate(truth)]
    seq = _scene(truth, 0, hidden=HIDDEN, others=(decoy,), ground_half=24.0)
    estimates = []
    for k, box in enumerate(truth):
        flags = ("init",) if k == 0 else ("searching",) if k in HIDDEN else ("reacquired",) if k == RELOCK else ()
        estimates.append(_estimate(k, decoy[k] if k in HIDDEN else box, 60, flags))
    online = TrackResult(estimates, np.asarray(truth[0].size), np.zeros((0, 3)), get_preset("full", seed=0))
    return seq, truth, online


def test_bridged_frames_lie_on_the_line_between_the_frames_around_them_without_points(decoyed):
    _, truth, online = decoyed
    bridged = bridged_result(online, 3)
    for k in HIDDEN:
        e = bridged.estimates[k]
        assert "bridged" in e.flags and e.num_points == 0 and len(e.points) == 0
        assert not frame_is_valid(e.flags)        # a prediction: motion export and track health take it as such
        assert np.allclose(e.box.center, truth[k].center, atol=1e-9)   # a straight drive: the line is the truth
    assert all(a is b for a, b in zip(online.estimates[:HIDDEN.start] + online.estimates[RELOCK:],
                                      bridged.estimates[:HIDDEN.start] + bridged.estimates[RELOCK:], strict=True))
    clean = dataclasses.replace(online, estimates=[dataclasses.replace(e, flags=()) for e in online.estimates])
    assert bridged_result(clean, 3) is clean


@pytest.mark.parametrize("mode", ["offline", "lag"])
def test_the_refinements_take_the_bridge_and_not_the_other_cars_points(decoyed, mode):
    """Without the bridge the solves hold the hidden frames on the other car (its points agree with each other)
    and pull the frames around them toward it; with it they follow the car."""
    seq, truth, online = decoyed

    def refined(bridge: str):
        config = get_preset("full", seed=0, **{"refinement.relock_bridge": bridge})
        return refine_offline(seq, online, config) if mode == "offline" else refine_fixed_lag(seq, online, 10, config)

    plain, bridged = refined("none"), refined("both")
    iou_plain, iou_bridged = _iou(plain, truth), _iou(bridged, truth)
    hidden = slice(HIDDEN.start, HIDDEN.stop)
    assert iou_plain[hidden].max() < 0.2 and iou_bridged[hidden].min() > 0.6
    assert iou_bridged[1:].mean() > iou_plain[1:].mean() + 0.15
    assert all("bridged" in e.flags and e.num_points == 0 for e in bridged.estimates[hidden])
    if mode == "lag":   # "offline" bridges the whole-sequence solve only
        boxes = [e.box.to_array() for e in refined("offline").estimates]
        assert np.array_equal(boxes, [e.box.to_array() for e in plain.estimates])


def test_the_offline_bridge_from_regions_gathered_while_tracking_is_the_one_from_the_source(decoyed):
    """The multi-object pass (sot_apps.tracking.track_objects) solves offline from the region points it gathered
    around the online boxes as it tracked: the bridge drops the bridged frames' points there too, so the result is
    the one of reading the source (as tracking one object alone does)."""
    from tracker.offline import frame_region_points_timed

    seq, _, online = decoyed
    config = get_preset("full", seed=0, **{"refinement.relock_bridge": "offline"})
    params = config.refinement.offline
    regions, times, previous = [], [], None
    for e in online.estimates:
        frame = seq.lidar_frame(e.frame)
        points, when = frame_region_points_timed(frame, e.box, config, params, previous,
                                                 with_times=params.own_motion_spread > 0)
        regions.append(points)
        times.append(when)
        previous = (int(frame.timestamp_ns), frame.world_from_ego)
    from_source = refine_offline(seq, online, config)
    from_regions = refine_offline(None, online, config, points=regions, point_times=times)
    assert np.array_equal([e.box.to_array() for e in from_source.estimates],
                          [e.box.to_array() for e in from_regions.estimates])
    assert [e.flags for e in from_source.estimates] == [e.flags for e in from_regions.estimates]
