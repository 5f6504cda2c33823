"""The float32 pre-cuts over whole sweeps (LiDAR occluders in the camera view, points near a track's box) keep every
point the exact float64 tests keep: the results equal those of the tests run on all points."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sot_apps.flow.annotate import _lidar_occluders
from sot_apps.flow.camera import CameraModel
from sot_apps.flow.objects import objects_from_tracks
from sot_apps.flow.occlusion import project_lidar
from sot_apps.io.object_track import ObjectTrack
from sot_apps.io.sequence import FrameInfo, Sequence, Sweep
from sot_apps.io.tracks import TrackHeader, write_track
from tracker.geometry import Box, invert_transform, make_transform, points_in_box, transform_points

K = np.array([[1970.0, 0.0, 960.0], [0.0, 1970.0, 540.0], [0.0, 0.0, 1.0]])
MODEL = CameraModel(K, np.zeros(5), 1920, 1080)


def _rotation(yaw: float, pitch: float = 0.0) -> np.ndarray:
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    return np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]]) @ np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])


WORLD_FROM_EGO = make_transform(_rotation(2.3), np.array([4567.25, -1234.5, 12.0]))   # far from the origin
EGO_FROM_CAMERA = make_transform(np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]), [1.2, 0.1, 1.6])


def _sequence(points_ego: np.ndarray, offsets: np.ndarray | None = None) -> Sequence:
    frames = [FrameInfo(0, 1_000_000_000, WORLD_FROM_EGO, Path("none"))]
    return Sequence("s", Path("."), "test", frames, lambda k: Sweep(points_ego.astype(np.float32), None, offsets))


def _border_points(rng: np.random.Generator) -> np.ndarray:
    """Ego points all around the car plus many right at the view cut: depth 0.5 m and the image +- 480 px."""
    spread = rng.uniform([-80, -80, -3], [80, 80, 5], (20_000, 3))
    camera_from_ego = invert_transform(EGO_FROM_CAMERA)
    slack = 0.25 * 1920
    z = np.r_[rng.uniform(0.49, 0.51, 3000), rng.uniform(0.5, 60.0, 6000)]
    u = np.r_[rng.uniform(-slack - 2, 1920 + slack + 2, 3000),
              rng.choice([-slack, 1920 + slack], 6000) + rng.uniform(-1e-3, 1e-3, 6000)]
    v = np.r_[rng.uniform(-slack - 2, 1080 + slack + 2, 3000), rng.uniform(-slack - 2, 1080 + slack + 2, 6000)]
    cam = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], axis=1)
    near_border = transform_points(invert_transform(camera_from_ego), cam)
    return np.concatenate([spread, near_border])


def test_lidar_occluders_equal_the_view_cut_over_every_point():
    points_ego = _border_points(np.random.default_rng(3)).astype(np.float32)
    seq = _sequence(points_ego)
    world_from_camera = WORLD_FROM_EGO @ EGO_FROM_CAMERA
    camera_from_world = invert_transform(world_from_camera)
    got = _lidar_occluders(seq, 0, [], camera_from_world, MODEL, 0.4)
    # the straightforward cut: every point to the world and the camera in float64, then the same view test
    world = transform_points(WORLD_FROM_EGO, points_ego)
    cam = transform_points(camera_from_world, world)
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = cam[:, :2] / cam[:, 2:3] * np.diag(K)[:2] + K[:2, 2]
    slack = 0.25 * 1920
    view = ((cam[:, 2] > 0.5) & (uv[:, 0] > -slack) & (uv[:, 0] < 1920 + slack) & (uv[:, 1] > -slack)
            & (uv[:, 1] < 1080 + slack))
    want = project_lidar(world[view], camera_from_world, MODEL)
    assert len(want.depth) > 1000
    for a, b in ((got.uv, want.uv), (got.depth, want.depth), (got.world_z, want.world_z)):
        np.testing.assert_array_equal(a, b)


def test_restamped_box_times_equal_the_box_test_over_every_point(tmp_path):
    rng = np.random.default_rng(4)
    box = Box(4580.0, -1240.0, 13.0, 0.7, 4.5, 2.0, 1.6)
    # points on the box faces +- 1 mm (inside and outside), plus the rest of the sweep
    local = rng.uniform(-0.5, 0.5, (4000, 3)) * box.size
    axis = rng.integers(0, 3, 4000)
    local[np.arange(4000), axis] = np.sign(local[np.arange(4000), axis]) * (box.size[axis] / 2 + rng.uniform(-1e-3, 1e-3, 4000))
    world = transform_points(box.world_from_object(), local)
    ego = np.concatenate([transform_points(invert_transform(WORLD_FROM_EGO), world), rng.uniform(-60, 60, (30_000, 3))])
    offsets = rng.integers(-100_000_000, 0, len(ego))
    seq = _sequence(ego, offsets)
    track = ObjectTrack.from_states("car", "", (4.5, 2.0, 1.6), [0], [1_000_000_000], [box.to_array()[:4]], None,
                                    scores=[0.9], num_points=[100], shape_points=rng.uniform(-1, 1, (50, 3)))
    write_track(tmp_path / "car", TrackHeader("s", 0, 0, box, {"preset": "test"}), track)
    [stamped] = objects_from_tracks([tmp_path / "car"], box_time="points", seq=seq)
    inside = points_in_box(transform_points(WORLD_FROM_EGO, ego.astype(np.float32)), box)
    assert 1000 < inside.sum() < 4000
    assert stamped.trajectory.times_ns[0] == 1_000_000_000 + int(np.median(offsets[inside]))


def test_a_frame_without_points_has_no_lidar_occluders():
    seq = _sequence(np.zeros((0, 3)))
    got = _lidar_occluders(seq, 0, [], invert_transform(WORLD_FROM_EGO @ EGO_FROM_CAMERA), MODEL, 0.4)
    assert len(got.uv) == len(got.depth) == len(got.world_z) == 0
