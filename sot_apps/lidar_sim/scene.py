"""Scenes for ``simulate-lidar``: bank vehicles placed around a sensor, optionally inside a real sweep.

Everything is in the SENSOR frame (x forward, y left, z up). Without a background the sensor sees the
vehicles and, when ``ground_z`` is a number, a flat ground plane at that height.

With a background sweep (a real scan, e.g. PandaSet) the vehicles are inserted with correct occlusion
both ways:

- a background return is removed when the ray from the sensor to it hits an inserted vehicle first
  (Embree is asked along exactly that ray: the removed set is exactly the occluded set);
- a simulated vehicle return is removed when a background return within the sensor's angular resolution
  (half the azimuth step, at least 0.1 deg) of its direction is nearer by more than 0.3 m (a real object,
  e.g. a pole or another car, stands in front of the inserted vehicle).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tracker import Box

from ..errors import InputError
from ..objects.bank import Bank
from ..raycast import RaycastScene
from ..schemas import validate
from ..sensor.model import Sensor, load_sensor
from ..sensor.noise import Realism
from ..sensor.occlusion import OCCLUDER_MARGIN_M, angular_tolerance, blocked_by_real
from ..sensor.scan import Scan, SimObject, Trajectory, simulate_scan
from .visibility import Visibility, placed_vertices, vehicle_visibility

__all__ = ["SceneObject", "SceneSpec", "SimResult", "load_scene", "overlapping_objects", "random_scene", "simulate_scene",
           "insert_into_background", "OCCLUDER_MARGIN_M"]


@dataclass
class SceneObject:
    bank_id: str
    x: float
    y: float
    z: float | None
    heading: float
    label: str | None = None
    reflectivity: float = 0.5
    roll: float = 0.0
    pitch: float = 0.0


@dataclass
class SceneSpec:
    sensor: Sensor
    ground_z: float | None
    objects: list[SceneObject]
    realism: Realism = field(default_factory=lambda: Realism(motion_distortion=False))

    def to_json(self) -> dict:
        return {"version": 1, "sensor": self.sensor.name, "ground_z": self.ground_z,
                "objects": [{"bank_id": o.bank_id, "x": o.x, "y": o.y, "z": o.z, "heading": o.heading,
                             **({"roll": o.roll, "pitch": o.pitch} if o.roll or o.pitch else {})}
                            for o in self.objects]}


@dataclass
class SimResult:
    scan: Scan
    boxes: list[Box]                 # sensor frame, one per scene object
    objects: list[SceneObject]
    labels: list[str]
    removed_background: int = 0
    removed_vehicle: int = 0
    visibility: list[Visibility] = field(default_factory=list)   # per object: what the sensor saw of it


def load_scene(path: str | Path) -> SceneSpec:
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "scene file is missing")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(path, f"not valid JSON ({exc})") from exc
    validate("scene", doc, path)
    sensor_spec = doc["sensor"]
    candidate = path.parent / sensor_spec
    sensor = load_sensor(str(candidate) if candidate.is_file() else sensor_spec)
    realism_doc = doc.get("realism", {})
    realism = Realism(motion_distortion=False, **realism_doc)
    objects = [SceneObject(o["bank_id"], float(o["x"]), float(o["y"]), None if o.get("z") is None else float(o["z"]),
                           float(o["heading"]), o.get("label"), float(o.get("reflectivity", 0.5)),
                           float(o.get("roll", 0.0)), float(o.get("pitch", 0.0)))
               for o in doc["objects"]]
    from ..io.bounds import check_coordinates

    check_coordinates([[o.x, o.y, 0.0 if o.z is None else o.z, o.heading, o.roll, o.pitch] for o in objects], path,
                      "object")
    if doc.get("ground_z") is not None:
        check_coordinates([doc["ground_z"]], path, "ground_z")
    return SceneSpec(sensor, doc.get("ground_z"), objects, realism)


def overlapping_objects(spec: SceneSpec, bank: Bank) -> list[tuple[int, int]]:
    """Index pairs of scene objects whose bird's-eye-view footprints (bank box size, placed) intersect."""
    from tracker import iou_3d_batch

    n = len(spec.objects)
    if n < 2:
        return []
    # footprints as boxes of one common height: their 3D IoU is positive exactly when the footprints intersect
    boxes = np.array([[o.x, o.y, 0.0, o.heading, *bank.get(o.bank_id).box_size()[:2], 1.0] for o in spec.objects])
    i, j = np.triu_indices(n, k=1)
    hit = iou_3d_batch(boxes[i], boxes[j]) > 0
    return [(int(a), int(b)) for a, b in zip(i[hit], j[hit], strict=True)]


