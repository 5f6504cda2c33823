"""tracker.metrics against hand-computed cases and an independent (scipy half-space) polygon intersection."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, HalfspaceIntersection

from tracker.geometry import Box, make_transform, points_in_box, rotation_zyx, transform_points
from tracker.metrics import (
    PooledMetrics,
    accuracy,
    bev_corners_batch,
    bev_intersection_area_batch,
    centre_errors_batch,
    chamfer_distance,
    difficulty,
    iou_3d,
    iou_3d_batch,
    pool_metrics,
    precision,
    robustness,
    robustness_curve,
    score_tracklet,
    success,
    tracklet_metrics,
    voxel_downsample_centres,
    voxel_downsample_means,
)

# --------------------------------------------------------------------------- IoU: hand-computed cases

def test_identical_boxes_iou_one():
    box = Box(3.0, -2.0, 0.8, 0.7, 4.5, 1.9, 1.6)
    assert iou_3d(box, box) == pytest.approx(1.0, abs=1e-12)
    # heading + pi describes the same box
    flipped = Box(3.0, -2.0, 0.8, 0.7 + math.pi, 4.5, 1.9, 1.6)
    assert iou_3d(box, flipped) == pytest.approx(1.0, abs=1e-12)


def test_equal_heights_offset_along_length():
    # 4 x 2 x 1.5 boxes, second shifted 1 m along x: intersection 3*2*1.5 = 9, union 12 + 12 - 9 = 15.
    a = Box(0.0, 0.0, 0.0, 0.0, 4.0, 2.0, 1.5)
    b = Box(1.0, 0.0, 0.0, 0.0, 4.0, 2.0, 1.5)
    assert iou_3d(a, b) == pytest.approx(9.0 / 15.0, abs=1e-12)
    # the same pair rotated by 30 degrees about the origin (both boxes) has the same IoU
    th = math.radians(30.0)
    a_r = Box(0.0, 0.0, 0.0, th, 4.0, 2.0, 1.5)
    b_r = Box(math.cos(th), math.sin(th), 0.0, th, 4.0, 2.0, 1.5)
    assert iou_3d(a_r, b_r) == pytest.approx(9.0 / 15.0, abs=1e-12)


def test_unequal_heights_use_true_vertical_overlap():
    # Same 4 x 2 footprint. a: z in [0, 2] (h=2); b: z in [-0.25, 0.75] (h=1).
    # Vertical overlap = min(2, 0.75) - max(0, -0.25) = 0.75 -> I = 8 * 0.75 = 6;
    # V_a = 16, V_b = 8 -> IoU = 6 / (16 + 8 - 6) = 1/3.
    a = Box(0.0, 0.0, 1.0, 0.0, 4.0, 2.0, 2.0)
    b = Box(0.0, 0.0, 0.25, 0.0, 4.0, 2.0, 1.0)
    assert iou_3d(a, b) == pytest.approx(1.0 / 3.0, abs=1e-12)
    assert iou_3d(b, a) == pytest.approx(1.0 / 3.0, abs=1e-12)


def test_45_degree_rotation_of_a_square():
    # Two s x s squares with the same centre, one rotated by 45 deg. With a = s/2, the axis-aligned
    # square loses four corner triangles cut by the lines |x| + |y| = a*sqrt(2); each has legs
    # a - (a*sqrt(2) - a) = a(2 - sqrt(2)), so the cut area is 4 * a^2 (2 - sqrt(2))^2 / 2 =
    # a^2 (12 - 8 sqrt(2)) and the octagon has area 4a^2 - a^2(12 - 8 sqrt(2)) = 8 a^2 (sqrt(2) - 1)
    # = 2 (sqrt(2) - 1) s^2. With equal heights h: IoU = 2(sqrt2-1) / (2 - 2(sqrt2-1)) = 1/sqrt(2).
    s, h = 2.0, 1.3
    corners_a = bev_corners_batch(np.array([[0.0, 0.0, 0.0, 0.0, s, s, h]]))
    corners_b = bev_corners_batch(np.array([[0.0, 0.0, 0.0, math.pi / 4, s, s, h]]))
    area = bev_intersection_area_batch(corners_a, corners_b)[0]
    assert area == pytest.approx(2.0 * (math.sqrt(2.0) - 1.0) * s * s, abs=1e-12)
    a = Box(5.0, 7.0, 1.0, 0.0, s, s, h)
    b = Box(5.0, 7.0, 1.0, math.pi / 4, s, s, h)
    assert iou_3d(a, b) == pytest.approx(1.0 / math.sqrt(2.0), abs=1e-12)


def test_90_degree_rotation_of_a_rectangle():
    # 4 x 2 rectangle and the same rotated by 90 deg: the overlap is the 2 x 2 square -> 4h / (16h - 4h).
    a = Box(0.0, 0.0, 0.0, 0.0, 4.0, 2.0, 1.0)
    b = Box(0.0, 0.0, 0.0, math.pi / 2, 4.0, 2.0, 1.0)
    assert iou_3d(a, b) == pytest.approx(1.0 / 3.0, abs=1e-12)


def test_disjoint_boxes_iou_zero():
    a = Box(0.0, 0.0, 0.0, 0.3, 4.0, 2.0, 1.5)
    assert iou_3d(a, Box(10.0, 0.0, 0.0, 0.3, 4.0, 2.0, 1.5)) == 0.0          # apart in x-y
    assert iou_3d(a, Box(0.0, 0.0, 1.6, 0.3, 4.0, 2.0, 1.5)) == 0.0           # stacked, no vertical overlap
    # footprints that touch only along an edge (a 4 x 2 box shifted by its length)
    assert iou_3d(Box(0, 0, 0, 0, 4, 2, 1), Box(4, 0, 0, 0, 4, 2, 1)) == pytest.approx(0.0, abs=1e-12)
    # circumscribed circles overlap but the rotated rectangles do not
    assert iou_3d(Box(0, 0, 0, 0, 4, 1, 1), Box(0, 2.0, 0, 0, 4, 1, 1)) == 0.0


def test_containment_is_volume_ratio():
    big = Box(1.0, 1.0, 1.0, 0.4, 6.0, 3.0, 2.0)
    small = Box(1.2, 0.9, 0.8, 1.1, 1.0, 0.8, 0.5)  # fits well inside (diagonal 1.28 < 3, height 0.5 < 2)
    assert iou_3d(big, small) == pytest.approx((1.0 * 0.8 * 0.5) / (6.0 * 3.0 * 2.0), abs=1e-12)


def _halfspace_area(ca: np.ndarray, cb: np.ndarray) -> float:
    """Area of the intersection of two CCW convex quadrilaterals via scipy's half-space intersection."""
    halfspaces = []
    for poly in (ca, cb):
        for i in range(4):
            p, q = poly[i], poly[(i + 1) % 4]
            normal = np.array([q[1] - p[1], p[0] - q[0]])  # outward for CCW
            halfspaces.append([normal[0], normal[1], -normal @ p])
    hs = np.array(halfspaces)
    norms = np.linalg.norm(hs[:, :2], axis=1)
    lp = linprog([0, 0, -1], A_ub=np.c_[hs[:, :2], norms], b_ub=-hs[:, 2],
                 bounds=[(None, None), (None, None), (0, None)])
    if lp.x is None or lp.x[2] < 1e-9:
        return 0.0
    return float(ConvexHull(HalfspaceIntersection(hs, lp.x[:2]).intersections).volume)


