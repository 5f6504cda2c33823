"""``ground.remover="sweep"`` (``full``, ``faithful``): the sweep plane's ground points near the box stay the road
that the height uses (z_mode "filter"), and none of them reaches the registration."""

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