def _free_spot(background_xyz: np.ndarray, x: float, y: float, heading: float, size: tuple[float, float, float]) -> bool:
    """True when the background has ground near (x, y) and nothing standing inside the (enlarged) footprint."""
    d = background_xyz[:, :2] - [x, y]
    near = np.hypot(d[:, 0], d[:, 1]) < max(size[0], size[1]) / 2 + 1.5
    if near.sum() < 5:
        return False
    ground = float(np.percentile(background_xyz[near, 2], 5))
    c, s = math.cos(heading), math.sin(heading)
    lx, ly = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    inside = (np.abs(lx) < size[0] / 2 + 0.5) & (np.abs(ly) < size[1] / 2 + 0.5)
    standing = inside & (background_xyz[:, 2] > ground + 0.3) & (background_xyz[:, 2] < ground + size[2] + 1.0)
    return not standing.any()


def random_scene(bank: Bank, count: int, seed: int, sensor: Sensor, ground_z: float | None = -1.8,
                 min_range: float = 6.0, max_range: float = 45.0, background_xyz: np.ndarray | None = None) -> SceneSpec:
    """``count`` bank vehicles at random non-overlapping places and headings around the sensor.

    With ``background_xyz`` (a real sweep, sensor frame) places are only accepted on visible free ground:
    ground returns nearby and no return standing inside the footprint enlarged by 0.5 m.
    """
    if not bank.entries:
        raise InputError(bank.root / "index.json", "the bank has no entries")
    rng = np.random.default_rng(seed)
    placed: list[tuple[float, float, float]] = []
    objects = []
    for _ in range(count):
        entry = bank.entries[int(rng.integers(len(bank.entries)))]
        radius = math.hypot(entry.box_size()[0], entry.box_size()[1]) / 2
        for _attempt in range(500):
            r = rng.uniform(min_range, max_range)
            az = rng.uniform(-math.pi, math.pi)
            heading = round(float(rng.uniform(-math.pi, math.pi)), 4)
            x, y = r * math.cos(az), r * math.sin(az)
            if all(math.hypot(x - px, y - py) > radius + pr + 0.5 for px, py, pr in placed) and (
                    background_xyz is None or _free_spot(background_xyz, x, y, heading, entry.box_size())):
                break
        else:
            raise InputError(bank.root, f"could not find a free place for vehicle {len(objects) + 1} of {count}")
        placed.append((x, y, radius))
        objects.append(SceneObject(entry.id, round(x, 3), round(y, 3), None, heading))
    return SceneSpec(sensor, ground_z, objects, Realism(motion_distortion=False, seed=seed))


def _local_ground(background_xyz: np.ndarray | None, x: float, y: float, radius: float, fallback: float | None) -> float:
    if background_xyz is not None and len(background_xyz):
        near = np.hypot(background_xyz[:, 0] - x, background_xyz[:, 1] - y) < radius
        if near.sum() >= 5:
            return float(np.percentile(background_xyz[near, 2], 5))
    if fallback is None:
        raise InputError(None, "an object has no z and the scene has no ground_z (and no background ground near it)")
    return float(fallback)


def _placed_objects(spec: SceneSpec, bank: Bank, background_xyz: np.ndarray | None
                    ) -> tuple[list[SimObject], list[Box], list[str]]:
    sims, boxes, labels = [], [], []
    for i, o in enumerate(spec.objects):
        entry = bank.get(o.bank_id)
        vertices, faces = bank.mesh(o.bank_id)
        length, width, height = entry.box_size()
        z = o.z
        if z is None:
            z = _local_ground(background_xyz, o.x, o.y, max(length, width) / 2 + 1.5, spec.ground_z) + height / 2
        sims.append(SimObject(vertices, faces, Trajectory.static(o.x, o.y, z, o.heading, o.roll, o.pitch), instance=i,
                              reflectivity=o.reflectivity, name=o.bank_id))
        boxes.append(Box(o.x, o.y, z, o.heading, length, width, height, o.roll, o.pitch))
        labels.append(o.label or entry.label or "Car")
    return sims, boxes, labels


