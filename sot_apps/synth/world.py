"""A small synthetic driving world with exact ground truth, written as a canonical sequence.

The world (everything in metres, world frame z up, ground plane z = 0):

- a straight road along +x; walls (with gaps) at |y| ~ 14 m, poles at |y| ~ 12 m, parked cars at |y| ~ 10 m
  (``open_road``: no walls and no poles, open ground all round);
- ``vehicles`` procedural vehicles (sedan/SUV/van/truck, varied size) in lanes y = 3.5, -3.5, 7 (oncoming),
  0 (ego lane, ahead or behind); each follows a random piecewise profile of cruising, turning, abrupt
  stops (-6..-9 m/s^2) and abrupt accelerations (+3..+5 m/s^2), integrated at 1 ms; or, with
  ``profiles``, the benchmark's motion profiles (:mod:`sot_apps.objects.motion_profiles`);
- the ego (= the LiDAR, 1.8 m above the ground; ``ego_from_lidar`` is the identity) drives along the
  road with gentle speed and heading changes.

Frame ``k``'s timestamp marks the end of its sweep. Points are simulated with a rolling scan (see
:mod:`sot_apps.sensor.scan`): the ego and every vehicle are at their exact pose at each column's time.
Ground-truth boxes in ``sequence.json`` describe each object when the LiDAR saw it (the median capture
time of its returns; see :func:`observation_times_ns`), as PandaSet's annotations do; ``gt/objects.json``
has the states at the frame timestamps and ``gt/trajectories.npz`` every millisecond.

Ground truth beyond the sequence (``DIR/gt/``, see docs/synth.md):

- ``gt/objects.json``: every annotated object (moving vehicles ``veh_NNN`` and parked cars
  ``parked_NNN``): kind, label, size, mesh path, and its state at every frame timestamp (and camera
  timestamp when cameras are on);
- ``gt/meshes/<id>.ply``: the object's mesh in its object frame (box centre origin, x forward);
- ``gt/trajectories.npz``: ``times_ns`` (T,) and per object ``<id>`` (T, 4) x, y, z, heading sampled every
  1 ms (linear interpolation between samples is exact to the simulation), plus ``ego`` (the sensor);
- ``gt/labels/NNNNNN.npz``: ``instance`` (N,) int32 per point of frame k: index into ``objects`` (-1 =
  background: ground, walls, poles).

``DIR/preview.png`` is a bird's-eye view of the last frame (ego frame) with the ground-truth boxes.

Same arguments, same bytes: every random draw comes from ``numpy.random.default_rng(seed)``. The one
exception is camera PNGs (Mesa software OpenGL resolves some depth ties at triangle edges differently run to
run: a few single edge pixels may differ; see ``sot-apps synth --help``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from tracker import Box, invert_transform, transform_points

from ..interrupts import import_trimesh
from ..io.atomic import write_json, write_npz
from ..io.canonical import write_sequence
from ..io.ply import write_ply_mesh
from ..io.sequence import BoxAnnotation, Camera, CameraFrame, FrameInfo, Sequence, Sweep
from ..objects.meshes import box_mesh
from ..objects.motion_profiles import PROFILES, integrate_motion, place_path, sample_motion
from ..objects.trajectory import Trajectory, world_from_object, wrap_heading
from ..raycast import RaycastScene
from ..sensor.model import Sensor, load_sensor
from ..sensor.noise import Realism
from ..sensor.scan import Scan, SimObject, simulate_scan
from .clutter import clutter_objects
from .vehicles import random_vehicle

__all__ = ["WorldObject", "World", "SynthCamera", "make_world", "write_world", "SENSOR_HEIGHT", "BASE_TIME_NS"]

SENSOR_HEIGHT = 1.8
BASE_TIME_NS = 1_600_000_000_000_000_000
STEP_NS = 1_000_000  # trajectory sampling: 1 ms


@dataclass
class WorldObject:
    """An annotated object: a vehicle mesh (object frame) and its trajectory (box centre, heading)."""

    id: str
    label: str
    kind: str
    size: tuple[float, float, float]
    vertices: np.ndarray
    faces: np.ndarray
    trajectory: Trajectory
    moving: bool
    color: tuple[float, float, float] = (0.6, 0.6, 0.6)
    reflectivity: float = 0.5

    def box_at(self, t_ns: int) -> Box:
        x, y, z, h = _wrapped(self.trajectory, t_ns)
        return Box(float(x), float(y), float(z), float(h), *self.size)


@dataclass(frozen=True)
class SynthCamera:
    """A pinhole camera rigidly mounted on the ego (OpenCV axes: x right, y down, z forward)."""

    name: str
    K: np.ndarray
    width: int
    height: int
    ego_from_camera: np.ndarray
    time_offset_ns: int  # image time relative to the lidar frame timestamp


@dataclass
class World:
    sensor: Sensor
    seed: int
    frame_times_ns: np.ndarray
    ego: Trajectory                      # the sensor (= ego) pose over time
    objects: list[WorldObject]           # annotated vehicles (moving and parked)
    background: list[SimObject]          # ground, walls, poles
    cameras: list[SynthCamera] = field(default_factory=list)
    realism: Realism = field(default_factory=Realism)

    @property
    def num_frames(self) -> int:
        return len(self.frame_times_ns)

    def world_from_ego(self, t_ns: int) -> np.ndarray:
        return world_from_object(self.ego.states_at(t_ns))

    def boxes_at(self, t_ns: int) -> list[Box]:
        return [o.box_at(t_ns) for o in self.objects]

    def sim_objects(self) -> list[SimObject]:
        out = list(self.background)
        for i, o in enumerate(self.objects):
            traj = o.trajectory if o.moving else Trajectory(np.zeros(1, np.int64), o.trajectory.states[:1])
            out.append(SimObject(o.vertices, o.faces, traj, instance=i, reflectivity=o.reflectivity, name=o.id))
        return out

    def scan(self, k: int, static_scene: RaycastScene | None = None) -> Scan:
        """Simulate frame ``k`` (points in the ego frame at the frame time)."""
        realism = Realism(**{**self.realism.__dict__, "seed": self.seed * 100_003 + k})
        return simulate_scan(self.sensor, self.sim_objects(), self.ego, int(self.frame_times_ns[k]), realism,
                             static_scene=static_scene)

    def static_scene(self) -> RaycastScene:
        from ..sensor.scan import build_static_scene

        return build_static_scene(self.sim_objects())


def observation_times_ns(world: World, scan: Scan, frame_time_ns: int) -> np.ndarray:
    """(len(world.objects),) absolute time at which the LiDAR saw each object in this sweep.

    The median capture time of the object's returns; for an object without returns, the firing time of
    the column that points at its box centre. Annotations are boxes at these times, as PandaSet's are:
    an annotator draws the box around the points, which a rolling scan records at its own times.
    """
    num = len(world.objects)
    out = np.full(num, frame_time_ns, dtype=np.int64)
    inst = scan.instance
    order = np.argsort(inst, kind="stable")
    starts = np.searchsorted(inst[order], np.arange(num))
    ends = np.searchsorted(inst[order], np.arange(num), side="right")
    ego_from_world = invert_transform(world.world_from_ego(frame_time_ns))
    col_t = world.sensor.column_time_offsets_ns()
    col_az = np.asarray(world.sensor.column_azimuths(), dtype=np.float64)
    for i, o in enumerate(world.objects):
        if ends[i] > starts[i]:
            out[i] = frame_time_ns + int(np.median(scan.time_offset_ns[order[starts[i]:ends[i]]]))
            continue
        centre = transform_points(ego_from_world, o.box_at(frame_time_ns).center[None])[0]
        azimuth = math.atan2(centre[1], centre[0])
        diff = np.abs((col_az - azimuth + math.pi) % (2.0 * math.pi) - math.pi)
        out[i] = frame_time_ns + int(col_t[int(np.argmin(diff))])
    return out


# ------------------------------------------------------------------------------------------ motion

def _integrate(rng: np.random.Generator, t0_ns: int, t1_ns: int, start: tuple[float, float, float, float],
               speed: float, gentle: bool) -> Trajectory:
    """Integrate a random piecewise (acceleration, yaw rate) profile of a unicycle at 1 ms."""
    n = int((t1_ns - t0_ns) // STEP_NS) + 1
    dt = STEP_NS * 1e-9
    accel = np.zeros(n)
    yaw_rate = np.zeros(n)
    i = 0
    while i < n:
        length = int(rng.uniform(0.3, 0.9) / dt)
        mode = rng.choice(4, p=[0.4, 0.3, 0.15, 0.15] if gentle else [0.3, 0.25, 0.25, 0.2])
        seg = slice(i, min(n, i + length))
        if mode == 1:  # turn: an S-curve (lane change) or a persistent turn
            w = rng.uniform(0.05, 0.12) if gentle else rng.uniform(0.2, 0.45)
            w *= rng.choice([-1.0, 1.0])
            if rng.random() < 0.5:
                half = max(1, (seg.stop - seg.start) // 2)
                yaw_rate[seg.start:seg.start + half] = w
                yaw_rate[seg.start + half:seg.stop] = -w
            else:
                yaw_rate[seg] = w
        elif mode == 2:  # stop / brake abruptly
            accel[seg] = -rng.uniform(2.0, 3.0) if gentle else -rng.uniform(6.0, 9.0)
        elif mode == 3:  # accelerate abruptly
            accel[seg] = rng.uniform(1.5, 2.5) if gentle else rng.uniform(3.0, 5.0)
        i += length
    states = np.zeros((n, 4))
    x, y, z, h = start
    v = speed
    vmax = 12.0 if gentle else 16.0
    for j in range(n):  # 1 ms steps over a few seconds: a few thousand iterations per object
        states[j] = (x, y, z, h)
        v = min(max(v + accel[j] * dt, 0.0), vmax)
        h += yaw_rate[j] * dt * min(1.0, v / 2.0)
        x += v * math.cos(h) * dt
        y += v * math.sin(h) * dt
    states[:, 3] = (states[:, 3] + np.pi) % (2 * np.pi) - np.pi
    times = t0_ns + np.arange(n, dtype=np.int64) * STEP_NS
    return Trajectory(times, states)


def _profile_trajectory(rng: np.random.Generator, t0_ns: int, t1_ns: int, start: tuple[float, float, float, float],
                        profile: str) -> Trajectory:
    """A drawn motion profile (shared with the benchmark) integrated at 1 ms from ``start``."""
    duration = (t1_ns - t0_ns) * 1e-9
    path = integrate_motion(sample_motion(profile, rng, duration), duration, dt=STEP_NS * 1e-9)
    xyh = place_path(path, start[0], start[1], start[3])
    times = t0_ns + np.arange(len(xyh), dtype=np.int64) * STEP_NS
    return Trajectory(times, np.column_stack([xyh[:, :2], np.full(len(xyh), start[2]), xyh[:, 2]]))


# ------------------------------------------------------------------------------------------ scene

def _box_mesh(extents, centre) -> tuple[np.ndarray, np.ndarray]:
    mesh = box_mesh(*(float(v) for v in extents))
    return mesh.vertices + np.asarray(centre, dtype=np.float64), mesh.faces


def _cylinder_mesh(radius: float, height: float, centre) -> tuple[np.ndarray, np.ndarray]:
    trimesh = import_trimesh()

    m = trimesh.creation.cylinder(radius=radius, height=height, sections=12)
    return np.asarray(m.vertices) + np.asarray(centre), np.asarray(m.faces)


def _background(rng: np.random.Generator, x_min: float, x_max: float, open_road: bool = False) -> list[SimObject]:
    out: list[SimObject] = []
    ground_v = np.array([[x_min - 300, -300, 0], [x_max + 300, -300, 0], [x_max + 300, 300, 0], [x_min - 300, 300, 0]], float)
    out.append(SimObject(ground_v, np.array([[0, 1, 2], [0, 2, 3]]), Trajectory.static(0, 0, 0, 0), -1, 0.2, "ground"))
    if open_road:  # open ground all round: no walls, no poles
        return out
    for side in (1.0, -1.0):
        x = x_min
        while x < x_max:  # walls with gaps
            length = rng.uniform(10, 30)
            height = rng.uniform(2.0, 4.0)
            y = side * rng.uniform(13.5, 15.0)
            v, f = _box_mesh([length, 0.3, height], [x + length / 2, y, height / 2])
            out.append(SimObject(v, f, Trajectory.static(0, 0, 0, 0), -1, 0.35, "wall"))
            x += length + rng.uniform(3, 10)
        x = x_min + rng.uniform(0, 10)
        while x < x_max:  # poles
            v, f = _cylinder_mesh(0.15, 5.0, [x, side * rng.uniform(11.5, 12.5), 2.5])
            out.append(SimObject(v, f, Trajectory.static(0, 0, 0, 0), -1, 0.6, "pole"))
            x += rng.uniform(12, 20)
    return out


def _color(rng: np.random.Generator) -> tuple[float, float, float]:
    return tuple(round(float(c), 3) for c in rng.uniform(0.15, 0.95, size=3))  # type: ignore[return-value]


def default_front_camera(width: int = 640, height: int = 360, period_ns: int = 100_000_000) -> SynthCamera:
    f = 0.5 * width / math.tan(math.radians(40.0))  # 80 deg horizontal field of view
    K = np.array([[f, 0.0, width / 2.0], [0.0, f, height / 2.0], [0.0, 0.0, 1.0]])
    ego_from_camera = np.eye(4)
    # OpenCV axes: camera x -> ego -y, camera y -> ego -z, camera z -> ego +x.
    ego_from_camera[:3, :3] = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    ego_from_camera[:3, 3] = [1.2, 0.0, -0.3]
    return SynthCamera("front_camera", K, width, height, ego_from_camera, -period_ns // 2)


def make_world(frames: int = 20, vehicles: int = 3, sensor: str | Sensor = "pandar64", seed: int = 0,
               cameras: bool = False, camera_size: tuple[int, int] = (640, 360), parked: int | None = None,
               realism: Realism | None = None, profiles: bool = False, open_road: bool = False,
               clutter: bool = False) -> World:
    """Build (but do not simulate) a synthetic world; cheap (well under a second).

    ``profiles``: moving vehicle i follows motion profile ``PROFILES[i % 7]`` of
    :mod:`sot_apps.objects.motion_profiles` (the benchmark's: kinematic bicycle, bounded acceleration and
    jerk; ``occluded`` is left out) instead of the random piecewise profile. ``open_road``: no walls and no
    poles, open ground all round (the generated benchmark's hard profiles need room off the road). ``clutter``:
    unannotated roadside bushes, hedges, trees, building corners, kiosks and pedestrians
    (:mod:`.clutter`), drawn from their own generator (``[seed, 1]``) so the rest of the world is the same."""
    if frames < 1 or vehicles < 0:
        raise ValueError("frames must be >= 1 and vehicles >= 0")
    sensor = load_sensor(sensor)
    rng = np.random.default_rng(seed)
    period_ns = int(round(sensor.period_s * 1e9))
    frame_times = BASE_TIME_NS + period_ns * np.arange(1, frames + 1, dtype=np.int64)
    t0 = int(frame_times[0] - 2 * period_ns)
    t1 = int(frame_times[-1] + period_ns)

    ego = _integrate(rng, t0, t1, (0.0, 0.0, SENSOR_HEIGHT, 0.0), float(rng.uniform(5.0, 9.0)), gentle=True)
    x_end = float(ego.states[:, 0].max())
    x_min, x_max = -70.0, x_end + 90.0

    objects: list[WorldObject] = []
    lanes = [(3.5, 0.0), (-3.5, 0.0), (7.0, math.pi), (0.0, 0.0)]
    used: dict[int, list[float]] = {}
    for i in range(vehicles):
        lane = i % len(lanes)
        y, heading = lanes[lane]
        for _ in range(100):
            x = float(rng.uniform(-25.0, 40.0))
            if lane == 3 and abs(x) < 12.0:
                continue
            if all(abs(x - other) > 20.0 for other in used.get(lane, [])):
                break
        used.setdefault(lane, []).append(x)
        mesh = random_vehicle(rng)
        speed = float(rng.uniform(4.0, 12.0))
        start = (x, y + float(rng.uniform(-0.3, 0.3)), mesh.size[2] / 2.0, heading)
        traj = (_profile_trajectory(rng, t0, t1, start, PROFILES[i % (len(PROFILES) - 1)]) if profiles else
                _integrate(rng, t0, t1, start, speed, gentle=False))
        objects.append(WorldObject(f"veh_{i:03d}", mesh.label, mesh.kind, mesh.size, mesh.vertices, mesh.faces, traj,
                                   moving=True, color=_color(rng), reflectivity=float(rng.uniform(0.3, 0.8))))
    n_parked = int(rng.integers(4, 9)) if parked is None else parked
    spots: list[tuple[float, float]] = []
    for j in range(n_parked):
        side = 1.0 if j % 2 == 0 else -1.0
        for _ in range(100):
            x = float(rng.uniform(x_min + 20.0, x_max - 20.0))
            if all(abs(x - sx) > 7.0 or sy != side for sx, sy in spots):
                break
        spots.append((x, side))
        mesh = random_vehicle(rng, weights=(0.5, 0.35, 0.15, 0.0))
        heading = float(rng.choice([0.0, math.pi]) + rng.uniform(-0.05, 0.05))
        traj = Trajectory.static(x, side * float(rng.uniform(9.5, 10.5)), mesh.size[2] / 2.0, heading)
        objects.append(WorldObject(f"parked_{j:03d}", mesh.label, mesh.kind, mesh.size, mesh.vertices, mesh.faces,
                                   traj, moving=False, color=_color(rng), reflectivity=float(rng.uniform(0.3, 0.8))))
    background = _background(rng, x_min, x_max, open_road)
    if clutter:
        background += clutter_objects(np.random.default_rng([seed, 1]), x_min, x_max)
    cams = [default_front_camera(*camera_size, period_ns=period_ns)] if cameras else []
    return World(sensor, seed, frame_times, ego, objects, background, cams, realism or Realism())


# ------------------------------------------------------------------------------------------ writing

def _wrapped(trajectory: Trajectory, times_ns) -> np.ndarray:
    """States at ``times_ns`` with the heading wrapped to [-pi, pi) (the ground truth files' convention)."""
    states = trajectory.states_at(times_ns)
    states[..., 3] = wrap_heading(states[..., 3])
    return states


def _gt_document(world: World, camera_times: list[np.ndarray]) -> dict:
    objects = []
    for o in world.objects:
        states = []
        for k, t in enumerate(world.frame_times_ns):
            x, y, z, h = (float(v) for v in _wrapped(o.trajectory, int(t)))
            states.append({"frame": k, "timestamp_ns": int(t), "x": x, "y": y, "z": z, "heading": h})
        entry = {"id": o.id, "label": o.label, "kind": o.kind, "moving": o.moving,
                 "size": {"length": o.size[0], "width": o.size[1], "height": o.size[2]},
                 "mesh": f"gt/meshes/{o.id}.ply", "color": list(o.color), "reflectivity": o.reflectivity,
                 "states": states}
        if camera_times:
            entry["camera_states"] = {
                cam.name: [dict(zip(("x", "y", "z", "heading"), (float(v) for v in _wrapped(o.trajectory, int(t))),
                                    strict=True),
                                timestamp_ns=int(t)) for t in times]
                for cam, times in zip(world.cameras, camera_times, strict=True)}
        objects.append(entry)
    return {"version": 1, "generator": "sot_apps.synth", "seed": world.seed,
            "sensor": world.sensor.to_dict(), "sensor_height": SENSOR_HEIGHT, "ground_z": 0.0,
            "frame_timestamps_ns": [int(t) for t in world.frame_times_ns],
            "trajectories": "gt/trajectories.npz", "labels": "gt/labels/{frame:06d}.npz",
            "objects": objects}


def write_world(out: str | Path, frames: int = 20, vehicles: int = 3, sensor: str | Sensor = "pandar64",
                seed: int = 0, cameras: bool = False, camera_size: tuple[int, int] = (640, 360),
                world: World | None = None, progress: bool = False, profiles: bool = False,
                open_road: bool = False, clutter: bool = False, parked: int | None = None) -> Path:
    """Synthesise a world and write it as a canonical sequence with ground truth; returns ``out``.

    Pass ``world`` (from :func:`make_world`) to write a world you built or modified yourself.
    """
    out = Path(out)
    if world is None:
        world = make_world(frames, vehicles, sensor, seed, cameras, camera_size, profiles=profiles, open_road=open_road,
                           clutter=clutter, parked=parked)
    out.mkdir(parents=True, exist_ok=True)
    static = world.static_scene()
    sweeps: list[Sweep] = []
    infos: list[FrameInfo] = []
    annotations: list[list[BoxAnnotation]] = []
    for k in tqdm(range(world.num_frames), desc="simulating", unit="frame", disable=not progress, leave=False):
        t = int(world.frame_times_ns[k])
        scan = world.scan(k, static)
        sweeps.append(Sweep(scan.xyz, scan.intensity, scan.time_offset_ns))
        write_npz(out / "gt" / "labels" / f"{k:06d}.npz", instance=scan.instance.astype(np.int32),
                  beam=scan.beam.astype(np.int16), column=scan.column.astype(np.int16))
        infos.append(FrameInfo(k, t, world.world_from_ego(t), Path(f"points/{k:06d}.npz")))
        seen_ns = observation_times_ns(world, scan, t)
        annotations.append([BoxAnnotation(o.id, o.label, o.box_at(int(ts)), stationary=not o.moving)
                            for o, ts in zip(world.objects, seen_ns, strict=True)])

    camera_models: dict[str, Camera] = {}
    camera_times: list[np.ndarray] = []
    if world.cameras:
        from .render import render_camera_images

        for cam in world.cameras:
            times = world.frame_times_ns + cam.time_offset_ns
            camera_times.append(times)
            paths = render_camera_images(world, cam, times, out / "cameras" / cam.name)
            cam_frames = [CameraFrame(int(t), p, world.world_from_ego(int(t)) @ cam.ego_from_camera)
                          for t, p in zip(times, paths, strict=True)]
            camera_models[cam.name] = Camera(cam.name, cam.K, np.zeros(5), cam.width, cam.height, cam_frames,
                                             ego_from_camera=cam.ego_from_camera)

    seq = Sequence(id=f"synth_s{world.seed}", root=Path("synthetic"), format="synth", frames=infos,
                   load_sweep=lambda k: sweeps[k], ego_from_lidar=np.eye(4), cameras=camera_models,
                   annotations=annotations, cache_size=0)
    for o in world.objects:
        write_ply_mesh(out / "gt" / "meshes" / f"{o.id}.ply", o.vertices, o.faces)
    ids = {o.id: _wrapped(o.trajectory, world.ego.times_ns) for o in world.objects}
    write_npz(out / "gt" / "trajectories.npz", times_ns=world.ego.times_ns, ego=world.ego.states, **ids)
    write_json(out / "gt" / "objects.json", _gt_document(world, camera_times))
    _write_preview(out / "preview.png", world, scan, infos[-1])
    write_sequence(seq, out, progress=progress)
    return out


def _write_preview(path: Path, world: World, scan: Scan, info: FrameInfo) -> None:
    """Bird's-eye view of the last frame (ego frame) with its ground-truth boxes."""
    from tracker import invert_transform

    from ..sensor.preview import write_bev_png

    ego_from_world = invert_transform(info.world_from_ego)
    boxes = [o.box_at(info.timestamp_ns).transformed(ego_from_world) for o in world.objects]
    write_bev_png(path, scan.xyz, scan.instance, boxes, extent=40.0)