def test_bev_area_matches_independent_halfspace_intersection():
    rng = np.random.default_rng(7)
    n = 150
    a = np.c_[rng.uniform(-2, 2, (n, 2)), np.zeros(n), rng.uniform(-4, 4, n), rng.uniform(1, 5, (n, 2)), np.ones(n)]
    b = np.c_[rng.uniform(-2, 2, (n, 2)), np.zeros(n), rng.uniform(-4, 4, n), rng.uniform(1, 5, (n, 2)), np.ones(n)]
    b[:30, 3] = a[:30, 3]                # parallel edges
    b[30:50, 3] = a[30:50, 3] + np.pi / 2
    b[50:60, :2] = a[50:60, :2]          # same centre
    ca, cb = bev_corners_batch(a), bev_corners_batch(b)
    got = bev_intersection_area_batch(ca, cb)
    expected = np.array([_halfspace_area(ca[i], cb[i]) for i in range(n)])
    assert np.count_nonzero(expected > 0) > n // 2
    np.testing.assert_allclose(got, expected, atol=1e-9)


def test_iou_batch_matches_single_and_is_symmetric():
    rng = np.random.default_rng(3)
    n = 50
    a = np.c_[rng.normal(0, 1, (n, 3)), rng.uniform(-4, 4, n), rng.uniform(1, 5, (n, 2)), rng.uniform(1, 2, n)]
    b = np.c_[rng.normal(0, 1, (n, 3)), rng.uniform(-4, 4, n), rng.uniform(1, 5, (n, 2)), rng.uniform(1, 2, n)]
    batch = iou_3d_batch(a, b)
    single = np.array([iou_3d(Box.from_array(a[i]), Box.from_array(b[i])) for i in range(n)])
    np.testing.assert_allclose(batch, single, atol=1e-12)
    np.testing.assert_allclose(batch, iou_3d_batch(b, a), atol=1e-12)
    assert np.all((batch >= 0) & (batch <= 1))


