"""Vehicle bank, simulate-lidar (scene files, background insertion), exports read back independently."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from sot_apps.cli.main import main
from sot_apps.io import open_sequence
from sot_apps.lidar_sim.export import kitti_label_lines
from sot_apps.lidar_sim.scene import SceneObject, SceneSpec, insert_into_background
from sot_apps.objects.bank import (
    Bank,
    aggregate_track_points,
    entries_from_annotations,
    entry_from_mesh_file,
    read_bank,
    write_bank_index,
)
from sot_apps.objects.trajectory import Trajectory
from sot_apps.sensor.model import PRESETS
from sot_apps.sensor.noise import Realism
from sot_apps.sensor.scan import SimObject, simulate_scan
from sot_apps.synth import make_world, write_world
from tracker.geometry import Box, transform_points

BOX_SIZE = (4.0, 2.0, 1.6)


@pytest.fixture()
def box_bank(tmp_path):
    mesh_path = tmp_path / "box_car.ply"
    trimesh.creation.box(extents=BOX_SIZE).export(mesh_path)
    bank = Bank(tmp_path / "bank")
    bank.upsert(entry_from_mesh_file(bank.root, mesh_path, label="Car"))
    write_bank_index(bank)
    return read_bank(bank.root)


def _segment_hits_box(points: np.ndarray, centre: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Slab test: does the segment origin -> point cross the axis-aligned box? (independent of Embree)"""
    d = points
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (centre - half) / d
        t2 = (centre + half) / d
    tmin = np.nanmax(np.minimum(t1, t2), axis=1)
    tmax = np.nanmin(np.maximum(t1, t2), axis=1)
    return (tmax >= np.maximum(tmin, 0.0)) & (tmin < 1.0)


def test_background_insertion_removes_exactly_the_occluded_returns(box_bank):
    rng = np.random.default_rng(0)
    # background: a wall at x = 30 and ground at z = -1.8 in front of the sensor, plus points behind it
    wall = np.column_stack([np.full(4000, 30.0), rng.uniform(-15, 15, 4000), rng.uniform(-1.8, 3.0, 4000)])
    ground = np.column_stack([rng.uniform(2, 40, 6000), rng.uniform(-15, 15, 6000), np.full(6000, -1.8)])
    behind = np.column_stack([rng.uniform(-30, -5, 1000), rng.uniform(-10, 10, 1000), rng.uniform(-1.8, 1, 1000)])
    bg = np.vstack([wall, ground, behind])
    centre = np.array([15.0, 1.0, -1.8 + BOX_SIZE[2] / 2])
    half = np.array(BOX_SIZE) / 2
    grown = _segment_hits_box(bg, centre, half + 2e-3)
    shrunk = _segment_hits_box(bg, centre, half - 2e-3)
    bg = bg[grown == shrunk]             # drop rays that graze the box's silhouette within 2 mm
    truth = _segment_hits_box(bg, centre, half)
    assert 200 < truth.sum() < len(bg) // 2
    spec = SceneSpec(PRESETS["pandar64"], None, [SceneObject(box_bank.entries[0].id, 15.0, 1.0, None, 0.0)],
                     Realism.ideal())
    result = insert_into_background(spec, box_bank, bg.astype(np.float32))
    kept = result.scan.extra["background_kept"]
    np.testing.assert_array_equal(~kept, truth)
    assert result.removed_background == truth.sum()
    # z was taken from the local ground; vehicle returns lie on the box surface
    assert result.boxes[0].z == pytest.approx(centre[2], abs=1e-6)
    veh = result.scan.xyz[result.scan.instance == 0].astype(np.float64)
    assert len(veh) > 100
    local = np.abs(veh - centre)
    assert (local <= half + 1e-3).all()
    assert (np.abs(local - half) < 1e-3).any(axis=1).all()


