"""``sot-apps bench tracker``'s rows on a synthetic sequence with known boxes: online, fixed-lag and the
offline row (the refinement's CPU ms per tracked frame), and the table that prints them."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from tracker_synthetic import make_sequence

from sot_apps.bench.tracker import _offline_row, _time_track, _times_online, format_table
from tracker import get_preset, pool_metrics, score_tracklet


def test_offline_row_times_the_refinement_per_frame_and_scores_it():
    seq = make_sequence(n_frames=10, seed=5)
    spec = SimpleNamespace(track_id="synthetic", frames=tuple(range(10)), boxes=tuple(seq.boxes))
    config = get_preset("full")
    row = _offline_row(seq, [spec], config, "full")
    assert row["row"] == "full+offline" and row["frames"] == 9
    assert row["offline_added_ms"] > 0 and row["offline_added_ms_per_track"] == [row["offline_added_ms"]]
    assert row["acc"] > 0.8 and row["rob"] > 0.8   # a clean synthetic car: the refinement keeps it

    truth = np.array([b.to_array() for b in seq.boxes])
    boxes, wall, cpu = _time_track(seq, spec, config, lag=3)
    assert boxes.shape == (10, 7) and len(cpu) == 9 and np.all(cpu > 0) and np.all(wall > 0)
    assert pool_metrics([score_tracklet("synthetic", boxes, truth)]).acc > 0.8

    online = {"row": "full", "acc": 0.9, "rob": 0.9, "frames": 9, "cpu_median_ms": 10.0, "cpu_mean_ms": 11.0,
              "cpu_p90_ms": 12.0, "cpu_frame1_mean_ms": 50.0, "cpu_median_ms_k2": 10.0, "wall_median_ms": 10.0,
              "wall_mean_ms": 11.0}
    machine = {"cpu": "test", "load_average": "0.00 0.00 0.00"}
    table = format_table({"sequence": "synthetic", "tracks": ["synthetic"], "frames_per_preset": 9,
                          "machine": machine, "rows": [online, row]})
    line = next(ln for ln in table.splitlines() if ln.startswith("full+offline"))
    cells = line.split()
    assert cells[1:8] == ["-"] * 7 and cells[8] == f"{row['offline_added_ms']:.1f}"
    assert "added ms" in table and next(ln for ln in table.splitlines() if ln.startswith("full ")).split()[8] == "-"


def test_sweep_ground_is_timed_once_per_sweep_and_shown_apart():
    """``full`` and ``faithful`` remove the ground with one plane per sweep, shared by every object in the sweep:
    the bench times it per sweep, warms the cache so that the step times exclude it, and prints it apart."""
    from sot_apps.bench.tracker import _time_sweep_ground
    from tracker.sweep_ground import _CACHE, sweep_ground_mask

    seq = make_sequence(n_frames=4, seed=6)
    config = get_preset("full")
    ms = _time_sweep_ground(seq, [0, 1, 2, 3], config)
    assert ms.shape == (4,) and np.all(ms > 0)
    for k in range(4):
        points = seq.lidar_frame(k).points_ego
        entry = _CACHE[id(points)]
        assert entry[0]() is points and np.array_equal(entry[2], sweep_ground_mask(points, *config.ground.sweep_args()))
    assert _time_sweep_ground(seq, [0, 1], get_preset("full", **{"ground.remover": "local"})).size == 0   # nothing shared

    row = {"row": "full", "acc": 0.9, "rob": 0.9, "frames": 3, "cpu_median_ms": 10.0, "cpu_mean_ms": 11.0,
           "cpu_p90_ms": 12.0, "cpu_frame1_mean_ms": 50.0, "cpu_median_ms_k2": 10.0, "wall_median_ms": 10.0,
           "wall_mean_ms": 11.0, "sweep_ground_ms": float(np.median(ms))}
    table = format_table({"sequence": "synthetic", "tracks": ["synthetic"], "frames_per_preset": 3,
                          "machine": {"cpu": "test", "load_average": "0"}, "rows": [row]})
    assert next(ln for ln in table.splitlines() if ln.startswith("full ")).split()[9] == f"{np.median(ms):.1f}"


def test_fixed_lag_rows_give_their_ratio_to_the_online_row():
    """'x online': a fixed-lag row's median over the online row's (timed interleaved), per object step and per
    lone-object frame (the sweep's ground added to both); the table prints both."""
    online = {"cpu_median_ms": 7.5, "sweep_ground_ms": 5.0}
    lag = {"row": "full+lag10", "acc": 0.9, "rob": 0.9, "frames": 3, "cpu_median_ms": 15.0, "cpu_mean_ms": 15.0,
           "cpu_p90_ms": 16.0, "cpu_frame1_mean_ms": 50.0, "cpu_median_ms_k2": 15.0, "wall_median_ms": 15.0,
           "wall_mean_ms": 15.0, "sweep_ground_ms": 5.0}
    lag.update(_times_online(lag, online))
    assert lag["times_online"] == 2.0 and lag["times_online_lone_object"] == 20.0 / 12.5
    assert _times_online({"cpu_median_ms": 3.0}, {"cpu_median_ms": 2.0}) == {"times_online": 1.5,
                                                                              "times_online_lone_object": 1.5}
    table = format_table({"sequence": "synthetic", "tracks": ["synthetic"], "frames_per_preset": 3,
                          "machine": {"cpu": "test", "load_average": "0"}, "rows": [lag]})
    cells = next(ln for ln in table.splitlines() if ln.startswith("full+lag10")).split()
    assert cells[9:12] == ["5.0", "2.00", "1.60"] and "x online (lone)" in table
