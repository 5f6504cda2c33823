"""End to end on one real PandaSet pair: ``sot-apps flow --from-annotations`` for 8ac00bad, front camera."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from sot_apps.cli.main import main
from sot_apps.flow.kitti_io import read_kitti_flow
from sot_apps.schemas import validate


@pytest.mark.slow
def test_flow_from_annotations_on_pandaset_pair(pandaset_root, pandaset, tmp_path):
    out = tmp_path / "flow"
    args = [str(pandaset_root), "--from-annotations", "--track-id", "8ac00bad", "--camera", "front_camera",
            "--pairs", "4:5", "--shape-frames", "0:10", "--out", str(out), "--quiet", "--vis"]
    assert main(["flow", *args]) == 0
    root = out / "front_camera"
    instance = cv2.imread(str(root / "instances" / "000004.png"), cv2.IMREAD_UNCHANGED)
    assert instance.dtype == np.uint16 and instance.shape == (1080, 1920)
    mapping = json.loads((root / "instances.json").read_text())["instances"]
    assert [m["object_id"][:8] for m in mapping] == ["8ac00bad"]
    mask = instance == 1
    assert mask.sum() > 20000  # a car ~10 m ahead covers a large part of the image
    # Independent check: the mask lies inside the annotated box projected at the camera time (+ slack).
    camera = pandaset.cameras["front_camera"]
    tid = pandaset.resolve_track_id("8ac00bad")
    box = pandaset.tracks()[tid].box_at(4)
    cam_from_world = np.linalg.inv(camera.frames[4].world_from_camera)
    corners = box.scaled(1.15).corners() @ cam_from_world[:3, :3].T + cam_from_world[:3, 3]
    uv = (corners @ camera.K.T)[:, :2] / corners[:, 2:]
    hull = np.zeros_like(instance, dtype=np.uint8)
    cv2.fillConvexPoly(hull, cv2.convexHull(np.round(uv).astype(np.int32)), 1)
    assert (hull[mask] == 1).mean() > 0.99
    # The object covers most of its projected box (a dense mask, not scattered points).
    assert mask.sum() > 0.4 * hull.sum()
    flow, valid = read_kitti_flow(root / "flow_occ" / "000004.png")
    _, valid_noc = read_kitti_flow(root / "flow_noc" / "000004.png")
    assert (valid == mask).all()
    assert (valid_noc <= valid).all() and valid_noc.sum() > 0.5 * valid.sum()
    assert np.isfinite(flow[valid]).all() and np.abs(flow[valid]).max() < 100
    flo = cv2.readOpticalFlow(str(root / "flo" / "000004.flo"))
    assert np.abs(flo[valid] - flow[valid]).max() <= 0.5 / 64 + 1e-6
    stats = json.loads((root / "stats.json").read_text())
    validate("flow_stats", stats, root / "stats.json")
    assert stats["pairs"][0]["pixels"] == int(mask.sum())
    assert (root / "vis" / "000004_flow.png").is_file() and (root / "vis" / "000004_overlay.jpg").is_file()
    # Rerun resumes: the finished pair is skipped and nothing changes.
    before = (root / "flow_occ" / "000004.png").stat().st_mtime_ns
    assert main(["flow", *args]) == 0
    assert (root / "flow_occ" / "000004.png").stat().st_mtime_ns == before