def test_real_object_in_front_hides_inserted_vehicle(box_bank):
    # a dense 'pole' sheet at x = 8 covering azimuths |az| < 3 deg, in front of a vehicle at x = 20
    el = np.radians(np.linspace(-25, 15, 400))
    az = np.radians(np.linspace(-3, 3, 200))
    E, A = np.meshgrid(el, az)
    r = 8.0 / (np.cos(E) * np.cos(A))
    sheet = np.stack([r * np.cos(E) * np.cos(A), r * np.cos(E) * np.sin(A), r * np.sin(E)], axis=-1).reshape(-1, 3)
    spec = SceneSpec(PRESETS["pandar64"], -1.8, [SceneObject(box_bank.entries[0].id, 20.0, 1.5, None, 0.0)],
                     Realism.ideal())
    result = insert_into_background(spec, box_bank, sheet.astype(np.float32))
    veh = result.scan.xyz[result.scan.instance == 0]
    veh_az = np.degrees(np.arctan2(veh[:, 1], veh[:, 0]))
    assert result.removed_vehicle > 50
    assert len(veh) > 50 and (np.abs(veh_az) > 2.8).all()


def test_kitti_labels_match_box_corners():
    box = Box(12.0, -3.0, -0.9, 0.7, 4.5, 1.9, 1.6)
    fields = kitti_label_lines([box], ["Car"])[0].split()
    h, w, l = (float(v) for v in fields[8:11])
    x, y, z, ry = (float(v) for v in fields[11:15])
    # KITTI devkit corner construction (camera frame, location = bottom centre)
    xc = [l / 2, l / 2, -l / 2, -l / 2, l / 2, l / 2, -l / 2, -l / 2]
    yc = [0, 0, 0, 0, -h, -h, -h, -h]
    zc = [w / 2, -w / 2, -w / 2, w / 2, w / 2, -w / 2, -w / 2, w / 2]
    R = np.array([[math.cos(ry), 0, math.sin(ry)], [0, 1, 0], [-math.sin(ry), 0, math.cos(ry)]])
    cam = (R @ np.array([xc, yc, zc])).T + [x, y, z]
    lidar = np.column_stack([cam[:, 2], -cam[:, 0], -cam[:, 1]])
    expected = box.corners()
    dist = np.linalg.norm(lidar[:, None, :] - expected[None, :, :], axis=2)
    assert dist.min(axis=1).max() < 1e-3


def test_simulate_lidar_cli_outputs_read_back(box_bank, tmp_path, capsys):
    scene = {"sensor": "vlp16", "ground_z": -1.8,
             "objects": [{"bank_id": box_bank.entries[0].id, "x": 10.0, "y": 0.0, "heading": 0.3},
                         {"bank_id": box_bank.entries[0].id, "x": -8.0, "y": 6.0, "z": None, "heading": 2.0}]}
    (tmp_path / "scene.json").write_text(json.dumps(scene))
    out = tmp_path / "sim"
    assert main(["simulate-lidar", "--bank", str(box_bank.root), "--scene", str(tmp_path / "scene.json"),
                 "--out", str(out), "--format", "bin,pcd,ply"]) == 0
    data = np.load(out / "scan.npz")
    xyz, inst, intensity = data["xyz"], data["instance"], data["intensity"]
    assert xyz.dtype == np.float32 and inst.dtype == np.int32 and set(np.unique(inst)) == {-1, 0, 1}
    # .bin: plain numpy
    binary = np.fromfile(out / "scan.bin", dtype="<f4").reshape(-1, 4)
    np.testing.assert_array_equal(binary[:, :3], xyz)
    np.testing.assert_array_equal(binary[:, 3], intensity)
    # .ply: trimesh
    cloud = trimesh.load(out / "scan.ply")
    np.testing.assert_allclose(np.asarray(cloud.vertices), xyz, atol=1e-6)
    # .pcd: a plain parse of the header + binary body
    raw = (out / "scan.pcd").read_bytes()
    head_end = raw.index(b"DATA binary\n") + len(b"DATA binary\n")
    header = dict(line.split(" ", 1) for line in raw[:head_end].decode().splitlines() if not line.startswith("#"))
    assert header["FIELDS"].split() == ["x", "y", "z", "intensity", "instance"] and int(header["POINTS"]) == len(xyz)
    body = np.frombuffer(raw[head_end:], dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("i", "<f4"), ("n", "<i4")])
    np.testing.assert_array_equal(np.column_stack([body["x"], body["y"], body["z"]]), xyz)
    np.testing.assert_array_equal(body["n"], inst)
    boxes = json.loads((out / "boxes.json").read_text())["boxes"]
    assert [b["num_points"] for b in boxes] == [int((inst == 0).sum()), int((inst == 1).sum())]
    assert boxes[1]["z"] == pytest.approx(-1.8 + BOX_SIZE[2] / 2)
    assert len((out / "labels_kitti.txt").read_text().splitlines()) == 2
    assert (out / "preview.png").stat().st_size > 1000
    assert data["range_image"].shape == (16, 1800)