# --------------------------------------------------------------------------- IoU of tilted boxes (roll, pitch)

def _halfspace_volume(a: Box, b: Box) -> float:
    """Intersection volume of two boxes via scipy's half-space intersection (an independent method)."""
    halfspaces = []
    for box in (a, b):
        r = box.rotation()
        for axis in range(3):
            for sign in (1.0, -1.0):
                normal = sign * r[:, axis]
                halfspaces.append([*normal, -(normal @ box.center) - box.size[axis] / 2.0])
    hs = np.array(halfspaces)
    norms = np.linalg.norm(hs[:, :3], axis=1)
    lp = linprog([0, 0, 0, -1], A_ub=np.c_[hs[:, :3], norms], b_ub=-hs[:, 3],
                 bounds=[(None, None)] * 3 + [(0, None)])
    if lp.x is None or lp.x[3] < 1e-9:
        return 0.0
    return float(ConvexHull(HalfspaceIntersection(hs, lp.x[:3]).intersections).volume)


def _random_tilted(rng: np.random.Generator, n: int, tilt: float) -> list[Box]:
    return [Box(*rng.normal(0, 0.6, 3), rng.uniform(-np.pi, np.pi), *rng.uniform(1, 4, 3), *rng.uniform(-tilt, tilt, 2))
            for _ in range(n)]


def test_tilted_box_against_itself_is_one():
    box = Box(3.0, -2.0, 0.8, 0.7, 4.5, 1.9, 1.6, roll=0.2, pitch=-0.3)
    assert iou_3d(box, box) == pytest.approx(1.0, abs=1e-12)
    # the same solid described with heading + pi, roll and pitch negated
    same = Box(3.0, -2.0, 0.8, 0.7 + math.pi, 4.5, 1.9, 1.6, roll=-0.2, pitch=0.3)
    np.testing.assert_allclose(same.corners()[np.lexsort(same.corners().T)],
                               box.corners()[np.lexsort(box.corners().T)], atol=1e-12)
    assert iou_3d(box, same) == pytest.approx(1.0, abs=1e-12)


def test_cube_pitched_or_rolled_by_45_degrees():
    """A 2 m cube against itself pitched (or rolled) by 45 deg about its centre: the section across the
    rotation axis is the square-and-rotated-square octagon of the level case, so IoU = 1/sqrt(2)."""
    level = Box(5.0, 7.0, 1.0, 0.3, 2.0, 2.0, 2.0)
    for tilt in ({"pitch": math.pi / 4}, {"roll": math.pi / 4}):
        tilted = Box(5.0, 7.0, 1.0, 0.3, 2.0, 2.0, 2.0, **tilt)
        assert iou_3d(level, tilted) == pytest.approx(1 / math.sqrt(2), abs=1e-12)


