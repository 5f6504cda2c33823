"""The Detection term (Det+SOT) and the Det baseline on synthetic scenes with known truth."""

from __future__ import annotations

import numpy as np

from tracker.config import get_preset
from tracker.detection import FrameDetections, associate_detection, detection_motion
from tracker.frames import LidarFrame
from tracker.geometry import Box
from tracker.sotracker import track

SPEED = 0.5  # m/frame of the (unobservable) slide along the wall
FRAMES = 12


class WallSource:
    """A static scene whose only object points are a long flat wall along x (plus a ground plane): a box
    sliding along x explains the points equally well everywhere, so the points cannot tell where it is."""

    def __init__(self) -> None:
        rng = np.random.default_rng(0)
        wall = np.column_stack([rng.uniform(-30, 30, 6000), rng.uniform(0.9, 0.95, 6000), rng.uniform(0.3, 1.5, 6000)])
        ground = np.column_stack([rng.uniform(-30, 30, 8000), rng.uniform(-8, 8, 8000), rng.normal(0, 0.01, 8000)])
        self.points = np.vstack([wall, ground])

    def __len__(self) -> int:
        return FRAMES

    def lidar_frame(self, index: int) -> LidarFrame:
        return LidarFrame(index=index, timestamp_ns=index * 100_000_000, points_ego=self.points,
                          world_from_ego=np.eye(4))


START = Box(0.0, 0.0, 0.8, 0.0, 4.5, 1.9, 1.6)


def truth_x(k: int) -> float:
    return SPEED * k


def detections(score: float = 0.9, offset: float = 0.0, lateral: float = 0.0) -> dict[int, FrameDetections]:
    return {k: FrameDetections(np.array([[truth_x(k) + offset, lateral, 0.8, 0.0, 4.5, 1.9, 1.6],
                                         [truth_x(k) + 30.0, 5.0, 0.8, 0.0, 4.5, 1.9, 1.6]]), np.array([score, 0.95]))
            for k in range(1, FRAMES)}


def xs(result) -> np.ndarray:
    return np.array([b.x for b in result.boxes])


def test_detection_term_pulls_an_ambiguous_track_onto_the_detections():
    source = WallSource()
    plain = track(source, START, config=get_preset("full"))
    with_det = track(source, START, config=get_preset("det_sot"), detections=detections())
    truth = np.array([truth_x(k) for k in range(FRAMES)])
    err_plain = np.abs(xs(plain) - truth)[1:]
    err_det = np.abs(xs(with_det) - truth)[1:]
    assert err_plain[-1] > 5.0                 # without detections the track cannot follow the slide
    # det_sot's small weight (docs/detection.md) competes with the motion prior: the pull takes a few frames and
    # swings a little (last three frames: 0.22, 0.05, 0.11 m with full), against
    # more than 5 m without detections
    assert err_det.max() < 2.0 and err_det[-1] < 0.15
    assert all("det" in e.flags for e in with_det.estimates[1:])
    # a weight above the motion prior's holds the track on the detections from the first frame
    strong = track(source, START, config=get_preset("det_sot", **{"detection.weight": 1.0}), detections=detections())
    assert np.all(np.abs(xs(strong) - truth)[1:] < 0.1)


def test_detections_below_the_score_or_iou_threshold_have_no_effect():
    source = WallSource()
    plain = track(source, START, config=get_preset("full"))
    low_score = track(source, START, config=get_preset("det_sot"), detections=detections(score=0.45))
    # beside the wall, 1.85 m to the side of the truth (width 1.9): BEV IoU < 0.1 with any box on the wall's line
    far = track(source, START, config=get_preset("det_sot"), detections=detections(lateral=1.85))
    for other in (low_score, far):
        np.testing.assert_array_equal(np.array([b.to_array() for b in other.boxes]),
                                      np.array([b.to_array() for b in plain.boxes]))
        assert not any("det" in e.flags for e in other.estimates)
    # thresholds are configurable: the low-score detections count once the threshold is lowered
    lowered = track(source, START, config=get_preset("det_sot", **{"detection.min_score": 0.4}), detections=detections(score=0.45))
    assert abs(xs(lowered)[-1] - truth_x(FRAMES - 1)) < 0.2


def test_association_picks_the_largest_iou_and_aligns_the_heading():
    pred = Box(0.0, 0.0, 0.0, 0.0, 4.0, 2.0, 1.5)
    dets = FrameDetections(np.array([[1.0, 0.0, 0.0, np.pi, 4.0, 2.0, 1.5], [0.3, 0.1, 0.0, 0.0, 4.0, 2.0, 1.5],
                                     [0.0, 0.0, 0.0, 0.0, 4.0, 2.0, 1.5]]), np.array([0.9, 0.8, 0.3]))
    best = associate_detection(pred, dets, 0.5, 0.1)
    np.testing.assert_allclose(best, dets.boxes[1])          # the exact match has a low score
    motion = detection_motion(pred, dets.boxes[0], 0.0)      # heading pi is the same box turned: no turn
    np.testing.assert_allclose(motion, [1.0, 0.0, 0.0, 0.0], atol=1e-12)
    assert associate_detection(pred, None) is None


