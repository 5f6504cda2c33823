"""Auto-label tracks from near-exact detections on a synthetic world (exact ground truth): one track per moving
vehicle over its frames, across a gap in its detections, with a duplicated start merged; chunking does not
change the labels."""

from __future__ import annotations

import numpy as np
import pytest

from sot_apps.cli.main import main
from sot_apps.detection.autolabel import LabelConfig, autolabel, per_frame_detections
from sot_apps.evaluation.detection import ground_truth_frames, identity_coverage, only_objects
from sot_apps.io import open_sequence
from sot_apps.io.cached_source import CachedSource
from tracker import get_preset
from tracker.metrics import iou_bev_batch

GAP = range(7, 13)        # frames where the gap vehicle has no detection (longer than max_misses: two tracks)
DUPLICATE = range(0, 4)   # frames where the duplicated vehicle has a second, shifted detection


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    root = tmp_path_factory.mktemp("autolabel_tracks")
    assert main(["synth", "--out", str(root / "world"), "--frames", "20", "--vehicles", "3", "--seed", "0"]) == 0
    return open_sequence(root / "world")


def _detections(world):
    """Every annotated vehicle's box with small noise (score 0.9); the first moving vehicle loses its detections
    over GAP; the second gets a duplicate shifted 0.6 m along its heading over DUPLICATE (score 0.8)."""
    rng = np.random.default_rng(0)
    moving = sorted(t for t in world.tracks() if t.startswith("veh_"))
    gap_id, duplicate_id = moving[0], moving[1]
    entries = []
    for k, frame_annotations in enumerate(world.annotations):
        for a in frame_annotations:
            box = a.box.to_array() + np.r_[rng.normal(0, 0.05, 3), rng.normal(0, 0.01), rng.normal(0, 0.03, 3)]
            if a.track_id == gap_id and k in GAP:
                continue
            entries.append((k, box, 0.9))
            if a.track_id == duplicate_id and k in DUPLICATE:
                shifted = box.copy()
                shifted[:2] += 0.6 * np.array([np.cos(box[3]), np.sin(box[3])])
                entries.append((k, shifted, 0.8))
    return per_frame_detections(entries), moving


def _labels(world, detections, chunk=None, offline=True):
    labels, tracks = autolabel(CachedSource(world), detections, get_preset("det_sot", seed=0), offline=offline,
                               label_config=LabelConfig(chunk=chunk))
    return labels, tracks


@pytest.fixture(scope="module")
def labelled(world):
    detections, moving = _detections(world)
    labels, tracks = _labels(world, detections)
    return detections, moving, labels, tracks


def test_every_moving_vehicle_is_one_track_across_a_gap_and_a_duplicated_start(world, labelled):
    _, moving, labels, tracks = labelled
    truth = only_objects(ground_truth_frames(world), moving)
    boxes = {lbl.track_id: {k: b.to_array() for k, b in lbl.boxes.items()} for lbl in labels}
    # the detections alone split the gap vehicle and double the duplicated one
    assert len(tracks) >= len(world.tracks()) + 2
    coverage = identity_coverage(boxes, truth, 0.5, min_points=5)
    assert coverage["objects"] == len(moving) == 3
    assert coverage["coverage"] >= 0.9, coverage
    for tid in moving:   # each moving vehicle overlaps exactly one label track (no duplicate, no fragment)
        frames = [k for k in range(len(world)) if tid in truth[k].track_ids]
        gt = np.array([truth[k].boxes[truth[k].track_ids.index(tid)] for k in frames])
        overlapping = []
        for name, track in boxes.items():
            shared = [i for i, k in enumerate(frames) if k in track]
            if shared and (iou_bev_batch(gt[shared], np.array([track[frames[i]] for i in shared])) >= 0.3).sum() >= 2:
                overlapping.append(name)
        assert len(overlapping) == 1, (tid, overlapping)


def test_the_gap_vehicle_is_labelled_through_its_gap(world, labelled):
    _, moving, labels, _ = labelled
    gap_id = moving[0]
    track = world.tracks()[gap_id]
    best = 0
    for lbl in labels:
        held = [k for k in GAP if k in lbl.boxes and k in track.frames
                and iou_bev_batch(track.box_at(k).to_array()[None], lbl.boxes[k].to_array()[None])[0] >= 0.5]
        best = max(best, len(held))
    assert best == len(GAP)


def test_labels_do_not_depend_on_chunking(world, labelled):
    detections, _, _, _ = labelled
    whole, _ = _labels(world, detections, chunk=None, offline=False)
    one_by_one, _ = _labels(world, detections, chunk=1, offline=False)
    assert [lbl.track_id for lbl in whole] == [lbl.track_id for lbl in one_by_one]
    for a, b in zip(whole, one_by_one, strict=True):
        assert sorted(a.boxes) == sorted(b.boxes)
        np.testing.assert_array_equal(np.array([a.boxes[k].to_array() for k in sorted(a.boxes)]),
                                      np.array([b.boxes[k].to_array() for k in sorted(b.boxes)]))