def test_iou_is_invariant_under_a_tilting_rigid_motion():
    """Level pairs of known IoU moved by one rigid transform with roll and pitch keep their IoU."""
    world_from_box = make_transform(rotation_zyx(0.9, 0.35, -0.25), [12.0, -4.0, 2.5])
    pairs = [(Box(0.0, 0.0, 0.0, 0.0, 4.0, 2.0, 1.5), Box(1.0, 0.0, 0.0, 0.0, 4.0, 2.0, 1.5), 9.0 / 15.0),
             (Box(0.0, 0.0, 1.0, 0.0, 4.0, 2.0, 2.0), Box(0.0, 0.0, 0.25, 0.0, 4.0, 2.0, 1.0), 1.0 / 3.0),
             (Box(0.0, 0.0, 0.0, 0.0, 4.0, 2.0, 1.0), Box(0.0, 0.0, 0.0, math.pi / 2, 4.0, 2.0, 1.0), 1.0 / 3.0),
             (Box(0, 0, 0, 0, 4, 2, 1), Box(4, 0, 0, 0, 4, 2, 1), 0.0)]
    for a, b, expected in pairs:
        ta, tb = a.transformed(world_from_box, keep_tilt=True), b.transformed(world_from_box, keep_tilt=True)
        assert not ta.is_level
        assert iou_3d(ta, tb) == pytest.approx(expected, abs=1e-12)
        assert iou_3d_batch(np.array([[*ta.to_array(), ta.roll, ta.pitch]]),
                            np.array([[*tb.to_array(), tb.roll, tb.pitch]]))[0] == pytest.approx(expected, abs=1e-12)


def test_tilted_iou_matches_halfspace_intersection_and_sampling():
    """Random tilted pairs: the volume behind the IoU equals scipy's half-space intersection; and, for a few,
    the share of points sampled uniformly in box a that lie in box b (points_in_box) times V_a."""
    rng = np.random.default_rng(11)
    a, b = _random_tilted(rng, 60, 0.7), _random_tilted(rng, 60, 0.7)
    got = iou_3d_batch(a, b)
    inter = np.array([_halfspace_volume(x, y) for x, y in zip(a, b, strict=True)])
    va, vb = np.array([np.prod(x.size) for x in a]), np.array([np.prod(y.size) for y in b])
    assert np.count_nonzero(inter > 0) > 40
    np.testing.assert_allclose(got, inter / (va + vb - inter), atol=1e-9)
    np.testing.assert_allclose(got, iou_3d_batch(b, a), atol=1e-12)
    for i in range(3):
        local = rng.uniform(-0.5, 0.5, (200_000, 3)) * a[i].size
        inside = points_in_box(transform_points(a[i].world_from_object(), local), b[i]).mean() * va[i]
        assert inside == pytest.approx(inter[i], abs=0.02 * va[i])


def test_level_and_polytope_paths_agree_on_level_boxes():
    """A vanishing tilt sends a level pair through the polytope path: the same IoU as the level formula."""
    rng = np.random.default_rng(5)
    n = 80
    a = np.c_[rng.normal(0, 1, (n, 3)), rng.uniform(-4, 4, n), rng.uniform(1, 5, (n, 3)), np.zeros((n, 2))]
    b = np.c_[rng.normal(0, 1, (n, 3)), rng.uniform(-4, 4, n), rng.uniform(1, 5, (n, 3)), np.zeros((n, 2))]
    nearly = b.copy()
    nearly[:, 8] = 1e-13
    np.testing.assert_allclose(iou_3d_batch(a, nearly), iou_3d_batch(a[:, :7], b[:, :7]), atol=1e-9)


def test_boxes_keep_their_tilt_and_seven_value_arrays_are_level():
    """Boxes keep their roll and pitch through iou_3d and Box sequences; 7-value arrays are level boxes."""
    tilted = Box(0.0, 0.0, 0.0, 0.0, 4.0, 2.0, 1.5, pitch=0.1)
    level = Box(0.0, 0.0, 0.0, 0.0, 4.0, 2.0, 1.5)
    assert iou_3d(tilted, level) < 0.95
    assert iou_3d_batch([tilted], [level])[0] == pytest.approx(iou_3d(tilted, level), abs=1e-12)
    assert iou_3d_batch(tilted.to_array()[None], level.to_array()[None])[0] == pytest.approx(1.0, abs=1e-12)


def test_centre_errors():
    a = np.array([[0, 0, 0, 0, 4, 2, 1], [1, 1, 1, 0, 4, 2, 1]], dtype=float)
    b = np.array([[3, 4, 0, 1, 4, 2, 1], [1, 1, 3, 2, 4, 2, 1]], dtype=float)
    np.testing.assert_allclose(centre_errors_batch(a, b), [5.0, 2.0])


# --------------------------------------------------------------------------- Acc / Rob worked examples

# Values avoid the threshold grid (0.05 steps) so floating-point grid points cannot flip a comparison.
TRACK_A = np.array([0.92, 0.82, 0.32, 0.92])
TRACK_B = np.array([0.52, 0.52])


