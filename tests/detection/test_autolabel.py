"""Auto-labels on the synthetic world (exact ground truth): every moving vehicle is recovered as one track."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.feather as feather
import pytest

from sot_apps.cli.main import main
from sot_apps.io import open_sequence
from sot_apps.io.detections import read_detections
from tracker.metrics import iou_3d_batch, iou_bev_batch

FRONT_K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 180.0], [0.0, 0.0, 1.0]])
# a front camera 1.5 m up, looking along ego +x (OpenCV axes: x right = -y ego, y down = -z ego, z = +x ego)
EGO_FROM_FRONT = np.array([[0.0, 0.0, 1.0, 1.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 1.5], [0.0, 0.0, 0.0, 1.0]])


def _add_front_camera(path):
    """A calibration-only front camera (no images) in a canonical sequence.json: KITTI labels need a camera."""
    doc = json.loads(path.read_text())
    doc["cameras"] = {"front": {"K": FRONT_K.tolist(), "distortion": [0.0] * 5, "width": 640, "height": 360,
                                "ego_from_camera": EGO_FROM_FRONT.tolist(), "frames": []}}
    path.write_text(json.dumps(doc))


@pytest.fixture(scope="module")
def labelled(tmp_path_factory):
    root = tmp_path_factory.mktemp("autolabel")
    assert main(["synth", "--out", str(root / "world"), "--frames", "20", "--vehicles", "3", "--seed", "0"]) == 0
    _add_front_camera(root / "world" / "sequence.json")
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
        assert iou3d >= 0.7, (trk.track_id, iou3d)


def test_the_label_formats_hold_the_same_boxes(labelled):
    """KITTI holds the labels the front camera sees (with 2D boxes and scores), AV2 all of them (with scores in
    the submission table): the same boxes as the canonical copy."""
    world = open_sequence(labelled / "world")
    canonical = open_sequence(labelled / "labels" / "sequence")
    world_from_lidar = [np.asarray(f.world_from_ego) @ world.ego_from_lidar for f in world.frames]
    kitti = read_detections(labelled / "labels" / "kitti" / "label_02" / "0000.txt", world_from_lidar,
                            kitti_calib=labelled / "labels" / "kitti" / "calib" / "0000.txt")
    rows = [line.split() for line in (labelled / "labels" / "kitti" / "label_02" / "0000.txt").read_text().splitlines()]
    assert rows and all(len(r) == 18 and min(float(v) for v in r[6:10]) >= 0 for r in rows)  # 2D box, score
    table = feather.read_table(labelled / "labels" / "av2" / "annotations.feather").to_pandas()
    submission = feather.read_table(labelled / "labels" / "av2" / "submission.feather").to_pandas()
    assert len(submission) == len(table) and submission.score.between(0, 1).all() and submission.score.min() < 1
    assert set(table.category) == {"REGULAR_VEHICLE"}
    seen = 0
    for k in range(len(world)):
        ours = np.array([a.box.to_array() for a in canonical.annotations[k]]).reshape(-1, 7)
        assert len(ours) == int((table.timestamp_ns == world.frames[k].timestamp_ns).sum())
        ego = ours[:, :3] - world.frames[k].world_from_ego[:3, 3]
        ego = ego @ world.frames[k].world_from_ego[:3, :3]
        ahead = int((ego[:, 0] > 4.0 + 1.2 * np.abs(ego[:, 1]) * 500 / 320).sum())   # well inside the view
        found = kitti[k].boxes if k in kitti else np.zeros((0, 7))
        assert ahead <= len(found) <= len(ours)
        for box in found:   # each KITTI box is one of the labels
            assert np.abs(ours[:, [0, 1, 2, 4, 5, 6]] - box[[0, 1, 2, 4, 5, 6]]).max(axis=1).min() < 1e-4
        seen += len(found)
    assert seen > 0
    # AV2 boxes are in the ego frame (level here: the synthetic ego does not tilt), positive sizes
    np.testing.assert_allclose(table.qw ** 2 + table.qz ** 2, 1.0, atol=1e-9)
    assert (table[["length_m", "width_m", "height_m"]] > 0).all().all()


class _BoxOnGround:
    """Frames whose points are the surface of one known box standing on a ground plane (z = 0), seen from the
    sides listed in ``faces`` (+x, -x, +y, -y, top), plus the ground around it."""

    def __init__(self, truth, faces, frames=5):
        rng = np.random.default_rng(1)
        l, w, h = truth.length, truth.width, truth.height
        u, v, z = rng.uniform(-0.5, 0.5, (3, 4000))
        sides = {"+x": np.column_stack([np.full(4000, l / 2), v * w, (z + 0.5) * h]),
                 "-x": np.column_stack([np.full(4000, -l / 2), v * w, (z + 0.5) * h]),
                 "+y": np.column_stack([u * l, np.full(4000, w / 2), (z + 0.5) * h]),
                 "-y": np.column_stack([u * l, np.full(4000, -w / 2), (z + 0.5) * h]),
                 "top": np.column_stack([u * l, v * w, np.full(4000, h)])}
        local = np.vstack([sides[f] for f in faces])
        c, s = np.cos(truth.heading), np.sin(truth.heading)
        body = np.column_stack([truth.x + c * local[:, 0] - s * local[:, 1],
                                truth.y + s * local[:, 0] + c * local[:, 1], local[:, 2]])
        ground = np.column_stack([truth.x + rng.uniform(-5, 5, 6000), truth.y + rng.uniform(-5, 5, 6000),
                                  rng.normal(0.0, 0.01, 6000)])
        self.points = np.vstack([body, ground])
        self.n = frames

    def __len__(self):
        return self.n

    def lidar_frame(self, index):
        from tracker.frames import LidarFrame

        return LidarFrame(index=index, timestamp_ns=index * 100_000_000, points_ego=self.points,
                          world_from_ego=np.eye(4))


def test_fit_to_points_reads_the_box_from_the_points_where_both_faces_show():
    from sot_apps.detection.autolabel import fit_to_points
    from tracker.geometry import Box

    truth = Box(10.0, 5.0, 0.75, 0.3, 4.5, 1.8, 1.5)
    # the detector's bias: 0.25 m too far along, 0.15 m across, 0.12 m high, every size 6 % too large
    c, s = np.cos(truth.heading), np.sin(truth.heading)
    biased = Box(truth.x + 0.25 * c - 0.15 * s, truth.y + 0.25 * s + 0.15 * c, truth.z + 0.12, truth.heading,
                 4.77, 1.91, 1.59)
    before = float(iou_3d_batch(truth.to_array()[None], biased.to_array()[None])[0])
    fitted = fit_to_points(_BoxOnGround(truth, ["+x", "-x", "+y", "-y", "top"]), {k: biased for k in range(5)})
    after = np.array([b.to_array() for b in fitted.values()])
    assert before < 0.75
    assert iou_3d_batch(np.tile(truth.to_array(), (5, 1)), after).min() > 0.93
    # one long side only (-y, as seen level from the side): the width stays, the box moves just enough to
    # hold the points across; the side shows the length and the height
    partial = fit_to_points(_BoxOnGround(truth, ["-y"]), {0: biased})[0]
    assert partial.width == pytest.approx(biased.width)
    local_v = -s * (partial.x - truth.x) + c * (partial.y - truth.y)
    assert local_v - partial.width / 2 == pytest.approx(-truth.width / 2, abs=0.03)
    assert partial.length == pytest.approx(truth.length, abs=0.05)
    assert partial.height == pytest.approx(truth.height, abs=0.05)


def test_detection_sigma_grows_when_errors_repeat_from_frame_to_frame():
    from sot_apps.detection.autolabel import detection_sigma
    from sot_apps.io.object_track import ObjectTrack
    from tracker.geometry import Box

    rng = np.random.default_rng(0)
    n = 60
    iid = rng.normal(0.0, 0.2, n)
    correlated = np.full(n, rng.normal(0.0, 0.2))  # starts from the stationary spread
    for k in range(1, n):  # AR(1), rho 0.9, the same marginal spread
        correlated[k] = 0.9 * correlated[k - 1] + np.sqrt(1 - 0.81) * rng.normal(0.0, 0.2)
    boxes = {k: Box(0.0, 0.0, 0.0, 0.0, 4.0, 2.0, 1.5) for k in range(n)}

    def sigma(errors):
        track = ObjectTrack("t", "", np.arange(n), [[e, 0.0, 0.0, 0.0, 4.0, 2.0, 1.5] for e in errors],
                            scores=np.full(n, 0.9))
        return detection_sigma(boxes, track)[0][0]

    assert sigma(iid) == pytest.approx(0.2 / np.sqrt(n), rel=0.35)
    assert sigma(correlated) > 1.5 * sigma(iid)  # rho 0.9: n_eff ~ n / 19 (estimated rho from 60 samples is lower)
    few = ObjectTrack("t", "", [0, 1], np.zeros((2, 7)), scores=[0.9, 0.9])
    assert np.isinf(detection_sigma(boxes, few)[0]).all()
