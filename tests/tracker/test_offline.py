"""Offline refinement and pseudo-ground-truth shapes on synthetic scenes with a known truth (numpy only)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from tracker.config import TrackerConfig
from tracker.frames import LidarFrame
from tracker.geometry import Box, State
from tracker.metrics import centre_errors_batch, iou_3d_batch
from tracker.offline import OfflineParams, refine_offline
from tracker.pseudo_gt import mean_points_in_boxes, pseudo_gt_shape
from tracker.sotracker import FrameEstimate, TrackResult

L, W, H = 4.5, 1.9, 1.5


def _surface(rng: np.random.Generator, n: int) -> np.ndarray:
    """Object-frame points on the four sides of the box and on a roof patch set back from the front."""
    face = rng.integers(0, 5, n)
    u, v = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
    pts = np.empty((n, 3))
    pts[:, 0] = np.select([face == 0, face == 1, face == 4], [L / 2, -L / 2, u * L / 4 - 0.5], u * L / 2)
    pts[:, 1] = np.select([face == 2, face == 3], [W / 2, -W / 2], v * W / 2)
    pts[:, 2] = np.where(face == 4, H / 2, v * H / 2)
    pts[face < 2, 1] = u[face < 2] * W / 2
    return pts


class _Source:
    def __init__(self, frames: list[LidarFrame]) -> None:
        self.frames = frames

    def __len__(self) -> int:
        return len(self.frames)

    def lidar_frame(self, index: int) -> LidarFrame:
        return self.frames[index]


def _scene(seed: int = 0, n_frames: int = 30):
    """A box driving straight at 1 m/frame, then turning at 0.04 rad/frame, over a flat ground plane.

    Returns the source (ego = world), the true states (K, 4) and a noisy 'online' trajectory."""
    rng = np.random.default_rng(seed)
    truth = np.zeros((n_frames, 4))
    truth[0] = [10.0, 5.0, H / 2, 0.3]
    for k in range(1, n_frames):
        heading = truth[k - 1, 3] + (0.04 if k > n_frames // 2 else 0.0)
        truth[k] = [truth[k - 1, 0] + np.cos(heading), truth[k - 1, 1] + np.sin(heading), H / 2, heading]
    frames = []
    for k, s in enumerate(truth):
        obj = _surface(rng, 300) + rng.normal(0.0, 0.01, (300, 3))
        c, si = np.cos(s[3]), np.sin(s[3])
        world = obj @ np.array([[c, -si, 0.0], [si, c, 0.0], [0.0, 0.0, 1.0]]).T + s[:3]
        ground = np.c_[rng.uniform(s[0] - 15, s[0] + 15, 3000), rng.uniform(s[1] - 15, s[1] + 15, 3000),
                       rng.normal(0.0, 0.02, 3000)]
        frames.append(LidarFrame(k, k * 100_000_000, np.vstack([world, ground]).astype(np.float32), np.eye(4)))
    return _Source(frames), truth, _perturbed(rng, truth, 0.15, 0.05, 0.04)


def _perturbed(rng: np.random.Generator, truth: np.ndarray, sigma_xy: float, sigma_z: float,
               sigma_heading: float) -> np.ndarray:
    """``truth`` (N, 4) with Gaussian noise on frames 1.. (frame 0 exact), drawn xy, z, heading in that order."""
    noisy = truth.copy()
    n = len(truth) - 1
    noisy[1:, :2] += rng.normal(0.0, sigma_xy, (n, 2))
    noisy[1:, 2] += rng.normal(0.0, sigma_z, n)
    noisy[1:, 3] += rng.normal(0.0, sigma_heading, n)
    return noisy


def _result(states: np.ndarray) -> TrackResult:
    estimates = [FrameEstimate(k, State.from_array(s), Box(*s, L, W, H), 0, 1.0, (), 1.0, np.zeros((0, 3)))
                 for k, s in enumerate(states)]
    return TrackResult(estimates, np.array([L, W, H]), np.zeros((0, 3)), TrackerConfig())


def _distance_to_surface(points: np.ndarray) -> np.ndarray:
    """Distance of object-frame points to a dense sample of the true surface (one-sided: the shapes
    are sparse and have no points in the lowest 0.3 m, which ground removal takes with the road)."""
    dense = _surface(np.random.default_rng(123), 100_000)
    return cKDTree(dense).query(points)[0]


def _boxes(states: np.ndarray) -> np.ndarray:
    return np.c_[states, np.tile([L, W, H], (len(states), 1))]


def test_offline_refinement_recovers_a_noisy_trajectory():
    source, truth, noisy = _scene()
    refined = refine_offline(source, _result(noisy), TrackerConfig(), OfflineParams())
    out = np.array([b.to_array() for b in refined.boxes])
    gt = _boxes(truth)
    before_ce = centre_errors_batch(_boxes(noisy)[1:], gt[1:]).mean()
    after_ce = centre_errors_batch(out[1:], gt[1:]).mean()
    before_iou = iou_3d_batch(_boxes(noisy)[1:], gt[1:]).mean()
    after_iou = iou_3d_batch(out[1:], gt[1:]).mean()
    heading_err = np.abs(np.angle(np.exp(1j * (out[1:, 3] - truth[1:, 3]))))
    assert before_ce > 0.15 and before_iou < 0.85          # the input really is noisy
    assert after_ce < 0.05                                  # points are 1 cm noisy: cm-level recovery
    assert after_iou > 0.93
    assert np.degrees(heading_err).mean() < 0.5
    np.testing.assert_allclose(out[0], gt[0], atol=1e-9)    # the start box is kept exactly
    assert all("offline" in e.flags for e in refined.estimates)
    # the rebuilt shape lies on the true object-frame surface (voxel centres: <= 4.3 cm off)
    assert np.median(_distance_to_surface(refined.shape)) < 0.03
    assert np.mean(_distance_to_surface(refined.shape) < 0.06) > 0.95


def test_offline_refinement_is_deterministic_and_keeps_a_good_trajectory():
    source, truth, _ = _scene(seed=3, n_frames=20)
    a = refine_offline(source, _result(truth), TrackerConfig(), OfflineParams(outer_iterations=2))
    b = refine_offline(source, _result(truth), TrackerConfig(), OfflineParams(outer_iterations=2))
    sa = np.array([e.state.to_array() for e in a.estimates])
    np.testing.assert_array_equal(sa, np.array([e.state.to_array() for e in b.estimates]))
    assert centre_errors_batch(_boxes(sa), _boxes(truth)).max() < 0.05


def test_pseudo_gt_shape_removes_ground_and_uses_object_frame():
    source, truth, _ = _scene(seed=5, n_frames=6)
    boxes = [Box(*s, L, W, H) for s in truth]
    shape = pseudo_gt_shape(source, range(6), boxes)
    assert len(shape) > 500
    # object frame: every point within the box (voxel centres may sit half a voxel outside)
    assert np.all(np.abs(shape) <= np.array([L, W, H]) / 2 + 0.05)
    # no ground: the ground is 0.75 m below the box centre, i.e. at its bottom face; GPF removes it
    bottom = shape[:, 2] < -H / 2 + 0.1
    assert bottom.mean() < 0.05
    assert np.median(_distance_to_surface(shape)) < 0.03
    assert np.mean(_distance_to_surface(shape) < 0.06) > 0.95
    # boxes grown by 20 %: all 300 object points plus the ground under the box (~3.3 points/m^2 x 12.3 m^2)
    counts = mean_points_in_boxes(source, range(2), [b.scaled(1.2) for b in boxes[:2]])
    assert 320 <= counts <= 370


@pytest.mark.parametrize("gauge", ["regauge", "fix_first"])
def test_gauges_keep_start_box(gauge):
    source, truth, noisy = _scene(seed=7, n_frames=12)
    refined = refine_offline(source, _result(noisy), TrackerConfig(), OfflineParams(gauge=gauge, outer_iterations=2))
    np.testing.assert_allclose(refined.estimates[0].state.to_array(), truth[0], atol=1e-9)
