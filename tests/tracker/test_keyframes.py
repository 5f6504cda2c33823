"""Keyframe-assisted tracks (tracker/keyframes.py) and the offline solve's anchors, on synthetic scenes with a known
truth: a braking car (the rigid car of ``tracker_synthetic``), analytic trajectories for the interpolations."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_offline import _scene
from tracker_synthetic import BOX_SIZE, SyntheticSequence, car_points, ground_points

from tracker.config import get_preset
from tracker.frames import LidarFrame
from tracker.geometry import Box, invert_transform, make_transform, transform_points
from tracker.keyframes import (
    KeyframeParams,
    interpolate_ctrv,
    interpolate_linear,
    keyframe_passes,
    keyframe_schedule,
    track_keyframes,
)
from tracker.metrics import iou_3d_batch, voxel_downsample_centres, voxel_downsample_means
from tracker.offline import Anchors, OfflineParams, refine_states


def _braking_car(n_frames: int = 26, speed: float = 1.5, decel: float = 0.1, seed: int = 0) -> SyntheticSequence:
    """A car driving at ``speed`` m/frame that brakes at ``decel`` m/frame^2 from frame 0 (stopped at frame 15),
    seen by a sensor 6 m to its side."""
    rng = np.random.default_rng(seed)
    boxes, frames = [], []
    x, y, heading, v = 12.0, 4.0, 0.3, speed
    for k in range(n_frames):
        box = Box(x, y, 0.0, heading, *BOX_SIZE)
        boxes.append(box)
        x, y, v = x + v * np.cos(heading), y + v * np.sin(heading), max(0.0, v - decel)
        world_from_ego = make_transform(np.eye(3), np.array([0.3 * k, -6.0, 1.0]))
        pts = np.vstack([car_points(rng, box, world_from_ego[:3, 3]), ground_points(rng, box.center[:2], 10.0)])
        pts += rng.normal(0.0, 0.01, pts.shape)
        ego = transform_points(invert_transform(world_from_ego), pts).astype(np.float32)
        frames.append(LidarFrame(k, 1_000_000_000 + k * 100_000_000, ego, world_from_ego))
    return SyntheticSequence(frames, boxes)


def _sparse_turn(n_frames: int = 21, rate: float = 0.01, per_m2: float = 2.0, seed: int = 0) -> SyntheticSequence:
    """A car on a constant turn (1 m and ``rate`` rad per frame) seen obliquely by a sensor ~14 m to its side that
    passes it, with few points (~40 a frame): CTRV interpolation between keyframes is exact, the points pin little."""
    rng = np.random.default_rng(seed)
    boxes, frames = [], []
    x, y, heading = 12.0, 4.0, 0.3
    for k in range(n_frames):
        box = Box(x, y, 0.0, heading, *BOX_SIZE)
        boxes.append(box)
        heading += rate
        x, y = x + np.cos(heading), y + np.sin(heading)
        world_from_ego = make_transform(np.eye(3), np.array([0.5 * k, -14.0, 1.0]))
        pts = np.vstack([car_points(rng, box, world_from_ego[:3, 3], per_m2=per_m2),
                         ground_points(rng, box.center[:2], 10.0)])
        pts += rng.normal(0.0, 0.01, pts.shape)
        ego = transform_points(invert_transform(world_from_ego), pts).astype(np.float32)
        frames.append(LidarFrame(k, 1_000_000_000 + k * 100_000_000, ego, world_from_ego))
    return SyntheticSequence(frames, boxes)


def _acc(boxes: dict[int, Box], truth: list[Box]) -> float:
    pred = np.array([boxes[k].to_array() for k in range(len(truth))])
    return float(iou_3d_batch(pred[1:], np.array([b.to_array() for b in truth])[1:]).mean())


@pytest.fixture(scope="module")
def braking():
    seq = _braking_car()
    keys = keyframe_schedule(0, len(seq) - 1, 20)   # 0, 20, 25
    keyframes = {k: seq.boxes[k] for k in keys}
    config = get_preset("full")
    passes = keyframe_passes(seq, keyframes, 0, len(seq) - 1, config)
    return seq, keyframes, config, passes


@pytest.fixture(scope="module")
def sparse_turn():
    seq = _sparse_turn()
    keyframes = {k: seq.boxes[k] for k in (0, len(seq) - 1)}
    config = get_preset("full")
    return seq, keyframes, config, keyframe_passes(seq, keyframes, 0, len(seq) - 1, config)


def test_schedule_closes_with_the_last_frame():
    assert keyframe_schedule(0, 39, 20) == [0, 20, 39]
    assert keyframe_schedule(0, 39, 40) == [0, 39]
    assert keyframe_schedule(5, 9, 2) == [5, 7, 9]


def test_keyframes_beat_interpolation_on_a_braking_car(braking):
    seq, keyframes, config, passes = braking
    frames = list(range(len(seq)))
    linear = _acc(interpolate_linear(frames, keyframes), seq.boxes)
    ctrv = _acc(interpolate_ctrv(frames, keyframes), seq.boxes)
    result = track_keyframes(seq, keyframes, config=config, passes=passes)
    tracked = _acc({e.frame: e.box for e in result.estimates}, seq.boxes)
    # linear interpolation puts the car where constant speed would: far behind while it brakes
    assert linear < 0.6 and ctrv < 0.6
    assert tracked > linear + 0.25 and tracked > 0.85
    assert result.mode == "offline" and [e.frame for e in result.estimates] == frames


def test_keyframe_boxes_are_reproduced_exactly(braking):
    seq, keyframes, config, passes = braking
    for params in (KeyframeParams(), KeyframeParams(refine=False), KeyframeParams(backward=False, refine=False)):
        result = track_keyframes(seq, keyframes, config=config, params=params, passes=passes)
        got = {e.frame: e for e in result.estimates}
        for k, box in keyframes.items():
            assert got[k].box == box and "keyframe" in got[k].flags   # dataclass equality: every field, bit for bit


def test_keyframes_are_no_worse_than_interpolation_on_a_sparse_smooth_drive(sparse_turn):
    """Where the motion is smooth and the points are few, the solve keeps to the arc between the keyframes (a firm
    pull on frames with few points; fold shapes of voxel means, in the box grown by a margin) instead of turning and
    shifting the frames by the shape's errors."""
    seq, keyframes, config, passes = sparse_turn
    frames = list(range(len(seq)))
    linear = _acc(interpolate_linear(frames, keyframes), seq.boxes)
    ctrv = _acc(interpolate_ctrv(frames, keyframes), seq.boxes)
    tracked = _acc({e.frame: e.box for e in track_keyframes(seq, keyframes, config=config, passes=passes).estimates},
                   seq.boxes)
    assert ctrv > 0.999 and linear < 0.95   # the arc is exact, the chord is not
    assert tracked >= linear and tracked >= ctrv - 0.025   # the solve as it was (voxel centres, no pull): 0.949


