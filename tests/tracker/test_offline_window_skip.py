"""The offline solve skips its window pass (``refinement.offline.window_start``) only where the pass cannot change
the result: given the points (no source: the pipeline's path), when the solve from the online states holds so many
of them that no states' boxes could hold ``window_start_margin`` x as many. Synthetic scenes, the same boxes bit for
bit as with the pass run."""

from __future__ import annotations

import numpy as np
import pytest
from test_reacquire_clusters import _scene, _straight

import tracker.fixed_lag as fixed_lag
import tracker.offline as offline
from tracker import get_preset, refine_offline
from tracker.geometry import Box, State, points_in_box
from tracker.offline import _support, _support_bound, gather_frame_points
from tracker.sotracker import FrameEstimate, TrackResult


def _online(held_off: range, in_box: bool = False) -> tuple[TrackResult, list[np.ndarray]]:
    """A car driving straight at 1 m per frame past the parked ego; online states = truth + 5 cm / 0.6 deg noise,
    2.9 m behind it on the ``held_off`` frames; and each frame's region points (as the pipeline gathers them;
    ``in_box``: only those in the true box, so that the solve's boxes hold nearly all of them)."""
    boxes = _straight(14, (8.0, 6.0), 0.0, 1.0)
    seq = _scene(boxes, 0, ground_centre=(15.0, 6.0), ground_half=11.0)
    size = np.array(boxes[0].size)
    states = np.array([b.to_array()[:4] for b in boxes])
    noise = np.random.default_rng(0).normal(0.0, [0.05, 0.05, 0.0, 0.01], states.shape)
    states[1:] += noise[1:]
    states[list(held_off), 0] -= 2.9
    config = get_preset("full", seed=0)
    estimates = [FrameEstimate(k, State.from_array(x), Box(*x, *size), 50, 1.0, (), 1.0, np.zeros((0, 3)))
                 for k, x in enumerate(states)]
    online = TrackResult(estimates, size, np.zeros((0, 3)), config)
    points = gather_frame_points(seq, online, config, config.refinement.offline)
    if in_box:
        points = [p[points_in_box(p, truth, 1.0)] for p, truth in zip(points, boxes, strict=True)]
    return online, points


def _boxes(result: TrackResult) -> np.ndarray:
    return np.array([e.box.to_array() for e in result.estimates])


def _counting_window(monkeypatch) -> list[int]:
    calls: list[int] = []
    real = fixed_lag.window_states

    def counted(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(fixed_lag, "window_states", counted)
    return calls


@pytest.mark.parametrize("held_off, in_box, margin, skipped", [(range(0), True, 1.05, True),
                                                                (range(0), True, 1.0, False),
                                                                (range(1, 7), False, 1.0, False)])
def test_the_window_pass_is_skipped_only_where_it_cannot_change_the_boxes(monkeypatch, held_off, in_box, margin,
                                                                         skipped):
    """With ``full``'s margin of 1.0 the solve's boxes would have to hold every point any boxes could: not skipped
    even with only the car's points; with 1.05 it is."""
    online, points = _online(held_off, in_box)
    # (the gate on the first solve's move, tests/tracker/test_offline_window_start.py, off: this skip alone)
    config = online.config.updated({"refinement.offline.window_start_margin": margin,
                                    "refinement.offline.window_start_first_moved": 0.0})
    calls = _counting_window(monkeypatch)
    got = refine_offline(None, online, config, points=points)
    assert (len(calls) == 0) == skipped
    monkeypatch.setattr(offline, "_window_cannot_win", lambda *args: False)   # the pass always run, as before
    want = refine_offline(None, online, config, points=points)
    assert len(calls) == (1 if skipped else 2)
    assert np.array_equal(_boxes(got), _boxes(want))
    assert np.array_equal(got.shape, want.shape)
    assert [e.num_points for e in got.estimates] == [e.num_points for e in want.estimates]


def test_the_support_bound_holds_for_any_boxes():
    online, points = _online(range(1, 7))
    size = np.asarray(online.size)
    bound = _support_bound(points, float(size[2]))
    assert bound <= sum(len(p) for p in points)
    rng = np.random.default_rng(1)
    states = np.array([e.state.to_array() for e in online.estimates])
    for _ in range(50):   # boxes moved anywhere nearby, turned, raised or lowered
        moved = states + rng.normal(0.0, [1.0, 1.0, 0.3, 0.5], states.shape)
        assert _support(points, moved, size) <= bound
    tall = size * [1.0, 1.0, 1e3]   # a box tall enough to take every point of its frame in z: the bound is the total
    assert _support_bound(points, float(tall[2])) == sum(len(p) for p in points)