def _ground(z: float) -> SimObject:
    v = np.array([[-400, -400, z], [400, -400, z], [400, 400, z], [-400, 400, z]], dtype=float)
    return SimObject(v, np.array([[0, 1, 2], [0, 2, 3]]), Trajectory.static(0, 0, 0, 0), -1, 0.2, "ground")


def simulate_scene(spec: SceneSpec, bank: Bank) -> SimResult:
    """Simulate the scene alone (vehicles + optional ground plane)."""
    vehicles, boxes, labels = _placed_objects(spec, bank, None)
    objects = vehicles + ([_ground(float(spec.ground_z))] if spec.ground_z is not None else [])
    scan = simulate_scan(spec.sensor, objects, np.eye(4), realism=spec.realism)
    return SimResult(scan, boxes, spec.objects, labels,
                     visibility=vehicle_visibility(spec.sensor, vehicles, boxes, scan.instance))


def insert_into_background(spec: SceneSpec, bank: Bank, background_xyz: np.ndarray,
                           background_intensity: np.ndarray | None = None,
                           background_time_ns: np.ndarray | None = None) -> SimResult:
    """Insert the scene's vehicles into a real sweep (points in the sensor frame) with occlusion both ways."""
    bg = np.asarray(background_xyz, dtype=np.float64)
    vehicles, boxes, labels = _placed_objects(spec, bank, bg)
    scene = RaycastScene()
    for v in vehicles:
        scene.add_mesh(placed_vertices(v), v.faces)
    rng_bg = np.linalg.norm(bg, axis=1)
    valid = rng_bg > 1e-6
    dirs = np.zeros_like(bg)
    dirs[valid] = bg[valid] / rng_bg[valid, None]
    hits = scene.cast(np.zeros(3), dirs)
    occluded = valid & hits.hit & (hits.distance < rng_bg)
    keep_bg = ~occluded

    sim = simulate_scan(spec.sensor, vehicles, np.eye(4), realism=spec.realism)
    removed_vehicle = 0
    if len(sim) and keep_bg.any():
        kept = bg[keep_bg & valid]
        kept_r = np.linalg.norm(kept, axis=1)
        sim_r = np.linalg.norm(sim.xyz.astype(np.float64), axis=1)
        blocked = blocked_by_real(kept / kept_r[:, None], kept_r, sim.xyz / sim_r[:, None], sim_r,
                                  angular_tolerance(spec.sensor))
        removed_vehicle = int(blocked.sum())
        sim = _subset(sim, ~blocked)

    n_bg = int(keep_bg.sum())
    intensity_bg = np.zeros(n_bg, np.float32) if background_intensity is None else \
        np.asarray(background_intensity, dtype=np.float32)[keep_bg]
    if background_intensity is not None and intensity_bg.size and intensity_bg.max() > 1.0:
        intensity_bg = intensity_bg / 255.0
    time_bg = np.zeros(n_bg, np.int64) if background_time_ns is None else np.asarray(background_time_ns, np.int64)[keep_bg]
    scan = Scan(xyz=np.vstack([bg[keep_bg].astype(np.float32), sim.xyz]),
                instance=np.concatenate([np.full(n_bg, -1, np.int32), sim.instance]),
                intensity=np.concatenate([intensity_bg, sim.intensity]).astype(np.float32),
                time_offset_ns=np.concatenate([time_bg, sim.time_offset_ns]),
                beam=np.concatenate([np.full(n_bg, -1, np.int32), sim.beam]),
                column=np.concatenate([np.full(n_bg, -1, np.int32), sim.column]),
                distance=np.concatenate([rng_bg[keep_bg].astype(np.float32), sim.distance]),
                object_index=np.concatenate([np.full(n_bg, -1, np.int32), sim.object_index]),
                num_beams=spec.sensor.beams, num_columns=spec.sensor.columns,
                extra={"background_kept": keep_bg})
    return SimResult(scan, boxes, spec.objects, labels, removed_background=int(occluded.sum()),
                     removed_vehicle=removed_vehicle,
                     visibility=vehicle_visibility(spec.sensor, vehicles, boxes, scan.instance))


def _subset(scan: Scan, mask: np.ndarray) -> Scan:
    return Scan(scan.xyz[mask], scan.instance[mask], scan.intensity[mask], scan.time_offset_ns[mask], scan.beam[mask],
                scan.column[mask], scan.distance[mask], scan.object_index[mask], scan.num_beams, scan.num_columns)