def test_rob_single_tracklet_worked_example():
    # l(t): t in {0..0.30} -> 4 (no IoU below t); {0.35..0.80} -> 2 (0.32 fails at index 2);
    # {0.85, 0.90} -> 1 (0.82 fails at index 1); {0.95, 1.0} -> 0.
    # Rob(t) = l / 4 -> 7 x 1, 10 x 0.5, 2 x 0.25, 2 x 0.
    # trapz = 0.05 * (sum - (first + last)/2) = 0.05 * (12.5 - 0.5) = 0.60
    curve = robustness_curve([TRACK_A])
    np.testing.assert_allclose(curve, [1.0] * 7 + [0.5] * 10 + [0.25] * 2 + [0.0] * 2)
    assert robustness([TRACK_A]) == pytest.approx(0.60, abs=1e-12)


def test_rob_pooled_worked_example():
    # B: l = 2 for t <= 0.5, 0 above. Pooled Rob(t) = (l_A + l_B) / 6:
    # 7 x 1, 4 x 4/6, 6 x 2/6, 2 x 1/6, 2 x 0 -> sum 12, trapz = 0.05 * (12 - 0.5) = 0.575
    # (= length-weighted mean of per-tracklet Robs: (4 * 0.6 + 2 * 0.525) / 6).
    assert robustness([TRACK_A, TRACK_B]) == pytest.approx(0.575, abs=1e-12)
    assert robustness([TRACK_B]) == pytest.approx(0.525, abs=1e-12)
    assert accuracy([TRACK_A, TRACK_B]) == pytest.approx(4.02 / 6.0, abs=1e-12)


def test_rob_perfect_and_immediate_failure():
    assert robustness([np.ones(5)]) == pytest.approx(1.0)  # IoU 1 is never < t for t <= 1
    # IoU 0 in the first frame: l = 0 for every t > 0; Rob(0) = 1 -> area = 0.05 / 2
    assert robustness([np.zeros(3)]) == pytest.approx(0.025)


# --------------------------------------------------------------------------- Success / Precision

def test_success_worked_example():
    # IoUs [1.0, 0.52]: S(t) = 1 for t in {0..0.50} (11 values, 0.52 > 0.5), 0.5 for {0.55..0.95} (9),
    # 0 at t = 1 (1.0 > 1.0 is false). trapz = 0.05 * (11 + 4.5 + 0 - (1 + 0)/2) = 0.75 -> 75.0
    assert success(np.array([1.0, 0.52])) == pytest.approx(75.0, abs=1e-9)
    assert success(np.zeros(4)) == pytest.approx(0.0)


def test_precision_worked_example():
    # errors [0, 0.25, 3.0] m, d in {0, 0.1, .., 2}: P(0) = 0 (0 < 0 false), P(0.1) = P(0.2) = 1/3,
    # P(0.3..2.0) = 2/3 (18 values). trapz = 0.1 * (2/3 + 12 - (0 + 2/3)/2) = 1.2333..; / 2 m * 100.
    expected = 100.0 * 0.1 * (2.0 / 3.0 + 12.0 - 1.0 / 3.0) / 2.0
    assert precision(np.array([0.0, 0.25, 3.0])) == pytest.approx(expected, abs=1e-9)
    assert expected == pytest.approx(61.6667, abs=1e-3)
    # every error below the first positive threshold: P(0) = 0, P(d >= 0.1) = 1 -> 100 * 0.1 * 19.5 / 2
    assert precision(np.full(3, 0.05)) == pytest.approx(100.0 * (2.0 - 0.05) / 2.0, abs=1e-9)


# --------------------------------------------------------------------------- Chamfer

def test_chamfer_exact_points():
    a = np.array([[0.0, 0.0, 0.0]])
    b = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0]])
    # a->b: 0; b->a: 0 and 5 -> (0 + 0 + 5) / (1 + 2)
    assert chamfer_distance(a, b, voxel=None) == pytest.approx(5.0 / 3.0)
    # the paper's Eq. 3 variant: mean(0) + mean(0, 5)
    assert chamfer_distance(a, b, voxel=None, symmetric_mean=True) == pytest.approx(2.5)
    assert chamfer_distance(b, b, voxel=None) == 0.0


