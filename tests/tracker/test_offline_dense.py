"""The whole-sequence solve's fold shapes on a finer grid for a dense car (``refinement.offline.dense_voxel``; the
fixed-lag window's ``refinement.lag.dense_voxel``): a dense car's frames are pulled onto the coarse grid's voxel
centres, and the solve ends below the online pass; on a synthetic world (exact truth) and on an analytic sparse
scene (the grid unchanged there)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_offline import _result, _scene

from tracker import get_preset, refine_fixed_lag, refine_offline, track
from tracker.config import OFFLINE_PARAMS, TrackerConfig
from tracker.metrics import iou_3d_batch


def _acc(result, truth) -> float:
    boxes = np.array([e.box.to_array()[:7] for e in result.estimates])
    return 100.0 * float(iou_3d_batch(boxes[1:], truth[1:]).mean())


def _dense_world(tmp_path):
    """Synthetic world seed 2 (20 frames, pandar64, three moving cars of 3,060-3,310 points per frame) and a cached
    source of it."""
    from sot_apps.io import open_sequence
    from sot_apps.io.cached_source import CachedSource
    from sot_apps.synth import write_world

    sequence = open_sequence(write_world(tmp_path / "w", frames=20, vehicles=3, sensor="pandar64", seed=2))
    return sequence, CachedSource(sequence)


def _truth(sequence, track_id: str):
    """(first frame, last frame, ground-truth boxes, their (K, 7) array) of a track."""
    gt = sequence.tracks()[track_id]
    lo, hi = min(gt.frames), max(gt.frames)
    truth = [gt.box_at(k) for k in range(lo, hi + 1)]
    return lo, hi, truth, np.array([b.to_array()[:7] for b in truth])


@pytest.mark.slow
def test_a_dense_cars_offline_states_stay_above_online_on_the_finer_grid(tmp_path):
    """Synthetic world seed 2 (20 frames, pandar64): its three moving cars hold a median of 3,060-3,310 points per
    frame. With fold shapes of 5 cm voxel centres the offline solve ends below the online pass on two of them
    (Acc 90.6 and 96.2 against 92.3 and 97.8, seed 0); on the 2.5 cm grid every one is above it."""
    sequence, source = _dense_world(tmp_path)
    config = get_preset("full", seed=0, **{"refinement.offline.dense_voxel": 0.025})
    coarse = get_preset("full", seed=0, **{"refinement.offline.dense_voxel": 0.0})
    below_on_coarse = 0
    for tid in ("veh_000", "veh_001", "veh_002"):
        lo, hi, truth, truth_boxes = _truth(sequence, tid)
        online = track(source, truth[0], lo, hi, config)
        assert np.median([e.num_points for e in online.estimates]) >= 500, tid   # dense: the finer grid applies
        on, fine = _acc(online, truth_boxes), _acc(refine_offline(source, online, config), truth_boxes)
        assert fine >= on, (tid, on, fine)
        below_on_coarse += _acc(refine_offline(source, online, coarse), truth_boxes) < on - 1.0
    assert below_on_coarse >= 1   # the cause: the coarse grid's centres put the solve below online


@pytest.mark.slow
def test_a_dense_cars_window_states_stay_with_online_on_the_finer_grid(tmp_path):
    """The same world: on its 10 cm grid the window (lag 10) ends below the online pass on all three cars (Acc 91.6,
    93.9, 92.7 against 92.3, 97.8, 93.6, seed 0); on the 2.5 cm grid for a median of >= 1,000 points it is above
    online on two and within 0.6 of it on the third, and above the coarse grid's on every one."""
    sequence, source = _dense_world(tmp_path)
    config = get_preset("full", seed=0, **{"refinement.lag.dense_voxel": 0.025, "refinement.lag.dense_points": 1000})
    coarse = get_preset("full", seed=0, **{"refinement.lag.dense_voxel": 0.0})
    below_on_coarse = 0
    for tid in ("veh_000", "veh_001", "veh_002"):
        lo, hi, truth, truth_boxes = _truth(sequence, tid)
        online = track(source, truth[0], lo, hi, config)
        assert np.median([e.num_points for e in online.estimates]) >= 1000, tid
        on = _acc(online, truth_boxes)
        fine = _acc(refine_fixed_lag(source, online, 10, config), truth_boxes)
        rough = _acc(refine_fixed_lag(source, online, 10, coarse), truth_boxes)
        assert fine >= on - 1.0 and fine > rough, (tid, on, fine, rough)
        below_on_coarse += rough < on - 1.0
    assert below_on_coarse >= 1


def test_a_sparse_cars_solve_keeps_the_coarse_grid():
    """A car of 300 points per frame (130-180 in its noisy online boxes, below ``dense_points`` 500): the dense
    grid's settings change nothing, bit for bit; with ``dense_points`` lowered to 100 the same frames are solved on
    the finer grid (other states)."""
    source, _, noisy = _scene()
    config = TrackerConfig()
    plain = refine_offline(source, _result(noisy), config, OFFLINE_PARAMS)
    dense = dataclasses.replace(OFFLINE_PARAMS, dense_voxel=0.025)
    same = refine_offline(source, _result(noisy), config, dense)
    assert all(np.array_equal(a.state.to_array(), b.state.to_array())
               for a, b in zip(plain.estimates, same.estimates, strict=True))
    assert np.array_equal(plain.shape, same.shape)
    finer = refine_offline(source, _result(noisy), config, dataclasses.replace(dense, dense_points=100))
    assert not all(np.array_equal(a.state.to_array(), b.state.to_array())
                   for a, b in zip(plain.estimates, finer.estimates, strict=True))


def test_the_dense_grid_settings_are_checked():
    with pytest.raises(ValueError, match="dense_voxel"):
        get_preset("full", **{"refinement.offline.dense_voxel": -0.01})
