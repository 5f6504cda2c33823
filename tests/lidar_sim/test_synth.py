"""The synthetic world: determinism, exact per-point ground truth under rolling scan, camera images."""

from __future__ import annotations

import filecmp
import json

import cv2
import numpy as np

from sot_apps.io import open_sequence
from sot_apps.objects.trajectory import Trajectory, world_from_object
from sot_apps.sensor.noise import Realism
from sot_apps.synth import make_world, write_world
from tracker.geometry import invert_transform, transform_points


def _tree(root):
    return sorted(p.relative_to(root) for p in root.rglob("*") if p.is_file())


def test_same_seed_gives_identical_bytes(tmp_path):
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    kwargs = dict(frames=3, vehicles=2, sensor="vlp16", cameras=True, camera_size=(64, 48))
    write_world(a, seed=7, **kwargs)
    write_world(b, seed=7, **kwargs)
    write_world(c, seed=8, **kwargs)
    files = _tree(a)
    assert files == _tree(b) and len(files) > 10
    for rel in files:
        assert filecmp.cmp(a / rel, b / rel, shallow=False), rel
    assert not filecmp.cmp(a / "points" / "000000.npz", c / "points" / "000000.npz", shallow=False)
    seq = open_sequence(a)
    assert len(seq) == 3 and seq.annotations is not None
    assert {ann.track_id for ann in seq.annotations[0]} >= {"veh_000", "veh_001"}
    gt = json.loads((a / "gt" / "objects.json").read_text())
    assert [o["id"] for o in gt["objects"]] == [ann.track_id for ann in seq.annotations[0]]


def test_points_lie_on_their_object_at_their_own_time():
    """Rolling scan: de-skewing each labelled point with the GT trajectory at its firing time puts it in the box."""
    world = make_world(frames=6, vehicles=3, sensor="vlp16", seed=2,
                       realism=Realism(range_noise=False, drop_grazing=False, intensity=False, motion_distortion=True))
    k = 5
    t = int(world.frame_times_ns[k])
    scan = world.scan(k)
    world_from_ego = world.world_from_ego(t)
    pts_world = transform_points(world_from_ego, scan.xyz)
    moved_any = False
    for i, obj in enumerate(world.objects):
        sel = scan.instance == i
        if sel.sum() < 5:
            continue
        states = obj.trajectory.states_at(t + scan.time_offset_ns[sel])
        obj_from_world = np.linalg.inv(world_from_object(states))
        local = np.einsum("nij,nj->ni", obj_from_world[:, :3, :3], pts_world[sel]) + obj_from_world[:, :3, 3]
        half = np.asarray(obj.size) / 2 + 2e-3
        assert (np.abs(local) <= half).all(), obj.id
        # ... and NOT all in the box at the frame time for a vehicle that moved during the sweep
        box_local = transform_points(invert_transform(world_from_object(obj.trajectory.states_at(t))), pts_world[sel])
        if obj.moving and (np.abs(box_local) > half).any():
            moved_any = True
    assert moved_any, "expected visible rolling-scan distortion on at least one moving vehicle"
    # background points are on the ground or on static clutter (ground: z = 0)
    assert (np.abs(pts_world[scan.instance == -1][:, 2]) < 6.0).all()


def test_camera_image_shows_vehicle_where_projection_says(tmp_path):
    world = make_world(frames=2, vehicles=1, sensor="vlp16", seed=4, cameras=True, camera_size=(160, 96), parked=0)
    cam = world.cameras[0]
    t_cam = int(world.frame_times_ns[1] + cam.time_offset_ns)
    ego = world.world_from_ego(t_cam)
    # park the vehicle 12 m ahead of the camera, on the ground
    obj = world.objects[0]
    ahead = transform_points(ego, np.array([[13.2, 0.0, 0.0]]))[0]
    obj.trajectory = Trajectory.static(ahead[0], ahead[1], obj.size[2] / 2, 0.3)
    obj.color = (0.9, 0.1, 0.1)
    write_world(tmp_path / "w", world=world)
    seq = open_sequence(tmp_path / "w")
    camera = seq.cameras["front_camera"]
    frame = camera.frames[1]
    assert frame.timestamp_ns == t_cam
    image = cv2.imread(str(frame.image_path))
    assert image.shape == (96, 160, 3)
    centre_cam = transform_points(invert_transform(frame.world_from_camera), np.array([[ahead[0], ahead[1], obj.size[2] / 2]]))[0]
    uv = camera.K @ centre_cam / centre_cam[2]
    u, v = int(round(uv[0])), int(round(uv[1]))
    b, g, r = (float(x) for x in image[v, u])
    assert r > 2 * g and r > 2 * b, (r, g, b)   # the red vehicle
    b, g, r = (float(x) for x in image[2, u])    # sky above it: bluish
    assert b > r
