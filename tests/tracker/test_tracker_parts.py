"""The tracker's parts against independent truth: Jacobians vs finite differences, ground removal on a
sloped scene with sub-ground noise, RANSAC with outliers, de-skewing, shape aggregation, config."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tracker.association import fit_rigid_2d, ransac_rigid_2d
from tracker.config import PRESETS, TrackerConfig, get_preset
from tracker.geometry import make_transform, rotation_z, transform_points
from tracker.ground import GroundParams, ground_mask
from tracker.metrics import voxel_downsample_centres
from tracker.motion import MotionPrior
from tracker.shape import ShapeModel
from tracker.sotracker import deskew_points
from tracker.terms import apply_motion, motion_consistency_block, motion_prior_block, point_pair_block


def _numeric_jacobian(fn, x, eps=1e-6):
    base = fn(x)
    cols = []
    for i in range(len(x)):
        step = np.zeros_like(x)
        step[i] = eps
        cols.append((fn(x + step) - fn(x - step)) / (2 * eps))
    return np.stack(cols, axis=1), base


@pytest.mark.parametrize("with_normals", [False, True])
def test_point_pair_jacobian_matches_finite_differences(with_normals):
    rng = np.random.default_rng(0)
    src = rng.normal(size=(30, 3)) + [10.0, -4.0, 0.5]
    dst = src + rng.normal(scale=0.1, size=src.shape)
    pivot = np.array([10.2, -3.9, 0.4])
    normals = None
    if with_normals:
        normals = rng.normal(size=(30, 3))
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        normals[::5] = 0.0  # pairs without a normal
    x = np.array([0.3, -0.2, 0.05, 0.12])
    block = point_pair_block("icp", x, src, dst, pivot, 1.0, normals, 0.1)
    numeric, residuals = _numeric_jacobian(
        lambda xx: point_pair_block("icp", xx, src, dst, pivot, 1.0, normals, 0.1).residuals, x)
    np.testing.assert_allclose(block.residuals, residuals)
    np.testing.assert_allclose(block.jacobian, numeric, atol=1e-6)
    # the loss (closed form from the pairs' sums without normals, PairMoments) is the weighted sum of squares
    assert block.loss == pytest.approx(block.weight * float(residuals @ residuals), rel=1e-10)
    if block.normal_equations is not None:  # the closed-form normal equations the solver uses
        hessian, gradient = block.normal_equations
        np.testing.assert_allclose(hessian, block.jacobian.T @ block.jacobian, atol=1e-9)
        np.testing.assert_allclose(gradient, block.jacobian.T @ block.residuals, atol=1e-9)


def test_apply_motion_rotates_about_the_pivot_then_translates():
    pivot = np.array([5.0, 2.0, 0.0])
    pts = np.array([[6.0, 2.0, 1.0]])
    moved = apply_motion(np.array([1.0, 0.0, 0.5, np.pi / 2]), pts, pivot)
    np.testing.assert_allclose(moved, [[6.0, 3.0, 1.5]], atol=1e-12)


@pytest.mark.parametrize("symmetric", [False, True])
@pytest.mark.parametrize("heading", [0.3, 2.5, -1.2])
def test_motion_consistency_jacobian_matches_finite_differences(symmetric, heading):
    x = np.array([0.8, -0.35, 0.02, 0.07])
    block = motion_consistency_block(x, heading, 0.1, symmetric)
    numeric, residuals = _numeric_jacobian(lambda xx: motion_consistency_block(xx, heading, 0.1, symmetric).residuals, x)
    np.testing.assert_allclose(block.residuals, residuals)
    np.testing.assert_allclose(block.jacobian, numeric, atol=1e-6)
    # moving along the mean heading costs nothing
    along = np.array([np.cos(heading + 0.05), np.sin(heading + 0.05), 0.0, 0.1])
    assert motion_consistency_block(along, heading, 0.1, symmetric).loss < 1e-20


def test_motion_prior_block():
    ref = np.array([1.0, 2.0, 3.0, 0.1])
    x = np.array([1.5, 2.0, 2.0, 0.0])
    block = motion_prior_block(x, ref, 0.1)
    assert block.loss == pytest.approx(0.1 * (0.25 + 1.0 + 0.01))
    numeric, _ = _numeric_jacobian(lambda xx: motion_prior_block(xx, ref, 0.1).residuals, x)
    np.testing.assert_allclose(block.jacobian, numeric, atol=1e-8)


def _sloped_scene(rng):
    """Ground on a road that climbs 6 % for 30 m then 12 %, sub-ground noise, and a car on the slope."""
    x = rng.uniform(-30, 30, 20000)
    y = rng.uniform(-10, 10, 20000)
    def height(xx):
        return np.where(xx < 0, 0.06 * xx, 0.12 * xx)
    ground = np.column_stack([x, y, height(x) + rng.normal(0, 0.02, len(x))])
    # multipath returns 1-4 m below the road (a mirrored cluster and scattered points)
    noise = np.column_stack([rng.uniform(-30, 30, 150), rng.uniform(-10, 10, 150), np.zeros(150)])
    noise[:, 2] = height(noise[:, 0]) - rng.uniform(1.0, 4.0, 150)
    cluster = np.column_stack([rng.normal(12, 0.5, 60), rng.normal(2, 0.3, 60), np.zeros(60)])
    cluster[:, 2] = height(cluster[:, 0]) - 2.5 + rng.normal(0, 0.1, 60)
    # a car-like block on the road at x = 12: points from 0.4 m (above the 0.3 m plane band) to 1.6 m
    car = np.column_stack([rng.uniform(10, 14.5, 1500), rng.uniform(1.0, 2.8, 1500), rng.uniform(0.4, 1.6, 1500)])
    car[:, 2] += height(car[:, 0])
    return ground, np.vstack([noise, cluster]), car


def test_ground_removal_on_slopes_with_sub_ground_noise():
    rng = np.random.default_rng(1)
    ground, noise, car = _sloped_scene(rng)
    points = np.vstack([ground, noise, car])
    mask = ground_mask(points, GroundParams(seed_threshold=0.3, distance_threshold=0.2, segment_length=8.0))
    n_g, n_n = len(ground), len(noise)
    assert mask[:n_g].mean() > 0.98                 # the road, on both slopes
    assert mask[n_g:n_g + n_n].all()                # noise below the road is never kept as an object
    assert mask[n_g + n_n:].mean() < 0.02           # the car is kept
    # a single plane for the whole 60 m scene cannot do this (the reason for per-segment planes)
    single = ground_mask(points, GroundParams(seed_threshold=0.3, distance_threshold=0.2, segment_length=1000.0))
    assert single[:n_g].mean() < 0.95 or single[n_g + n_n:].mean() > 0.05


def test_ground_removal_with_the_paper_seed_threshold_keeps_the_car():
    rng = np.random.default_rng(2)
    ground, noise, car = _sloped_scene(rng)
    points = np.vstack([ground, noise, car])
    mask = ground_mask(points, GroundParams(low_plane_fallback=True))  # seeds 1.2 m, distance 0.3 m
    assert mask[:len(ground)].mean() > 0.97
    assert mask[len(ground):len(ground) + len(noise)].all()
    assert mask[len(ground) + len(noise):].mean() < 0.02


def test_ransac_finds_the_rigid_motion_among_outliers():
    rng = np.random.default_rng(3)
    src = rng.uniform(-3, 3, (300, 2))
    angle, t = 0.2, np.array([0.5, -0.3])
    c, s = np.cos(angle), np.sin(angle)
    dst = src @ np.array([[c, s], [-s, c]]) + t + rng.normal(0, 0.02, src.shape)
    outliers = rng.random(300) < 0.4
    dst[outliers] += rng.uniform(1.0, 3.0, (outliers.sum(), 2)) * rng.choice([-1, 1], (outliers.sum(), 2))
    result = ransac_rigid_2d(src, dst, np.random.default_rng(0), threshold=0.2)
    assert result.angle == pytest.approx(angle, abs=0.01)
    np.testing.assert_allclose(result.translation, t, atol=0.03)
    assert (result.inliers == ~outliers).mean() > 0.98
    a2, t2 = fit_rigid_2d(src[~outliers], dst[~outliers])
    assert a2 == pytest.approx(angle, abs=0.005)


def test_ransac_far_from_the_origin_returns_the_motion_in_the_given_coordinates():
    rng = np.random.default_rng(5)
    src = rng.uniform(-2, 2, (200, 2)) + [350.0, -1200.0]   # world coordinates far from the origin
    angle, t = -0.1, np.array([3.0, 1.5])
    c, s = np.cos(angle), np.sin(angle)
    dst = src @ np.array([[c, s], [-s, c]]) + t + rng.normal(0, 0.01, src.shape)
    result = ransac_rigid_2d(src, dst, np.random.default_rng(1), threshold=0.1, max_score_pairs=150)
    assert result.inliers.all()
    assert result.angle == pytest.approx(angle, abs=1e-3)
    c, s = np.cos(result.angle), np.sin(result.angle)   # the motion about the origin, not the points' centre
    np.testing.assert_allclose(src @ np.array([[c, s], [-s, c]]) + result.translation, dst, atol=0.05)


def test_deskew_recovers_static_points_seen_during_ego_motion():
    rng = np.random.default_rng(4)
    world_pts = rng.uniform(-20, 20, (500, 3))
    t_prev, t_cur = 1_000_000_000, 1_100_000_000
    pose_prev = make_transform(rotation_z(0.1), np.array([0.0, 0.0, 1.8]))
    pose_cur = make_transform(rotation_z(0.18), np.array([1.2, 0.3, 1.8]))
    offsets = -rng.integers(0, 100_000_000, 500)  # captured during the 0.1 s before the frame time
    s = 1.0 + offsets / (t_cur - t_prev)
    ego = np.empty_like(world_pts)
    for i in range(500):  # slow reference: the pose at each point's time
        pose = make_transform(rotation_z(0.1 + s[i] * 0.08), np.array([1.2 * s[i], 0.3 * s[i], 1.8]))
        ego[i] = transform_points(np.linalg.inv(pose), world_pts[i:i + 1])[0]
    recovered = deskew_points(ego, offsets, t_cur, pose_cur, t_prev, pose_prev)
    np.testing.assert_allclose(recovered, world_pts, atol=1e-9)
    skewed = transform_points(pose_cur, ego)
    assert np.abs(skewed - world_pts).max() > 0.5  # without de-skewing the error is large


def test_voxel_downsampling_and_shape_growth():
    pts = np.array([[0.01, 0.01, 0.01], [0.02, 0.04, 0.0], [0.26, 0.0, 0.0]])
    np.testing.assert_allclose(voxel_downsample_centres(pts, 0.05), [[0.025, 0.025, 0.025], [0.275, 0.025, 0.025]])
    shape = ShapeModel(0.05)
    shape.add(pts)
    shape.add(pts + 0.001)
    assert len(shape) == 2  # nothing duplicated, nothing removed
    shape.add(np.array([[1.0, 1.0, 1.0]]))
    assert len(shape) == 3


def test_motion_prior_moving_average():
    prior = MotionPrior(0.5)
    prior.update(np.array([1.0, 0.0, 0.0, 0.0]))
    prior.update(np.array([3.0, 0.0, 0.0, 0.2]))
    np.testing.assert_allclose(prior.predict(), [2.0, 0.0, 0.0, 0.1])
    turning = MotionPrior(0.5, frame="object")
    turning.update(np.array([1.0, 0.0, 0.0, 0.1]), heading=0.0)
    # in the box frame the motion is "forward 1 m": seen from a box heading 90 deg it goes along +y
    np.testing.assert_allclose(turning.predict(np.pi / 2), [0.0, 1.0, 0.0, 0.1], atol=1e-12)


def test_turn_prior_has_no_lag_in_a_steady_turn_and_ignores_the_box_heading():
    """A steady arc: 1 m chords, turning 0.1 rad per frame. "turn" predicts the next chord exactly; "world"
    lags (it averages chords of the past directions); neither depends on the box heading given."""
    omega = 0.1
    chords = [np.array([np.cos(omega * (k + 0.5)), np.sin(omega * (k + 0.5)), 0.0, omega]) for k in range(30)]
    turn, world = MotionPrior(0.6, frame="turn"), MotionPrior(0.6, frame="world")
    for chord in chords[:-1]:
        turn.update(chord, heading=123.0)   # a wrong box heading: not used
        world.update(chord, heading=-7.0)
    np.testing.assert_allclose(turn.predict(heading=5.0), chords[-1], atol=1e-9)
    lag = np.arctan2(*world.predict()[1::-1]) - omega * 29.5
    assert lag < -0.1                       # the world-frame average points 0.15 rad behind
    # per second (interval in seconds): the same arc at 10 Hz
    per_s = MotionPrior(0.6, frame="turn")
    for chord in chords[:-1]:
        per_s.update(chord / 0.1, interval=0.1)
    np.testing.assert_allclose(per_s.predict(interval=0.1) * 0.1, chords[-1], atol=1e-9)


def test_config_presets_and_round_trip():
    full = get_preset("full")
    assert TrackerConfig.from_dict(full.to_dict()) == full
    assert (full.registration.icp_weight, full.shape.weight, full.motion.consistency_weight,
            full.motion.prior_weight) == (1.0, 1.0, 0.1, 0.1)
    assert (full.search.scale, full.first_frame.scale, full.search.crop_scale) == (1.5, 3.0, 1.1)
    assert not get_preset("icp_mp").shape.enabled and get_preset("icp_mp").motion.consistency_weight == 0
    assert not get_preset("icp_mp_s1").shape.aggregate
    assert get_preset("no_ground_removal").ground.remover == "none"
    assert get_preset("no_ransac").shape.ransac.mode == "none"
    assert not get_preset("no_subshape").shape.subshape
    faithful = get_preset("faithful")
    assert faithful.registration.outer_iterations == 20 and faithful.first_frame.icp_iterations == 50
    assert set(PRESETS) == {"full", "faithful", "icp_mp", "icp_mp_s1", "icp_mp_sall", "no_ground_removal",
                            "no_ransac", "no_subshape", "det_sot", "det"}
    assert get_preset("full", seed=5).seed == 5
    with pytest.raises(ValueError):
        get_preset("nope")
    with pytest.raises(ValueError):
        TrackerConfig.from_dict({"registration": {"icp_weight": 1.0, "bogus": 2}})
    with pytest.raises(dataclasses.FrozenInstanceError):
        full.seed = 3  # frozen