def test_bank_from_annotations_recovers_the_true_shape(tmp_path):
    world = make_world(frames=4, vehicles=1, sensor="pandar64", seed=5, parked=2,
                       realism=Realism(range_noise=False, drop_grazing=False, motion_distortion=True))
    write_world(tmp_path / "w", world=world)
    seq = open_sequence(tmp_path / "w")
    track = "veh_000"
    points, frames, box = aggregate_track_points(seq, track)
    assert frames == [0, 1, 2, 3] and len(points) > 200
    gt = world.objects[0]
    mesh = trimesh.Trimesh(gt.vertices, gt.faces, process=False)
    # points (de-skewed with the interpolated GT boxes) lie on the true surface (dense surface samples)
    surface, _ = trimesh.sample.sample_surface(mesh, 300_000, seed=0)
    dist, _ = cKDTree(surface).query(points)
    assert np.median(dist) < 0.01 and np.percentile(dist, 95) < 0.06
    bank_root = tmp_path / "bank"
    entries, skipped = entries_from_annotations(bank_root, seq, [track], mirror=True, min_points=10)
    assert not skipped and entries[0].size["length"] == pytest.approx(gt.size[0])
    bank = Bank(bank_root, entries)
    write_bank_index(bank)
    vertices, faces = read_bank(bank_root).mesh(entries[0].id)
    # mirror completion: the mesh is symmetric about the length axis
    ys = np.sort(vertices[:, 1])
    assert ys[0] == pytest.approx(-ys[-1], abs=0.05)
    assert main(["bank", "list", str(bank_root)]) == 0


def test_bank_build_from_tracker_output_dir(tmp_path, capsys):
    from sot_apps.io.object_track import ObjectTrack
    from sot_apps.io.tracks import TrackHeader, write_track
    from sot_apps.synth.vehicles import make_vehicle

    vehicle = make_vehicle("suv", 4.6, 1.9, 1.7)
    shape, _ = trimesh.sample.sample_surface(trimesh.Trimesh(vehicle.vertices, vehicle.faces, process=False), 5000, seed=0)
    shape = shape[shape[:, 1] > -0.2]          # one side seen only
    track = ObjectTrack.from_states("car7", "Car", (4.6, 1.9, 1.7), [0, 1], [1_000_000_000, 1_100_000_000],
                                    [[10.0, 2.0, 0.85, 0.0], [11.0, 2.0, 0.85, 0.0]], None, scores=[0.9, 0.7],
                                    num_points=[300, 300], shape_points=shape)
    write_track(tmp_path / "track_car7", TrackHeader("seqA", 0, 1, Box(10.0, 2.0, 0.85, 0.0, 4.6, 1.9, 1.7),
                                                     {"preset": "default"}), track)
    bank_dir = tmp_path / "bank"
    assert main(["bank", "build", str(tmp_path / "track_car7"), "--mirror", "--out", str(bank_dir)]) == 0
    bank = read_bank(bank_dir)
    (entry,) = bank.entries
    assert entry.id == "seqA_car7" and entry.source["kind"] == "track" and entry.mirrored
    assert entry.quality == pytest.approx(0.8) and entry.size == {"length": 4.6, "width": 1.9, "height": 1.7}
    vertices, _ = bank.mesh(entry.id)
    assert vertices[:, 1].min() < -0.8       # mirror completion filled the unseen side
    out = capsys.readouterr().out
    assert main(["bank", "list", str(bank_dir)]) == 0
    assert "seqA_car7" in capsys.readouterr().out and "seqA_car7" in out


