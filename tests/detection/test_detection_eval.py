"""AP and identity coverage on hand-made cases with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from sot_apps.evaluation.detection import GroundTruthFrame, average_precision, identity_coverage
from tracker.detection import FrameDetections

CARS = np.array([[10.0, 0.0, 1.0, 0.0, 4.5, 1.9, 1.6], [30.0, 5.0, 1.0, 0.5, 4.5, 1.9, 1.6]])


def truth(n_frames: int = 4) -> dict[int, GroundTruthFrame]:
    return {k: GroundTruthFrame(CARS + [k, 0, 0, 0, 0, 0, 0], np.array([50, 50]), np.zeros(2), ("a", "b"))
            for k in range(n_frames)}


def test_ap_is_one_for_the_truth_and_falls_with_misses_and_false_positives():
    gt = truth()
    perfect = {k: FrameDetections(g.boxes, np.array([0.9, 0.8])) for k, g in gt.items()}
    assert average_precision(perfect, gt, 0.7)["ap"] == 1.0
    # only the first car: recall 0.5, precision 1 -> AP = 0.5 (20 of 40 recall points)
    half = {k: FrameDetections(g.boxes[:1], np.array([0.9])) for k, g in gt.items()}
    r = average_precision(half, gt, 0.7)
    assert r["recall"] == 0.5 and abs(r["ap"] - 0.5) < 1e-9
    # a confident false positive in every frame ranks first: precision drops at every recall
    fp = {k: FrameDetections(np.vstack([g.boxes, [[50, 50, 1, 0, 4.5, 1.9, 1.6]]]), np.array([0.8, 0.7, 0.95]))
          for k, g in gt.items()}
    assert average_precision(fp, gt, 0.7)["ap"] < 0.8
    # range bands: the far car (30 m) alone in the 20-40 m band
    assert average_precision(half, gt, 0.7, band=(20.0, 40.0))["ap"] == 0.0
    assert average_precision(half, gt, 0.7, band=(0.0, 20.0))["ap"] == 1.0


def test_identity_coverage_counts_one_track_per_object():
    gt = truth(4)
    whole = {"t1": {k: gt[k].boxes[0] for k in range(4)}, "t2": {k: gt[k].boxes[1] for k in range(4)}}
    assert identity_coverage(whole, gt)["coverage"] == 1.0
    # car a split into two tracks of 2 frames each: its best single track covers 2 of 4 frames
    split = {"t1a": {k: gt[k].boxes[0] for k in (0, 1)}, "t1b": {k: gt[k].boxes[0] for k in (2, 3)},
             "t2": whole["t2"]}
    assert identity_coverage(split, gt)["coverage"] == (2 + 4) / 8


def test_operating_point_counts_confident_detections_within_range():
    from sot_apps.evaluation.detection import operating_point

    gt = {0: GroundTruthFrame(CARS, np.array([60, 10]), np.zeros(2), ("a", "b"))}   # b has too few points
    fp = [[20.0, -8.0, 1.0, 0.0, 4.5, 1.9, 1.6]]
    far = [[50.0, 0.0, 1.0, 0.0, 4.5, 1.9, 1.6]]
    dets = {0: FrameDetections(np.vstack([CARS, fp, far, CARS[:1]]), np.array([0.9, 0.8, 0.7, 0.9, 0.3]))}
    point = operating_point(dets, gt)
    # recall: only car a counts (>= 50 points); precision: a is true, the fp false; the detection of b (a box
    # that does not count) is ignored, the unmatched far one (50 m) and the low-scored duplicate not scored
    assert point["n_gt"] == 1 and point["recall"] == 1.0
    assert point["n_det"] == 2 and abs(point["precision"] - 1 / 2) < 1e-9


def test_operating_point_ignores_detections_of_boxes_that_do_not_count():
    """KITTI's don't-care rule: a detection matched to a box beyond the range, with too few points or of another
    class is neither true nor false; the same detection with no box under it is false."""
    from sot_apps.evaluation.detection import OperatingPoint, operating_point

    boxes = np.array([[10.0, 0.0, 1.0, 0.0, 4.5, 1.9, 1.6], [0.0, 12.0, 1.0, 0.0, 4.5, 1.9, 1.6],
                      [41.0, 0.0, 1.0, 0.0, 4.5, 1.9, 1.6], [0.0, -15.0, 1.0, 0.0, 4.5, 1.9, 1.6]])
    gt = {0: GroundTruthFrame(boxes, np.array([80, 80, 80, 20]), np.zeros(2), ("a", "b", "c", "d"),
                              ("Car", "Towed Object", "Car", "Car"))}
    # detections of all four, the one of c (41 m) shifted to 39.5 m: within range, matched to a far box
    dets = boxes.copy()
    dets[2, 0] = 39.5
    point = operating_point({0: FrameDetections(dets, np.full(4, 0.9))}, gt, OperatingPoint(labels=("Car",)))
    assert point == {"recall": 1.0, "precision": 1.0, "n_gt": 1, "n_det": 1}
    # without boxes under them the three would be false positives
    alone = {0: GroundTruthFrame(boxes[:1], np.array([80]), np.zeros(2), ("a",), ("Car",))}
    point = operating_point({0: FrameDetections(dets, np.full(4, 0.9))}, alone, OperatingPoint(labels=("Car",)))
    assert point["n_det"] == 4 and point["precision"] == 0.25
    # every class counts when no labels are given: the towed object's box is then a true positive
    assert operating_point({0: FrameDetections(dets, np.full(4, 0.9))}, gt)["n_gt"] == 2


def test_ground_truth_boxes_keep_their_tilt_in_counts_and_3d_iou():
    """A pitched box (0.3 rad): the points inside it are all counted with its tilt (a level copy misses some), and
    a level detection of it scores the tilted 3D IoU (< 1) but the full footprint IoU."""
    from sot_apps.evaluation.detection import _pairwise_iou
    from sot_apps.objects.box_points import count_points_in_boxes
    from tracker import Box, iou_3d_batch, transform_points

    tilted = Box(10.0, 5.0, 1.0, 0.4, 4.0, 2.0, 1.5, roll=0.0, pitch=0.3)
    rng = np.random.default_rng(0)
    inside = rng.uniform(-0.49, 0.49, (500, 3)) * np.array([4.0, 2.0, 1.5])
    world = transform_points(tilted.world_from_object(), inside)
    row9 = np.array([[*tilted.to_array(), 0.0, 0.3]])
    assert count_points_in_boxes(world, row9)[0] == 500
    assert count_points_in_boxes(world, row9[:, :7])[0] < 500
    level = row9[:, :7]
    expected = iou_3d_batch(np.hstack([level, np.zeros((1, 2))]), row9)[0]
    assert 0.5 < expected < 0.99
    assert _pairwise_iou(level, row9, "3d")[0, 0] == pytest.approx(expected)
    assert _pairwise_iou(level, row9, "bev")[0, 0] == pytest.approx(1.0)