def test_soft_keyframes_stay_near_their_boxes(braking):
    seq, keyframes, config, passes = braking
    result = track_keyframes(seq, keyframes, config=config, params=KeyframeParams(sigma_xyz=0.02), passes=passes)
    for e in result.estimates:
        if e.frame in keyframes:
            assert np.linalg.norm(e.box.center - keyframes[e.frame].center) < 0.1


def test_linear_interpolation_is_exact_at_constant_velocity():
    truth = [Box(1.0 + 0.8 * k, -2.0 + 0.3 * k, 0.5, 0.36, 4.5, 1.8, 1.5) for k in range(21)]
    boxes = interpolate_linear(list(range(21)), {0: truth[0], 20: truth[20]})
    assert max(np.abs(boxes[k].to_array() - truth[k].to_array()).max() for k in range(21)) < 1e-9


def test_ctrv_interpolation_is_exact_on_a_constant_turn():
    radius, rate = 15.0, 0.04   # rad per frame
    truth = []
    for k in range(21):
        heading = 0.2 + rate * k
        truth.append(Box(radius * np.sin(heading), -radius * np.cos(heading), 0.5, heading, 4.5, 1.8, 1.5))
    ctrv = interpolate_ctrv(list(range(21)), {0: truth[0], 20: truth[20]})
    linear = interpolate_linear(list(range(21)), {0: truth[0], 20: truth[20]})
    assert max(np.linalg.norm(ctrv[k].center - truth[k].center) for k in range(21)) < 1e-9
    assert max(np.linalg.norm(linear[k].center - truth[k].center) for k in range(21)) > 0.5   # the chord cuts the arc


