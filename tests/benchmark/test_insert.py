"""Occlusion both ways, in a hand-made background: a wall in front of / behind an inserted vehicle."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from sot_apps.benchmark.deps import RaycastScene, Realism, SimObject, Trajectory, load_sensor, simulate_scan
from sot_apps.benchmark.insert import simulate_frame
from sot_apps.benchmark.placement import InsertedVehicle
from sot_apps.io.sequence import FrameInfo, Sequence, Sweep
from sot_apps.objects.motion_profiles import MotionSpec
from sot_apps.synth.vehicles import make_vehicle
from tracker.geometry import points_in_box

T0 = 1_700_000_000_000_000_000
GROUND_Z = -1.8


def _wall_background(wall_x: float) -> tuple[Sequence, object]:
    sensor = load_sensor("pandar64")
    box = trimesh.creation.box(extents=[0.3, 20.0, 6.0])
    wall = SimObject(np.asarray(box.vertices) + [wall_x, 0.0, 1.0], np.asarray(box.faces), Trajectory.static(0, 0, 0, 0))
    ground = SimObject(np.array([[-80, -80, GROUND_Z], [80, -80, GROUND_Z], [80, 80, GROUND_Z], [-80, 80, GROUND_Z]], float),
                       np.array([[0, 1, 2], [0, 2, 3]]), Trajectory.static(0, 0, 0, 0))
    scan = simulate_scan(sensor, [wall, ground], np.eye(4), T0, Realism.ideal())
    sweep = Sweep(scan.xyz, np.zeros(len(scan), np.float32), scan.time_offset_ns)
    frames = [FrameInfo(k, T0 + (k - 1) * 100_000_000, np.eye(4), Path(f"{k}.npz")) for k in range(3)]
    seq = Sequence("walls", Path("walls"), "memory", frames, lambda k: sweep, annotations=[[], [], []])
    return seq, sensor


def _parked(x: float) -> tuple[InsertedVehicle, dict]:
    mesh = make_vehicle("sedan", 4.5, 1.8, 1.45)
    times = T0 + np.arange(-5, 6, dtype=np.int64) * 100_000_000
    states = np.tile([x, 0.0, GROUND_Z + 1.45 / 2, np.pi / 2], (len(times), 1))
    vehicle = InsertedVehicle("car", "sedan", "Car", mesh.size, MotionSpec("constant_speed", 0.0), times, states)
    return vehicle, {"sedan": (mesh.vertices, np.asarray(mesh.faces))}


def test_inserted_vehicle_behind_a_real_wall_gets_no_points():
    seq, sensor = _wall_background(wall_x=10.0)
    vehicle, meshes = _parked(20.0)
    frame = simulate_frame(seq, 1, sensor, [vehicle], meshes, Realism(seed=0))
    assert (frame.instance == 0).sum() == 0
    assert frame.removed_inserted > 0  # it was simulated, then hidden
    assert frame.removed_real == 0     # and it hides nothing of the wall


def test_real_points_behind_an_inserted_vehicle_are_removed():
    seq, sensor = _wall_background(wall_x=20.0)
    vehicle, meshes = _parked(10.0)
    frame = simulate_frame(seq, 1, sensor, [vehicle], meshes, Realism(seed=0))
    ours = frame.instance == 0
    assert ours.sum() > 300 and frame.removed_real > 300
    real = frame.xyz[~ours].astype(np.float64)
    # no real return left whose ray from the sensor passes through the (parked) vehicle's mesh before it
    box = frame.boxes[0]
    vertices, faces = meshes["sedan"]
    c, s_ = np.cos(box.heading), np.sin(box.heading)
    scene = RaycastScene()
    scene.add_mesh(vertices @ np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1]]).T + box.center, faces)
    distance = np.linalg.norm(real, axis=1)
    hits = scene.cast(np.zeros(3), real / distance[:, None])
    assert not (hits.hit & (hits.distance < distance - 0.05)).any()
    # and every simulated return is inside the ground-truth box
    assert points_in_box(frame.xyz[ours].astype(np.float64), box).mean() >= 0.95
