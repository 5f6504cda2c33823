"""The sub-shape (tracker/shape.py ``SubShape``): the last frames' object points, and ``shape.subshape_hold``, which
leaves out the points of the frames after a coast (the box that placed them was placed by the coast) when the shape
holds ``shape.subshape_hold_shape`` points or more."""

from __future__ import annotations

import numpy as np
import pytest
from test_reacquire_clusters import REACQUIRE, _scene, _straight

from tracker import get_preset, track
from tracker.config import ShapeConfig
from tracker.shape import ShapeModel, SubShape
from tracker.sotracker import _hold_frames


def _frame(x: float) -> np.ndarray:
    """Object-frame points of one frame, all at along-position ``x`` (one per 0.2 m voxel across)."""
    return np.c_[np.full(5, x), np.arange(5) * 0.2, np.zeros(5)]


def _frames_in(sub: SubShape) -> list[float]:
    """The along-positions of the frames ``sub`` holds (its points are voxel centres, within half a voxel)."""
    return sorted({float(x) for x in np.round(sub.points[:, 0])})


def test_a_held_sub_shape_takes_no_points_while_its_older_frames_drop_out():
    sub = SubShape(2, 0.05)
    sub.add(_frame(1.0))
    sub.add(_frame(2.0))
    assert _frames_in(sub) == [1.0, 2.0]
    sub.hold(2)
    sub.add(_frame(3.0))                        # held: left out, frame 1.0 drops out
    assert _frames_in(sub) == [2.0]
    sub.add(_frame(4.0))                        # held: left out, frame 2.0 drops out
    assert len(sub.points) == 0
    sub.add(_frame(5.0))
    assert _frames_in(sub) == [5.0]


def test_a_held_sub_shape_takes_a_dense_frame():
    """``hold(frames, dense)``: a frame of ``dense`` points or more is taken while held, a sparser one is not."""
    sub = SubShape(3, 0.05)
    sub.hold(3, dense=5)
    sub.add(_frame(1.0)[:4])                    # 4 points: left out
    sub.add(_frame(2.0))                        # 5 points: taken
    sub.add(_frame(3.0)[:2])                    # left out
    sub.add(_frame(4.0)[:2])                    # no longer held: taken
    assert _frames_in(sub) == [2.0, 4.0]


def test_the_sub_shape_leaves_out_the_frames_after_a_coast():
    """A car hidden for 5 frames (coasting from the 2nd hidden frame on): with ``subshape_hold=5`` the sub-shape is
    empty for the 5 frames from the last coasting frame on (that one included) and fills again after them; without
    the hold it holds the car's points from the first frame the car is seen again. Before the car is hidden the
    sub-shapes are the same."""
    boxes = _straight(22, (10.0, 4.0), 0.0, 1.0)
    seq = _scene(boxes, 0, hidden=range(8, 13))

    def sizes(hold: int) -> tuple[np.ndarray, np.ndarray]:
        counts: list[int] = []
        result = track(seq, boxes[0], 0, len(seq) - 1, get_preset("full", seed=0, **REACQUIRE, **{
            "shape.subshape_hold": hold}), on_frame=lambda tracker, _: counts.append(len(tracker.subshape.points)))
        coasting = np.array(["coasting" in e.flags or "prior_only" in e.flags for e in result.estimates])
        return np.array(counts), coasting

    held, coasting = sizes(5)
    free, coasting_free = sizes(0)
    assert np.array_equal(coasting, coasting_free)
    last = int(np.flatnonzero(coasting).max())
    assert last == 12 and np.all(held[last: last + 5] == 0) and np.all(held[last + 5:] > 0)
    assert np.all(free[last + 1:] > 0)
    assert np.all(held[:8] == free[:8])


def test_the_hold_is_checked():
    for bad in ({"subshape_hold": -1}, {"subshape_hold_shape": -1}, {"subshape_hold_dense": -1}):
        with pytest.raises(ValueError, match="shape.subshape_hold"):
            ShapeConfig(**bad)


def test_a_sparse_objects_sub_shape_is_not_held():
    """A shape of fewer than ``subshape_hold_shape`` points cannot place the box after a coast: its sub-shape, the
    sparse object's recent points, is kept."""
    config = ShapeConfig(subshape_hold=5, subshape_hold_shape=100)
    sparse, dense = ShapeModel(0.05), ShapeModel(0.05)
    sparse.add(np.c_[np.arange(40) * 0.1, np.zeros((40, 2))])
    dense.add(np.c_[np.arange(400) * 0.1, np.zeros((400, 2))])
    assert len(sparse.points) == 40 and len(dense.points) == 400
    assert _hold_frames(config, sparse) == 0 and _hold_frames(config, dense) == 5