def test_labels_say_what_the_sensor_saw(box_bank, tmp_path):
    """Issue 16, defect 6: a vehicle with 0 simulated points was labelled KITTI occluded=0."""
    from sot_apps.lidar_sim.simulate import run_simulation

    entry = box_bank.entries[0].id
    objects = [SceneObject(entry, 10.0, 0.0, 0.0, 0.0),      # A: in front, fully visible
               SceneObject(entry, 30.0, 0.0, -1.0, 0.0),     # B: right behind A, fully hidden
               SceneObject(entry, 30.0, 3.0, -1.0, 0.0),     # C: behind A's edge, partly hidden
               SceneObject(entry, 15.0, -10.0, 0.0, 0.0)]    # D: alone, fully visible
    spec = SceneSpec(PRESETS["pandar64"], None, objects, Realism.ideal())
    out = run_simulation(spec, box_bank, tmp_path / "sim")
    counts = [int((out.result.scan.instance == i).sum()) for i in range(4)]
    assert counts[0] > 100 and counts[1] == 0 and counts[2] > 0 and counts[3] > 100
    boxes = json.loads((tmp_path / "sim" / "boxes.json").read_text())["boxes"]
    assert [b["num_points"] for b in boxes] == counts
    assert [b["visible"] for b in boxes] == [True, False, True, True]
    share = [b["visible_share"] for b in boxes]
    assert share[0] > 0.95 and share[3] > 0.95 and share[1] == 0.0 and 0.05 < share[2] < 0.8
    assert [b["occluded"] for b in boxes][:1] == [0] and boxes[2]["occluded"] in (1, 2) and boxes[3]["occluded"] == 0
    # KITTI labels: only what the sensor saw, with its occlusion level; the hidden vehicle is left out
    lines = (tmp_path / "sim" / "labels_kitti.txt").read_text().splitlines()
    assert len(lines) == 3
    assert [int(line.split()[2]) for line in lines] == [boxes[i]["occluded"] for i in (0, 2, 3)]
    assert all(float(line.split()[1]) == boxes[i]["truncated"] for line, i in zip(lines, (0, 2, 3), strict=True))


def _on_box_surface(points: np.ndarray, box: Box, tol: float = 2e-3) -> tuple[np.ndarray, np.ndarray]:
    """(inside the box within tol, on one of its faces within tol) per point, in the box's object frame."""
    local = np.abs(transform_points(box.object_from_world(), points.astype(np.float64)))
    half = box.size / 2.0
    return (local <= half + tol).all(axis=1), (np.abs(local - half) < tol).any(axis=1)


def test_tilted_scene_vehicle_returns_lie_on_the_tilted_box(box_bank, tmp_path):
    """A scene vehicle with roll and pitch is ray cast tilted: every return lies on the faces of its tilted box
    (boxes.json keeps the tilt), and not all of them inside the level box of the same centre and heading."""
    scene = {"sensor": "pandar64", "ground_z": None, "realism": {"range_noise": False, "drop_random": 0.0},
             "objects": [{"bank_id": box_bank.entries[0].id, "x": 9.0, "y": 2.0, "z": -0.6, "heading": 0.4,
                          "roll": 0.25, "pitch": -0.3}]}
    (tmp_path / "scene.json").write_text(json.dumps(scene))
    out = tmp_path / "sim"
    assert main(["simulate-lidar", "--bank", str(box_bank.root), "--scene", str(tmp_path / "scene.json"),
                 "--out", str(out), "--format", "bin"]) == 0
    xyz = np.load(out / "scan.npz")["xyz"]
    written = json.loads((out / "boxes.json").read_text())["boxes"][0]
    assert (written["roll"], written["pitch"]) == (0.25, -0.3)
    tilted = Box(9.0, 2.0, -0.6, 0.4, *BOX_SIZE, roll=0.25, pitch=-0.3)
    inside, on_face = _on_box_surface(xyz, tilted)
    assert len(xyz) > 200 and inside.all() and on_face.all()
    assert not _on_box_surface(xyz, Box(9.0, 2.0, -0.6, 0.4, *BOX_SIZE))[0].all()


def test_moving_tilted_object_is_cast_tilted(box_bank):
    """The moving-object path (a trajectory of several samples) places the mesh with its roll and pitch too."""
    vertices, faces = box_bank.mesh(box_bank.entries[0].id)
    pose = [8.0, -3.0, -0.5, -0.6]
    trajectory = Trajectory.from_samples([0, 100_000_000], [pose, pose], tilts=[[-0.2, 0.35], [-0.2, 0.35]])
    assert not trajectory.is_static
    scan = simulate_scan(PRESETS["pandar64"], [SimObject(vertices, faces, trajectory, instance=0)], np.eye(4),
                         realism=Realism.ideal())
    inside, on_face = _on_box_surface(scan.xyz, Box(*pose, *BOX_SIZE, roll=-0.2, pitch=0.35))
    assert len(scan.xyz) > 200 and inside.all() and on_face.all()
