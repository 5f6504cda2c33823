"""The whole-sequence solve against the fixed-lag window on a track that the online pass held metres off and then
re-locked (``refinement.offline.window_start``): started from the online states, the solve keeps the offset
stretch (a local minimum: its frames agree with each other, not with the re-locked ones); the window, registering
each new frame to the shape of frames it has already corrected, pulls them toward the car. Synthetic scene, known
truth."""

from __future__ import annotations

import numpy as np
import pytest
from test_offline_window_skip import _counting_window
from test_reacquire_clusters import _iou, _scene, _straight

from tracker import get_preset, refine_fixed_lag, refine_offline
from tracker.geometry import Box, State
from tracker.sotracker import FrameEstimate, TrackResult

HELD_OFF = range(1, 12)   # frames the online pass held 2.9 m behind the car (re-locked at 12)


@pytest.fixture(scope="module")
def held_off():
    """A car driving straight at 1 m per frame past the parked ego, ~50 points per frame; the online states are
    the truth with 5 cm / 0.6° noise, 2.9 m behind it on frames 1-11."""
    boxes = _straight(30, (8.0, 6.0), 0.0, 1.0)
    seq = _scene(boxes, 0, ground_centre=(22.0, 6.0), ground_half=18.0)
    rng = np.random.default_rng(0)
    config = get_preset("full", seed=0)
    estimates = []
    for k, truth in enumerate(boxes):
        state = truth.to_array()[:4].copy()
        if k > 0:
            state[:2] += rng.normal(0.0, 0.05, 2)
            state[3] += rng.normal(0.0, 0.01)
        if k in HELD_OFF:
            state[0] -= 2.9
        estimates.append(FrameEstimate(k, State.from_array(state), Box(*state, *truth.size), 50, 1.0, (), 1.0,
                                       np.zeros((0, 3))))
    online = TrackResult(estimates, np.array(boxes[0].size), np.zeros((0, 3)), config)
    return seq, boxes, online, config


def test_offline_is_at_least_the_window_where_the_online_pass_held_the_car_off_before_relocking(held_off):
    seq, boxes, online, config = held_off
    assert config.refinement.offline.window_start == 10                       # full's default
    lagged = _iou(refine_fixed_lag(seq, online, 10, config), boxes)
    refined = refine_offline(seq, online, config)
    offline = _iou(refined, boxes)
    from_online = _iou(refine_offline(seq, online, config.updated({"refinement.offline.window_start": 0})), boxes)
    assert _iou(online, boxes)[list(HELD_OFF)].max() < 0.3                     # the online pass lost them
    assert from_online.mean() < lagged.mean() - 0.05                           # the solve from the online states
    assert offline.mean() >= lagged.mean() and offline.mean() > from_online.mean() + 0.1
    assert offline[15:].min() > 0.9                                            # the re-locked frames stay on the car
    start = refined.estimates[0].box                                           # the start box is kept
    assert np.allclose(start.center, boxes[0].center)


def test_the_second_solve_runs_only_where_the_window_moved_a_state(held_off):
    """Online states on the car (the window moves none by more than ``window_start_moved``): the first solve's
    states, exactly."""
    seq, boxes, online, config = held_off
    on_the_car = TrackResult([FrameEstimate(k, State.from_array(b.to_array()[:4]), b, 50, 1.0, (), 1.0,
                                            np.zeros((0, 3))) for k, b in enumerate(boxes)],
                             online.size, online.shape, config)
    with_second = refine_offline(seq, on_the_car, config)
    without = refine_offline(seq, on_the_car, config.updated({"refinement.offline.window_start": 0}))
    assert np.array_equal([e.box.to_array() for e in with_second.estimates],
                          [e.box.to_array() for e in without.estimates])


def test_window_keep_takes_the_window_states_where_they_hold_more_points(held_off):
    """``window_keep``: with no second solve (``window_start_moved`` beyond any move) the solve from the online
    states keeps the 2.9 m offset; the window pass's own states hold more of the car's points and are the result
    (as ``refine_fixed_lag`` gives them); without ``window_keep`` the result is the solve's."""
    seq, boxes, online, config = held_off
    no_second = config.updated({"refinement.offline.window_start_moved": 100.0})
    kept = refine_offline(seq, online, no_second.updated({"refinement.offline.window_keep": True}))
    solved = refine_offline(seq, online, no_second)
    lagged = refine_fixed_lag(seq, online, 10, config)
    assert _iou(kept, boxes).mean() > _iou(solved, boxes).mean() + 0.05
    np.testing.assert_allclose([e.box.to_array() for e in kept.estimates],
                               [e.box.to_array() for e in lagged.estimates], atol=1e-6)
    assert sum(e.num_points for e in kept.estimates) > sum(e.num_points for e in solved.estimates)


def _on_the_car(boxes, online, config, lost_frames=()) -> TrackResult:
    return TrackResult([FrameEstimate(k, State.from_array(b.to_array()[:4]), b, 50, 1.0,
                                      ("prior_only",) if k in lost_frames else (), 1.0, np.zeros((0, 3)))
                        for k, b in enumerate(boxes)], online.size, online.shape, config)


@pytest.mark.parametrize("case, runs", [("held_off", True), ("on_the_car", False), ("on_the_car_one_lost", True)])
def test_the_window_pass_runs_only_where_the_first_solve_moved_a_state_or_a_frame_was_lost(monkeypatch, held_off,
                                                                                           case, runs):
    """``window_start_first_moved``: the car held 2.9 m off (the first solve moves those frames ~1 m) and a track
    with a prior-only frame run the window pass; online states on the car (the first solve moves none 0.25 m) do
    not, and get the boxes of the pass run every time, bit for bit (its second solve would not have been kept: the
    window moves no state 0.5 m)."""
    seq, boxes, online, config = held_off
    assert config.refinement.offline.window_start_first_moved == 0.25                 # full's
    track = online if case == "held_off" else _on_the_car(boxes, online, config,
                                                          (5,) if case == "on_the_car_one_lost" else ())
    calls = _counting_window(monkeypatch)
    gated = refine_offline(seq, track, config)
    assert len(calls) == runs
    if not runs:
        always = refine_offline(seq, track, config.updated({"refinement.offline.window_start_first_moved": 0.0}))
        assert len(calls) == 1                                                         # the ungated run's pass
        assert np.array_equal([e.box.to_array() for e in gated.estimates],
                              [e.box.to_array() for e in always.estimates])