def test_hard_anchor_at_the_first_frame_is_the_fix_first_gauge():
    source, truth, online = _scene(0, 20)
    points = [source.lidar_frame(k).points_world() for k in range(len(truth))]
    points = [p[np.abs(p[:, 2] - 0.8) < 0.7] for p in points]   # the box's points (the ground sits at z 0)
    size = np.array([4.5, 1.9, 1.5])
    fix_first, _ = refine_states(points, online, size, dataclasses.replace(OfflineParams(), gauge="fix_first"))
    anchored, _ = refine_states(points, online, size, OfflineParams(), anchors=Anchors(np.array([0]), online[:1]))
    np.testing.assert_array_equal(fix_first, anchored)


def test_hard_anchors_are_held_and_pull_the_frames_between():
    source, truth, online = _scene(1, 20)
    points = [source.lidar_frame(k).points_world() for k in range(len(truth))]
    points = [p[np.abs(p[:, 2] - 0.8) < 0.7] for p in points]
    size = np.array([4.5, 1.9, 1.5])
    frames = np.array([0, 10, 19])
    states, _ = refine_states(points, online, size, OfflineParams(), anchors=Anchors(frames, truth[frames]))
    np.testing.assert_array_equal(states[frames, :3], truth[frames, :3])
    np.testing.assert_allclose(states[frames, 3], truth[frames, 3], atol=1e-12)
    assert np.abs(states[:, :2] - truth[:, :2]).max() < 0.05


def test_per_frame_pulls_hold_their_frames():
    """Anchors.pull: a frame with a tight pull stays at its online state; the others follow the points."""
    source, truth, online = _scene(1, 20)
    points = [source.lidar_frame(k).points_world() for k in range(len(truth))]
    points = [p[np.abs(p[:, 2] - 0.8) < 0.7] for p in points]
    size = np.array([4.5, 1.9, 1.5])
    frames = np.array([0, 19])
    pull = np.tile([1.0, 1.0, 1.0, 0.3], (len(truth), 1))
    pull[10] = [1e-4, 1e-4, 1e-4, 1e-5]
    free, _ = refine_states(points, online, size, OfflineParams(), anchors=Anchors(frames, truth[frames]))
    held, _ = refine_states(points, online, size, OfflineParams(), anchors=Anchors(frames, truth[frames], pull=pull))
    assert np.abs(held[10, :3] - online[10, :3]).max() < 0.01
    assert np.linalg.norm(free[10, :2] - truth[10, :2]) < 0.05 < np.linalg.norm(online[10, :2] - truth[10, :2])
    assert np.abs(held[5, :2] - truth[5, :2]).max() < 0.1


def test_voxel_means_keep_a_surface_off_the_grid():
    """A plane at x = 0.0123: voxel centres put it at 0.025, voxel means where it is."""
    rng = np.random.default_rng(0)
    plane = np.c_[np.full(500, 0.0123), rng.uniform(-1, 1, (500, 2))]
    np.testing.assert_allclose(voxel_downsample_means(plane, 0.05)[:, 0], 0.0123)
    np.testing.assert_allclose(voxel_downsample_centres(plane, 0.05)[:, 0], 0.025)
    assert len(voxel_downsample_means(plane, 0.05)) == len(voxel_downsample_centres(plane, 0.05))