def test_chamfer_voxelised_at_5cm():
    # a -> voxel centre (0.025, 0.025, 0.025); b -> same centre and (0.325, 0.025, 0.025);
    # the extra point of b shares a voxel and disappears. CD = (0 + 0 + 0.3) / (1 + 2) = 0.1
    a = np.array([[0.01, 0.01, 0.01]])
    b = np.array([[0.02, 0.03, 0.04], [0.31, 0.01, 0.01], [0.34, 0.04, 0.04]])
    np.testing.assert_allclose(voxel_downsample_centres(b), [[0.025, 0.025, 0.025], [0.325, 0.025, 0.025]])
    assert chamfer_distance(a, b) == pytest.approx(0.1, abs=1e-12)
    assert np.isnan(chamfer_distance(np.zeros((0, 3)), b))


def test_voxel_centres_negative_coordinates():
    pts = np.array([[-0.01, -0.06, 0.0], [-0.02, -0.07, 0.04]])
    np.testing.assert_allclose(voxel_downsample_centres(pts), [[-0.025, -0.075, 0.025]])


def test_voxel_means_are_each_voxels_point_mean_in_sorted_voxel_order():
    """Three voxels of 5 cm (one across the origin's negative side), points given out of order: one mean each,
    voxels sorted by (x, y, z) index."""
    pts = np.array([[0.11, 0.01, 0.01], [-0.01, 0.02, 0.03], [0.12, 0.03, 0.02], [0.01, 0.01, 0.01],
                    [-0.03, 0.04, 0.01], [0.02, 0.03, 0.04]])
    want = [[-0.02, 0.03, 0.02], [0.015, 0.02, 0.025], [0.115, 0.02, 0.015]]
    np.testing.assert_allclose(voxel_downsample_means(pts, 0.05), want, atol=1e-12)
    far = np.vstack([pts, [[3e17, 0.0, 0.0]]])   # a span too wide for one int64 code: the row-wise path
    np.testing.assert_allclose(voxel_downsample_means(far, 0.05)[:3], want, atol=1e-12)


# --------------------------------------------------------------------------- difficulty and records

def test_difficulty_thresholds():
    assert difficulty(38.1) == "hard"
    assert difficulty(38.2) == "medium"
    assert difficulty(808.2) == "medium"
    assert difficulty(808.3) == "easy"
    assert difficulty(1277.0) == "easy"


def test_score_and_pool_tracklets():
    gt = np.array([[0, 0, 0, 0, 4, 2, 1.5], [1, 0, 0, 0, 4, 2, 1.5], [2, 0, 0, 0, 4, 2, 1.5]], dtype=float)
    pred = gt.copy()
    pred[0, 0] += 3.0            # frame 0 is never scored
    pred[2, 0] += 1.0            # IoU 9/15 = 0.6, centre error 1 m
    scores = score_tracklet("t1", pred, gt, mean_points_first10=50.0)
    np.testing.assert_allclose(scores.ious, [1.0, 0.6])
    np.testing.assert_allclose(scores.centre_errors, [0.0, 1.0])
    assert scores.difficulty == "medium"
    m = tracklet_metrics(scores)
    assert m.acc == pytest.approx(0.8)
    assert m.centre_error == pytest.approx(0.5)
    assert m.n_frames == 2
    other = score_tracklet("t2", gt[:2], gt[:2], shape=np.zeros((1, 3)), reference_shape=np.zeros((1, 3)))
    pooled = pool_metrics([scores, other])
    assert isinstance(pooled, PooledMetrics)
    assert pooled.n_frames == 3
    assert pooled.acc == pytest.approx((1.0 + 0.6 + 1.0) / 3.0)
    assert pooled.shape == pytest.approx(0.0)  # only t2 has shapes
    assert pooled.to_dict()["track_ids"] == ["t1", "t2"]


def test_unique_sorted_is_numpy_unique():
    """tracker.metrics.unique_sorted (voxel codes, matched rows): the same values, order and dtype as np.unique."""
    import numpy as np

    from tracker.metrics import unique_sorted

    rng = np.random.default_rng(3)
    for n in (0, 1, 2, 7, 1000):
        for dtype in (np.int64, np.int32, np.intp):
            values = rng.integers(-40, 40, n).astype(dtype)
            got, want = unique_sorted(values), np.unique(values)
            assert got.dtype == want.dtype and np.array_equal(got, want)
    assert list(unique_sorted(np.array([5, 5, 5]))) == [5]
