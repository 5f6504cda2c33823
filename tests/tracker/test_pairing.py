"""registration.pairing: which way the data terms pair the source (and shape) with the frame's points.

A car seen from behind as it drives away: the source (an earlier, nearer view, or the shape built from such views)
holds its rear face AND its roof, the new frame only the rear face. Paired source-to-frame, every roof point's
nearest frame point is the rear face's top edge, behind it, so the roof drags the box back toward the sensor
(a box placed on the visible face). Paired frame-to-source, every frame point has its counterpart in the source
and the roof pulls on nothing: the motion is found exactly.
"""

from __future__ import annotations

import numpy as np
import pytest

from tracker import get_preset
from tracker.association import NearestNeighbors
from tracker.geometry import Box
from tracker.registration import frame_pairs, unmove
from tracker.shape import to_object_frame
from tracker.strategies.choose import choose_strategies
from tracker.strategies.metric import FrameTarget
from tracker.terms import apply_motion

BOX = Box(20.0, 3.0, 0.0, 0.0, 4.5, 1.8, 1.5)
TRUE_MOTION = np.array([0.8, 0.0, 0.0, 0.0])   # 8 m/s straight on, 0.1 s


def _grid(a: tuple[float, float], b: tuple[float, float], step: float) -> np.ndarray:
    u, v = np.meshgrid(np.arange(a[0], a[1] + 1e-9, step), np.arange(b[0], b[1] + 1e-9, step), indexing="ij")
    return np.column_stack([u.ravel(), v.ravel()])


def _views() -> tuple[np.ndarray, np.ndarray]:
    """(source: rear face + roof, world at BOX; frame: the rear face alone, world at BOX moved by TRUE_MOTION)."""
    rear_yz = _grid((-0.9, 0.9), (-0.6, 0.75), 0.1)
    rear = np.column_stack([np.full(len(rear_yz), -2.25), rear_yz])
    roof_xy = _grid((-2.15, 0.5), (-0.8, 0.8), 0.1)
    roof = np.column_stack([roof_xy, np.full(len(roof_xy), 0.75)])
    world = BOX.world_from_object()
    to_world = (lambda p: p @ world[:3, :3].T + world[:3, 3])
    source = to_world(np.vstack([rear, roof]))
    frame = apply_motion(TRUE_MOTION, to_world(rear), BOX.center)
    return source, frame


def _register(pairing: str, x0: np.ndarray) -> np.ndarray:
    config = get_preset("full", **{"registration.pairing": pairing})
    registration = choose_strategies(config).registration
    source, frame = _views()
    shape = to_object_frame(source, BOX)
    x, info = registration.estimate(BOX, source, shape, FrameTarget(frame), x0, 1.5, 20, False, None, [],
                                    np.random.default_rng(0))
    assert info["icp_pairs"] > 0 and info["shape_inliers"] > 0
    return x


def test_unmove_inverts_apply_motion():
    rng = np.random.default_rng(3)
    points, pivot, x = rng.normal(size=(50, 3)), np.array([1.0, -2.0, 0.5]), np.array([0.4, -0.3, 0.1, 0.35])
    np.testing.assert_allclose(unmove(x, apply_motion(x, points, pivot), pivot), points, atol=1e-12)


def test_frame_pairs_pair_each_frame_point_with_its_nearest_moved_source_point():
    source, frame = _views()
    inside = np.arange(len(frame))
    src, idx, dist, moved, tgt = frame_pairs(TRUE_MOTION, NearestNeighbors(source), BOX.center, frame, inside, 0.5)
    assert len(src) == len(frame)            # every frame point has its counterpart (the rear face moved)
    np.testing.assert_allclose(moved, tgt, atol=1e-9)
    np.testing.assert_allclose(dist, 0.0, atol=1e-9)
    far = frame_pairs(TRUE_MOTION + np.array([1.0, 0.0, 0.0, 0.0]), NearestNeighbors(source), BOX.center, frame,
                      inside, 0.5)
    assert len(far[0]) == 0                  # 1 m away: every pair beyond the 0.5 m gate


@pytest.mark.parametrize("start", [0.6, 0.75, 0.9])
def test_paired_frame_to_source_the_roof_no_longer_drags_the_box_onto_the_rear_face(start):
    x0 = np.array([start, 0.0, 0.0, 0.0])
    behind = _register("source", x0)[0] - TRUE_MOTION[0]
    exact = _register("frame", x0)[0] - TRUE_MOTION[0]
    assert behind < -0.1                     # the box placed behind the car, on its visible face
    assert abs(exact) < 0.01


