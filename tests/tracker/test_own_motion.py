"""The object's own motion during a sweep taken out of its points (tracker/own_motion.py): analytic cases, and a car
sliding into the seam tracked online and in the fixed-lag window."""

from __future__ import annotations

import numpy as np
import pytest
from tracker_synthetic import BOX_SIZE, SyntheticSequence, car_points, ground_points

from tracker import Box, get_preset, refine_fixed_lag, track
from tracker.frames import LidarFrame
from tracker.geometry import invert_transform, make_transform, transform_points
from tracker.own_motion import RegionTimes, compensate_track, own_motion_compensated, track_velocities


def _car_surface(rng: np.random.Generator, n: int = 400) -> np.ndarray:
    """Points on the front face and both sides of a 4.5 x 1.8 x 1.5 m car centred at the origin, heading +x."""
    face = np.c_[np.full(n // 2, 2.25), rng.uniform(-0.9, 0.9, n // 2), rng.uniform(-0.7, 0.7, n // 2)]
    side = np.c_[rng.uniform(-2.2, 2.2, n // 2), np.where(rng.random(n // 2) < 0.5, -0.9, 0.9),
                 rng.uniform(-0.7, 0.7, n // 2)]
    return np.vstack([face, side])


@pytest.mark.parametrize("heading", [0.0, 0.7, -2.5])
def test_a_car_split_by_the_seam_is_put_back_together(heading):
    """Its left part hit 100 ms before the rest while it drives at 8 m/s: 0.8 m of shear along its travel.
    With its velocity, every point goes to where the car was at the median capture time (the later part's, as
    most returns are later), exactly."""
    rng = np.random.default_rng(0)
    local = _car_surface(rng)
    c, s = np.cos(heading), np.sin(heading)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    centre = np.array([12.0, -3.0, 0.75])
    velocity = 8.0 * np.array([c, s])
    offsets = np.where(local[:, 1] > 0.3, -100_000_000, 0).astype(np.int64)   # ns: the left part first
    assert 0.3 < np.mean(offsets < 0) < 0.45
    truth = local @ rot.T + centre                       # the car at time 0
    seen = truth.copy()
    seen[:, :2] += velocity[None] * (offsets * 1e-9)[:, None]   # where each point was hit
    box = Box(*centre, heading, 4.6, 1.9, 1.5)          # the face on its edge would be in or out by rounding
    moved = own_motion_compensated(seen, offsets, box, velocity, 0.05)
    np.testing.assert_allclose(moved, truth, atol=1e-12)
    # the sheared face is square to the heading again: its points' along-track spread is gone
    front = local[:, 0] == 2.25
    along = (moved[front, :2] - centre[:2]) @ np.array([c, s])
    assert np.ptp(along) < 1e-9 < np.ptp((seen[front, :2] - centre[:2]) @ np.array([c, s]))


def test_returns_within_the_spread_are_left_as_they_are():
    """A car hit within 20 ms (not at the seam): the very same array, so tracks away from the seam are unchanged."""
    rng = np.random.default_rng(1)
    points = _car_surface(rng) + [5.0, 5.0, 0.75]
    offsets = rng.integers(-20_000_000, 0, len(points))
    box = Box(5.0, 5.0, 0.75, 0.0, 4.5, 1.8, 1.5)
    assert own_motion_compensated(points, offsets, box, np.array([8.0, 0.0]), 0.05) is points
    assert own_motion_compensated(points, offsets, box, np.array([8.0, 0.0]), 0.0) is points   # off
    far = Box(50.0, 5.0, 0.75, 0.0, 4.5, 1.8, 1.5)                                             # no returns
    assert own_motion_compensated(points, offsets * 10, far, np.array([8.0, 0.0]), 0.05) is points


def test_track_velocities_are_central_differences_over_the_timestamps():
    t = np.array([0, 100, 200, 350, 450]) * 1_000_000               # ns; one frame 150 ms
    x = np.array([0.0, 1.0, 2.5, 4.0, 5.0])
    boxes = [Box(xi, 2.0 * xi, 0.0, 0.0, 4.0, 2.0, 1.5) for xi in x]
    v = track_velocities(boxes, t)
    assert v.shape == (5, 2)
    np.testing.assert_allclose(v[:, 0], [10.0, 12.5, 3.0 / 0.25, 2.5 / 0.25, 10.0])
    np.testing.assert_allclose(v[:, 1], 2.0 * v[:, 0])
    assert np.array_equal(track_velocities(boxes[:1], t[:1]), np.zeros((1, 2)))


def test_compensate_track_moves_only_frames_with_times():
    rng = np.random.default_rng(2)
    boxes = [Box(0.8 * k, 0.0, 0.75, 0.0, 4.5, 1.8, 1.5) for k in range(3)]
    points = [_car_surface(rng) + [0.8 * k, 0.0, 0.75] for k in range(3)]
    seam = np.where(points[1][:, 1] > 0, -100_000_000, 0)
    times = [RegionTimes(0, np.zeros(len(points[0]), dtype=np.int64)), RegionTimes(100_000_000, seam), None]
    out = compensate_track(points, times, boxes, 0.05)
    assert out[0] is points[0] and out[2] is points[2]              # within the spread; no times
    shift = out[1] - points[1]
    assert np.allclose(shift[:, 1:], 0.0) and np.ptp(shift[:, 0]) == pytest.approx(0.8)   # 8 m/s x 0.1 s
    assert compensate_track(points, times, boxes, 0.0) is points


def _car_drifting_into_the_seam(n: int = 20, speed: float = 8.0) -> SyntheticSequence:
    """A car following the ego 14 m behind at 8 m/s while the ego drifts sideways (0.3 m a frame, 10 frames), so
    the car slides into the sweep's seam (the line behind the sensor): its returns on the far side of the seam are
    hit 100 ms before the others, and the box is where the car was at their median capture time (as the synthetic
    world and PandaSet annotate)."""
    rng = np.random.default_rng(0)
    boxes, frames = [], []
    for k in range(n):
        ego_y = -3.0 + min(k, 10) * 0.3
        world_from_ego = make_transform(np.eye(3), np.array([speed * 0.1 * k, ego_y, 1.0]))
        box = Box(-14.0 + speed * 0.1 * k, 0.0, 0.0, 0.0, *BOX_SIZE)
        car = car_points(rng, box, world_from_ego[:3, 3])
        hit = np.where(car[:, 1] > ego_y, -0.1, 0.0)              # s, relative to the frame's end
        car[:, 0] += speed * (hit - np.median(hit))
        ground = ground_points(rng, box.center[:2], 12.0)
        points = np.vstack([car, ground]) + rng.normal(0.0, 0.01, (len(car) + len(ground), 3))
        offsets = np.r_[np.round(hit * 1e9), np.zeros(len(ground))].astype(np.int64)
        frames.append(LidarFrame(index=k, timestamp_ns=1_000_000_000 + k * 100_000_000,
                                 points_ego=transform_points(invert_transform(world_from_ego), points).astype(np.float32),
                                 world_from_ego=world_from_ego, point_time_offset_ns=offsets))
        boxes.append(box)
    return SyntheticSequence(frames, boxes)


def test_online_and_window_hold_the_heading_of_a_car_sliding_into_the_seam():
    """The sheared face turns the box online (and the window after it) unless the step takes the car's own motion
    out at its predicted velocity (search.own_motion_spread) and the window at its states' velocities
    (refinement.lag.own_motion_spread)."""
    seq = _car_drifting_into_the_seam()
    worst = {}
    for name, sets in (("captured", {"search.own_motion_spread": 0.0, "refinement.lag.own_motion_spread": 0.0}),
                       ("taken_out", {"search.own_motion_spread": 0.05, "refinement.lag.own_motion_spread": 0.05})):
        config = get_preset("full", **sets)
        online = track(seq, seq.boxes[0], 0, len(seq) - 1, config)
        lag = refine_fixed_lag(seq, online, 10, config)
        for mode, result in (("online", online), ("lag", lag)):
            worst[name, mode] = max(abs(np.degrees(e.box.heading)) for e in result.estimates)
            centre = max(np.hypot(*(e.box.center[:2] - b.center[:2])) for e, b in zip(result.estimates, seq.boxes, strict=True))
            assert centre < 0.2, (name, mode, centre)
    assert worst["taken_out", "online"] < 1.5 and worst["taken_out", "lag"] < 1.0, worst
    assert worst["captured", "online"] > 5.0 and worst["captured", "lag"] > 3.0, worst
