"""``ground.remover="sweep"`` (``full``, ``faithful``): the sweep plane's ground points near the box stay the road
that the height uses (z_mode "filter"), and none of them reaches the registration; ``height.road_max_range`` drops
that road for a box farther from the sensor."""

from __future__ import annotations

import numpy as np
from tracker_synthetic import make_sequence

from tracker.config import get_preset
from tracker.sotracker import Tracker


def test_sweep_scope_keeps_the_road_near_the_box_for_the_height():
    seq = make_sequence(n_frames=3, seed=3)                           # road at z = -0.75 (world)
    cfg = get_preset("full", seed=0)
    assert cfg.ground.remover == "sweep" and cfg.height.model == "filter"
    tracker = Tracker(cfg)
    tracker.start(seq.frames[0], seq.boxes[0])
    for k in (1, 2):
        tracker.step(seq.frames[k])
        road = tracker._ground_points
        assert len(road) > 50 and abs(np.median(road[:, 2]) + 0.75) < 0.05
        box = seq.boxes[k]
        assert np.hypot(*(road[:, :2] - box.center[:2]).T).max() < 0.5 * np.hypot(box.length, box.width) * 4 + 3
        local, _ = tracker._local_points(seq.frames[k], box, cfg.search.scale)
        assert (local[:, 2] < -0.75 + 0.1).mean() < 0.02                # the road is not in the registration's points


def test_no_road_for_the_height_beyond_road_max_range():
    seq = make_sequence(n_frames=4, seed=3)                           # road at z = -0.75 (world)
    ranges = [np.hypot(*(b.center[:2] - f.world_from_ego[:2, 3])) for b, f in zip(seq.boxes, seq.frames, strict=True)]
    runs = {}
    for far in (0.0, min(ranges) - 1.0, max(ranges) + 50.0):
        tracker = Tracker(get_preset("full", seed=0, **{"height.road_max_range": far}))
        tracker.start(seq.frames[0], seq.boxes[0])
        roads, boxes = [], []
        for k in (1, 2, 3):
            box = tracker.step(seq.frames[k]).box
            boxes.append([box.x, box.y, box.z, box.heading])
            roads.append(len(tracker._ground_points))
        runs[far] = (roads, np.array(boxes))
    default, near, beyond = runs.values()
    assert min(default[0]) > 50 and beyond[0] == default[0]           # every box nearer than the limit keeps its road
    np.testing.assert_array_equal(beyond[1], default[1])
    assert near[0] == [0, 0, 0]                                       # every box beyond it: no road, z from the fit
    assert np.abs(near[1][:, [0, 1, 3]] - default[1][:, [0, 1, 3]]).max() < 0.05  # x, y, heading barely move