def test_both_ways_keeps_the_source_pairs_and_adds_the_frame_pairs():
    x0 = np.array([0.75, 0.0, 0.0, 0.0])
    behind, both, exact = (_register(p, x0)[0] - TRUE_MOTION[0] for p in ("source", "both", "frame"))
    # the roof's pairs still drag the box back, outweighed in part by the frame's (-0.46 m, -0.35 m, 0)
    assert behind < 0.9 * behind < both < -0.1
    assert abs(exact) < 0.01


def test_a_car_accelerating_away_is_followed_closer_paired_frame_to_source():
    # 3 m/s accelerating at 3 m/s^2 away from a still sensor, 3 m to its side; LiDAR-like density (cos / r^2):
    # ~1200 points at 8 m, ~70 at 27 m, its roof and side thinning faster than its rear face
    from tracker_synthetic import BOX_SIZE, make_sequence

    from tracker import track

    x, step, boxes = 8.0, 0.3, []
    for _ in range(30):
        boxes.append(Box(x, 3.0, 0.0, 0.0, *BOX_SIZE))
        x, step = x + step, step + 0.03
    for seed in (0, 1):
        sequence = make_sequence(n_frames=30, seed=seed, boxes=boxes, lidar_density=20000.0, ego_speed=0.0,
                                 ego_yaw_rate=0.0)

        def along(pairing: str, sequence=sequence) -> float:
            result = track(sequence, boxes[0], 0, 29, get_preset("full", **{"registration.pairing": pairing}))
            return float(np.mean([e.box.x - b.x for e, b in zip(result.estimates[10:], boxes[10:], strict=True)]))

        behind, closer = along("source"), along("frame")
        # every run trails the car (0.04-0.05 m over frames 10-29); paired frame-to-source by a third less
        assert behind < -0.035
        assert abs(closer) < 0.75 * abs(behind)


def _decided(source: np.ndarray, frame: np.ndarray, x: np.ndarray) -> str:
    from tracker.registration import _FramePairing

    config = get_preset("full", **{"registration.pairing": "coverage"})
    pairing = _FramePairing.of(config, source, np.zeros((0, 3)), seed=0)
    return pairing._decide(pairing.trees["icp"], x, BOX.center, frame)


def test_coverage_pairs_from_the_frame_where_the_source_holds_more_of_the_car():
    source, frame = _views()
    assert _decided(source, frame, TRUE_MOTION) == "frame"     # the roof has no counterpart in the frame
    # the other way round (the frame shows the roof the source lacks: a nearer view, a face turning in):
    # source-to-frame, as every preset pairs
    rear_only = source[np.isclose(to_object_frame(source, BOX)[:, 0], -2.25)]
    assert _decided(rear_only, np.vstack([frame, apply_motion(TRUE_MOTION, source, BOX.center)]),
                    TRUE_MOTION) == "source"
    # the same faces in both: source-to-frame
    assert _decided(source, apply_motion(TRUE_MOTION, source, BOX.center), TRUE_MOTION) == "source"


@pytest.mark.parametrize("start", [0.6, 0.9])
def test_coverage_finds_the_receding_car_as_frame_to_source_does(start):
    x0 = np.array([start, 0.0, 0.0, 0.0])
    assert abs(_register("coverage", x0)[0] - TRUE_MOTION[0]) < 0.01


def test_coverage_that_pairs_source_to_frame_is_the_source_pairing_bit_for_bit():
    # a car whose frame shows what the source shows: every frame decided "source", the same boxes as "source"
    # (a margin no share can exceed): its crop subsets are its own draws, the tracker's random stream is untouched
    from tracker_synthetic import make_sequence, trajectory

    from tracker import track

    sequence = make_sequence(n_frames=12, seed=2)
    settings = {"registration.coverage_margin": 2.0}
    runs = [track(sequence, trajectory(12)[0], 0, 11, get_preset("full", **{"registration.pairing": p} | settings))
            for p in ("source", "coverage")]
    assert len(runs[0].estimates) == 12
    for a, b in zip(*(r.estimates for r in runs), strict=True):
        assert a.box == b.box
