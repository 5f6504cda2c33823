"""Auto-labels on the synthetic world (exact ground truth): every moving vehicle is recovered as one track."""

from __future__ import annotations

import numpy as np
import pyarrow.feather as feather
import pytest

from sot_apps.cli.main import main
from sot_apps.io import open_sequence
from sot_apps.io.detections import read_detections
from tracker.metrics import iou_3d_batch, iou_bev_batch


@pytest.fixture(scope="module")
def labelled(tmp_path_factory):
    root = tmp_path_factory.mktemp("autolabel")
    assert main(["synth", "--out", str(root / "world"), "--frames", "20", "--vehicles", "3", "--seed", "0"]) == 0
    assert main(["autolabel", str(root / "world"), "--simulate", "learned", "--seed", "0", "--out",
                 str(root / "labels"), "--quiet"]) == 0
    return root


def _best_match(gt_track, label_tracks):
    """(mean BEV IoU, mean 3D IoU) of the label track that overlaps ``gt_track`` best, over the GT frames."""
    truth = np.array([gt_track.box_at(k).to_array() for k in gt_track.frames])
    best = (0.0, 0.0)
    for lab in label_tracks.values():
        boxes = np.array([lab.box_at(k).to_array() if lab.box_at(k) is not None else [1e6, 1e6, 0, 0, 1, 1, 1]
                          for k in gt_track.frames])
        best = max(best, (float(iou_bev_batch(truth, boxes).mean()), float(iou_3d_batch(truth, boxes).mean())))
    return best


def test_every_moving_vehicle_is_recovered_by_one_track(labelled):
    world = open_sequence(labelled / "world")
    labels = open_sequence(labelled / "labels" / "sequence").tracks()
    moving = [t for tid, t in world.tracks().items() if tid.startswith("veh_")]
    assert len(moving) == 3
    for trk in moving:
        bev, iou3d = _best_match(trk, labels)
        assert bev >= 0.7, (trk.track_id, bev)
        assert iou3d >= 0.6, (trk.track_id, iou3d)


def test_the_three_label_formats_hold_the_same_boxes(labelled):
    world = open_sequence(labelled / "world")
    canonical = open_sequence(labelled / "labels" / "sequence")
    world_from_lidar = [np.asarray(f.world_from_ego) @ world.ego_from_lidar for f in world.frames]
    kitti = read_detections(labelled / "labels" / "kitti" / "label_02" / "0000.txt", world_from_lidar,
                            kitti_calib=labelled / "labels" / "kitti" / "calib" / "0000.txt")
    table = feather.read_table(labelled / "labels" / "av2" / "annotations.feather").to_pandas()
    for k in range(len(world)):
        ours = np.array([a.box.to_array() for a in canonical.annotations[k]]).reshape(-1, 7)
        assert len(kitti.get(k, ())) == len(ours) == int((table.timestamp_ns == world.frames[k].timestamp_ns).sum())
        if len(ours):
            order = np.lexsort(ours[:, :2].T)
            other = kitti[k].boxes[np.lexsort(kitti[k].boxes[:, :2].T)]
            np.testing.assert_allclose(other[:, [0, 1, 2, 4, 5, 6]], ours[order][:, [0, 1, 2, 4, 5, 6]], atol=1e-4)
    # AV2 boxes are in the ego frame: unit yaw quaternions, positive sizes
    np.testing.assert_allclose(table.qw ** 2 + table.qz ** 2, 1.0, atol=1e-9)
    assert (table[["length_m", "width_m", "height_m"]] > 0).all().all()
