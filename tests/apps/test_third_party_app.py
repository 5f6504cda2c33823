"""The example third-party app (examples/bev_grid_app): its grid on an analytic case, and the package installed
with pip into a directory of its own and run through ``sot-apps run`` like any user's plug-in."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from .conftest import tracking_doc

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "examples" / "bev_grid_app"


def _bev():
    sys.path.insert(0, str(EXAMPLE))
    try:
        import sot_apps_bev_grid
    finally:
        sys.path.remove(str(EXAMPLE))
    return sot_apps_bev_grid


def test_bev_grid_of_one_box_seen_from_a_turned_ego():
    """Ego at world (10, 5) facing world +y; a 4 x 2 m box 10 m ahead facing the same way, moving 5 m/s along
    world +y: in the ego grid it is 10 m ahead (x), 0 m aside, heading 0, moving +5 m/s along ego x."""
    bev = _bev()
    world_from_ego = np.eye(4)
    world_from_ego[:2, :2] = [[0.0, -1.0], [1.0, 0.0]]
    world_from_ego[:2, 3] = [10.0, 5.0]
    stamps = np.array([0, 1_000_000_000], np.int64)
    states = np.array([[10.0, 15.0, 0.0, np.pi / 2], [10.0, 20.0, 0.0, np.pi / 2]])
    occupancy, instance, velocity = bev.bev_grids(np.array([0]), world_from_ego[None], [
        (np.array([0, 1]), stamps, states, (4.0, 2.0))], extent_m=20.0, cell_m=0.5)
    assert occupancy.shape == (1, 80, 80)
    centres = -20.0 + 0.5 * (np.arange(80) + 0.5)
    rows, cols = np.nonzero(occupancy[0])
    assert len(rows) == 32                                   # 4 m x 2 m of 0.5 m cells
    assert np.allclose([centres[cols].min(), centres[cols].max()], [8.25, 11.75])
    assert np.allclose([centres[rows].min(), centres[rows].max()], [-0.75, 0.75])
    assert set(instance[0][occupancy[0] == 1]) == {0} and (instance[0][occupancy[0] == 0] == -1).all()
    assert np.allclose(velocity[0][occupancy[0] == 1], [5.0, 0.0], atol=1e-5)
    assert not velocity[0][occupancy[0] == 0].any()


def test_installed_example_app_runs_through_sot_apps_run(tmp_path, tiny_world):
    source = shutil.copytree(EXAMPLE, tmp_path / "bev_grid_app")   # the build leaves build/ and egg-info beside it
    target = tmp_path / "site"
    pip = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(target),
                          str(source)], capture_output=True, text=True, timeout=180)
    assert pip.returncode == 0, pip.stderr[-2000:]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(target), str(REPO)])}
    listing = subprocess.run([sys.executable, "-m", "sot_apps.cli.main", "apps", "--json"], env=env,
                             capture_output=True, text=True, timeout=120)
    assert listing.returncode == 0, listing.stderr
    apps = {d["name"]: d for d in json.loads(listing.stdout)}
    assert apps["bev_grid"]["module"] == "sot_apps_bev_grid"
    assert [f["field"] for f in apps["bev_grid"]["config"]] == ["extent_m", "cell_m", "min_quality"]

    out = tmp_path / "out"
    pipeline = tmp_path / "pipeline.json"
    pipeline.write_text(json.dumps(tracking_doc(tiny_world, out, bev_grid={"extent_m": 30, "cell_m": 0.5})))
    run = subprocess.run([sys.executable, "-m", "sot_apps.cli.main", "run", str(pipeline), "--quiet"], env=env,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    [path] = list(out.glob("*/bev_grid.npz"))
    grids = np.load(path)
    assert list(grids["object_ids"]) == ["veh_000", "veh_001", "veh_002"]
    assert grids["occupancy"].shape == (6, 120, 120)

    # against the annotated boxes (independent truth), rasterised the same way
    from sot_apps.io import open_sequence

    seq = open_sequence(tiny_world)
    tracks = seq.tracks()
    frames = np.arange(6)
    objects = []
    for oid in grids["object_ids"]:
        t = tracks[str(oid)]
        ks = np.array(sorted(t.frames))
        boxes = [t.box_at(int(k)) for k in ks]
        objects.append((ks, np.array([seq.frames[k].timestamp_ns for k in ks]),
                        np.array([[b.x, b.y, b.z, b.heading] for b in boxes]), (boxes[0].length, boxes[0].width)))
    truth, _, truth_velocity = _bev().bev_grids(frames, np.stack([seq.frames[k].world_from_ego for k in frames]),
                                                objects, 30.0, 0.5)
    tracked = grids["occupancy"].astype(bool)
    iou = (tracked & truth.astype(bool)).sum() / (tracked | truth.astype(bool)).sum()
    assert iou > 0.7, iou
    both = tracked & truth.astype(bool)
    speed_error = np.linalg.norm(grids["velocity_ego"][both] - truth_velocity[both], axis=1)
    assert np.median(speed_error) < 1.0, np.median(speed_error)

    manifest = json.loads((out / "manifest.json").read_text())
    units = [s for s in manifest["stages"] if s["stage"] == "bev_grid"]
    assert len(units) == 1 and units[0]["status"] == "done" and units[0]["result"]["objects"] == 3
    assert any(k.endswith("bev_grid.npz") for k in units[0]["outputs"])

    again = subprocess.run([sys.executable, "-m", "sot_apps.cli.main", "run", str(pipeline), "--quiet"], env=env,
                           capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    units = [s for s in json.loads((out / "manifest.json").read_text())["stages"] if s["stage"] == "bev_grid"]
    assert units[0]["status"] == "cached" and units[0]["result"]["objects"] == 3