def test_det_baseline_follows_detections_with_fixed_size_and_coasts_through_misses():
    source = WallSource()
    dets = detections()
    for k in (5, 6):
        dets[k] = FrameDetections(np.zeros((0, 7)), np.zeros(0))   # missed frames
    result = track(source, START, config=get_preset("det"), detections=dets)
    truth = np.array([truth_x(k) for k in range(FRAMES)])
    assert np.all(np.abs(xs(result) - truth) < 0.15)
    assert all(np.allclose(b.size, START.size) for b in result.boxes)
    assert "prior_only" in result.estimates[5].flags and "det" in result.estimates[7].flags


class GapSource(WallSource):
    """The wall scene with frames 5..7 empty (no points at all)."""

    def lidar_frame(self, index: int) -> LidarFrame:
        frame = super().lidar_frame(index)
        if 5 <= index <= 7:
            return LidarFrame(index=index, timestamp_ns=frame.timestamp_ns, points_ego=np.zeros((0, 3)),
                              world_from_ego=np.eye(4))
        return frame


def test_a_frame_without_points_minimises_prior_plus_detection():
    """No points: the loss is MP + Det, minimised by the weighted mean of the two motions (flag det_only)."""
    source = GapSource()
    dets = detections(offset=0.0)
    dets[6] = FrameDetections(dets[6].boxes + np.array([0.6, 0, 0, 0, 0, 0, 0]), dets[6].scores)  # a jump
    config = get_preset("det_sot", **{"detection.weight": 0.1})
    coasting = track(source, START, config=get_preset("full"))
    result = track(source, START, config=config, detections=dets)
    assert "det_only" in result.estimates[6].flags and "prior_only" not in result.estimates[6].flags
    assert "prior_only" in coasting.estimates[6].flags
    step_prior = result.boxes[5].x - result.boxes[4].x       # the motion the prior predicts (constant here)
    expected = result.boxes[5].x + (0.1 * step_prior + 0.1 * (dets[6].boxes[0, 0] - result.boxes[5].x)) / 0.2
    assert abs(result.boxes[6].x - expected) < 0.15


def test_distance_gate_takes_the_nearest_confident_detection_when_no_iou_qualifies():
    pred = Box(0.0, 0.0, 0.0, 0.0, 4.0, 2.0, 1.5)
    dets = FrameDetections(np.array([[0.0, 4.0, 0.0, 0.0, 4.0, 2.0, 1.5], [0.0, -3.0, 0.0, 0.0, 4.0, 2.0, 1.5],
                                     [2.0, 0.0, 0.0, 0.0, 4.0, 2.0, 1.5]]), np.array([0.9, 0.9, 0.4]))
    assert associate_detection(pred, dets, 0.5, 0.1) is None                  # no BEV overlap: the paper's rule
    np.testing.assert_allclose(associate_detection(pred, dets, 0.5, 0.1, max_distance=5.0), dets.boxes[1])
    assert associate_detection(pred, dets, 0.5, 0.1, max_distance=2.5) is None  # the low-score one never counts
    overlapping = FrameDetections(np.vstack([dets.boxes, [[0.5, 0.0, 0.0, 0.0, 4.0, 2.0, 1.5]]]),
                                  np.array([0.9, 0.9, 0.4, 0.6]))
    np.testing.assert_allclose(associate_detection(pred, overlapping, 0.5, 0.1, 5.0), overlapping.boxes[3])


def test_distance_gate_reanchors_a_track_that_coasted_off_its_object():
    """Points vanish for three frames (an occlusion); the detections then sit 2 m beside the coasting
    prediction (no BEV overlap): only the distance gate lets them pull the track across."""
    source = GapSource()
    dets = {k: FrameDetections(np.array([[truth_x(k), 2.0 if k >= 5 else 0.0, 0.8, 0.0, 4.5, 1.9, 1.6]]),
                               np.array([0.9])) for k in range(1, FRAMES)}
    paper = track(source, START, config=get_preset("det_sot"), detections=dets)
    gated = track(source, START, config=get_preset("det_sot", **{"detection.max_distance": 5.0}), detections=dets)
    assert not any("det" in e.flags for e in paper.estimates[5:8])
    assert all("det_only" in e.flags for e in gated.estimates[5:8])
    assert abs(paper.boxes[7].y) < 0.05 and gated.boxes[7].y > 0.5
