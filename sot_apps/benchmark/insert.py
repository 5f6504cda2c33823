"""Moving vehicles simulated into one real sweep, with the real sensor's timing and occlusion both ways.

Everything happens in the SENSOR frame at the frame time (``world_from_sensor`` = the frame's
``world_from_ego @ ego_from_lidar``):

1. every inserted vehicle's world trajectory around the sweep becomes a trajectory in that frame (the
   sensor's small roll/pitch relative to the world is applied to the mesh); the sensor's own motion over
   the sweep comes from the neighbouring frame poses; :func:`simulate_scan` then casts the sensor's beam
   table column by column at each column's firing time (rolling scan) with range noise, grazing drop and
   Lambertian intensity;
2. a real return is removed when its ray (from where the sensor was when it fired, at its own time)
   hits an inserted vehicle, at that vehicle's pose at that time, more than 5 cm before the return;
3. a simulated return is removed when a kept real return within the sensor's angular resolution of its
   direction is nearer by more than 0.3 m (a real object stands in front of it);
4. each vehicle's ground-truth box is its pose when the beams pass its centre (the firing time of the
   column aimed at its centre), as PandaSet annotates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tracker import Box, invert_transform, points_in_box, transform_points

from ..io.sequence import Sequence
from .background import ego_from_sensor, sensor_path, to_states
from .deps import (
    RaycastScene,
    Realism,
    Sensor,
    SimObject,
    Trajectory,
    angular_tolerance,
    blocked_by_real,
    invert_transform_batch,
    simulate_scan,
    world_from_object,
)
from .placement import InsertedVehicle

__all__ = ["InsertedFrame", "simulate_frame", "BACKGROUND_OCCLUSION_MARGIN_M"]

BACKGROUND_OCCLUSION_MARGIN_M = 0.05
_WINDOW_NS = (200_000_000, 60_000_000)  # trajectory samples kept before / after the frame time


@dataclass(frozen=True)
class InsertedFrame:
    """One output sweep (ego frame) and the inserted vehicles' ground truth."""

    xyz: np.ndarray               # (N, 3) float32 ego frame
    intensity: np.ndarray         # (N,) float32
    time_offset_ns: np.ndarray    # (N,) int64
    instance: np.ndarray          # (N,) int32: index into the vehicles, -1 real
    boxes: list[Box]              # world frame, one per vehicle
    box_times_ns: np.ndarray      # (V,) when the beams passed each vehicle's centre
    removed_real: int
    removed_inserted: int


def _rot_z(h: np.ndarray) -> np.ndarray:
    c, s = np.cos(h), np.sin(h)
    out = np.zeros(np.shape(h) + (3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 1, 0], out[..., 1, 1], out[..., 2, 2] = c, -s, s, c, 1.0
    return out


def _in_sensor_frame(vehicle: InsertedVehicle, mesh: tuple[np.ndarray, np.ndarray], sensor_from_world: np.ndarray,
                     t_ns: int, instance: int) -> tuple[SimObject, np.ndarray]:
    """The vehicle as a SimObject of the sensor frame (mesh tilted by the sensor's roll/pitch) and the tilt."""
    lo = max(0, int(np.searchsorted(vehicle.times_ns, t_ns - _WINDOW_NS[0])) - 1)
    hi = int(np.searchsorted(vehicle.times_ns, t_ns + _WINDOW_NS[1], side="right")) + 1
    times, states = vehicle.times_ns[lo:hi], vehicle.states[lo:hi]
    if len(times) < 2:  # one sample (the sweep is beyond the path's ends): still a moving object, held still
        times, states = np.array([times[0], times[0] + 1], dtype=np.int64), np.repeat(states, 2, axis=0)
    world_from_obj = world_from_object(states)
    rel = sensor_from_world @ world_from_obj
    rel_states = to_states(rel)
    rel_states[:, 3] = np.unwrap(rel_states[:, 3])
    mid = len(times) // 2
    tilt = _rot_z(-rel_states[mid, 3]) @ rel[mid, :3, :3]  # the sensor's roll/pitch seen in the object frame
    vertices = mesh[0] @ tilt.T
    return SimObject(vertices, mesh[1], Trajectory(times, rel_states), instance=instance, name=vehicle.id), tilt


def _background_occlusion(objects: list[tuple[SimObject, np.ndarray]], scenes: dict[str, RaycastScene],
                          origins: np.ndarray, xyz: np.ndarray, t_ns: np.ndarray, frame_time_ns: int) -> np.ndarray:
    """Mask of real returns whose ray from ``origins`` hits an inserted vehicle (at its pose then) first.

    ``scenes`` holds each vehicle's untilted mesh (built once per copy): rays are un-tilted instead.
    """
    d = xyz - origins
    dist = np.linalg.norm(d, axis=1)
    dirs = d / np.maximum(dist, 1e-9)[:, None]
    azimuth = np.arctan2(dirs[:, 1], dirs[:, 0])
    occluded = np.zeros(len(xyz), dtype=bool)
    for o, tilt in objects:
        states = o.trajectory.states
        speed = float(np.max(np.hypot(*np.diff(states[:, :2], axis=0).T) /
                             np.maximum(np.diff(o.trajectory.times_ns) * 1e-9, 1e-9))) if len(states) > 1 else 0.0
        radius = o.radius() + speed * 0.12 + 0.2
        centre = o.trajectory.states_at(frame_time_ns)[:3]
        reach = float(np.hypot(centre[0], centre[1]))
        half = math.pi if reach <= radius + 1.0 else math.asin(min(1.0, radius / (reach - 1.0))) + 0.02
        cand = np.flatnonzero(np.abs((azimuth - math.atan2(centre[1], centre[0]) + math.pi) % (2 * math.pi) - math.pi)
                              <= half)
        c = centre - origins[cand]
        t = (c * dirs[cand]).sum(axis=1)
        perp2 = (c * c).sum(axis=1) - t * t
        cand = cand[(perp2 <= radius * radius) & (t >= -radius) & (t <= dist[cand] + radius)]
        if cand.size == 0:
            continue
        object_from_sensor = invert_transform_batch(world_from_object(o.trajectory.states_at(t_ns[cand])))
        to_mesh = tilt.T @ object_from_sensor[:, :3, :3]  # into the untilted mesh frame
        o_obj = np.einsum("nij,nj->ni", to_mesh, origins[cand]) + \
            np.einsum("ij,nj->ni", tilt.T, object_from_sensor[:, :3, 3])
        d_obj = np.einsum("nij,nj->ni", to_mesh, dirs[cand])
        hits = scenes[o.name].cast(o_obj, d_obj)
        occluded[cand[hits.hit & (hits.distance < dist[cand] - BACKGROUND_OCCLUSION_MARGIN_M)]] = True
    return occluded


def _centre_times(vehicles: list[InsertedVehicle], sensor: Sensor, sensor_from_world: np.ndarray,
                  frame_time_ns: int) -> np.ndarray:
    """When the beams pass each vehicle's centre (two fixed-point steps: pose -> azimuth -> column time)."""
    col_az = sensor.column_azimuths()
    col_t = sensor.column_time_offsets_ns()
    times = np.full(len(vehicles), frame_time_ns, dtype=np.int64)
    for _ in range(2):
        centres = np.array([v.states_at(int(t))[:3] for v, t in zip(vehicles, times, strict=True)]).reshape(-1, 3)
        local = transform_points(sensor_from_world, centres)
        az = np.arctan2(local[:, 1], local[:, 0])
        col = np.argmin(np.abs((col_az[None, :] - az[:, None] + np.pi) % (2 * np.pi) - np.pi), axis=1)
        times = frame_time_ns + col_t[col]
    return times


def vehicle_scenes(vehicles: list[InsertedVehicle], meshes: dict[str, tuple[np.ndarray, np.ndarray]]
                   ) -> dict[str, RaycastScene]:
    """One ray-casting scene per vehicle (its mesh in its object frame), to reuse over the frames."""
    scenes = {}
    for v in vehicles:
        scenes[v.id] = RaycastScene()
        scenes[v.id].add_mesh(*meshes[v.bank_id])
    return scenes


def simulate_frame(seq: Sequence, k: int, sensor: Sensor, vehicles: list[InsertedVehicle],
                   meshes: dict[str, tuple[np.ndarray, np.ndarray]], realism: Realism,
                   scenes: dict[str, RaycastScene] | None = None,
                   origin: tuple[float, float, float] = (0.0, 0.0, 0.0), cut: list[Box] = ()) -> InsertedFrame:
    """Insert ``vehicles`` into frame ``k`` of ``seq`` (see the module doc); ``scenes`` from
    :func:`vehicle_scenes` (built here when not given); ``origin``: the simulated optical centre in the LiDAR frame
    (0: the reader's LiDAR frame, which is the optical centre; what-if experiments only); ``cut``: world boxes
    whose real points are removed first (grown 0.75 m at each end for the rolling-scan smear, 0.3 m at the sides)."""
    t_k = int(seq.frames[k].timestamp_ns)
    world_from_sensor, path = sensor_path(seq, k, origin)
    mount = ego_from_sensor(seq, origin)
    sensor_from_world = invert_transform(world_from_sensor)
    scenes = scenes if scenes is not None else vehicle_scenes(vehicles, meshes)
    objects = [_in_sensor_frame(v, meshes[v.bank_id], sensor_from_world, t_k, i) for i, v in enumerate(vehicles)]
    reach = sensor.max_range + 10.0
    objects = [(o, tilt) for o, tilt in objects if np.linalg.norm(o.trajectory.states_at(t_k)[:3]) < reach]
    scan = simulate_scan(sensor, [o for o, _ in objects], path, t_k, realism, static_scene=RaycastScene())

    sweep = seq.sweep(k)
    keep = np.ones(len(sweep.xyz), dtype=bool)
    if cut:
        world_pts = transform_points(seq.frames[k].world_from_ego, sweep.xyz)
        for b in cut:
            keep &= ~points_in_box(world_pts, b, scale=((b.length + 1.5) / b.length, (b.width + 0.6) / b.width, 1.05))
    real = transform_points(invert_transform(mount), sweep.xyz[keep])
    real_offsets = (sweep.time_offset_ns[keep] if sweep.time_offset_ns is not None
                    else np.zeros(len(real), dtype=np.int64))
    real_t = t_k + real_offsets
    real_origins = path.states_at(real_t)[:, :3]
    occluded = _background_occlusion(objects, scenes, real_origins, real, real_t, t_k)

    sim = scan.xyz.astype(np.float64)
    sim_origins = path.states_at(t_k + scan.time_offset_ns)[:, :3]
    kept_real = ~occluded
    rd = real[kept_real] - real_origins[kept_real]
    rr = np.linalg.norm(rd, axis=1)
    sd = sim - sim_origins
    sr = np.linalg.norm(sd, axis=1)
    blocked = blocked_by_real(rd / np.maximum(rr, 1e-9)[:, None], rr, sd / np.maximum(sr, 1e-9)[:, None], sr,
                              angular_tolerance(sensor))
    keep_sim = ~blocked

    intensity_real = (sweep.intensity[keep] if sweep.intensity is not None else np.zeros(len(real), np.float32))
    scale = 255.0 if intensity_real.size and float(intensity_real.max()) > 1.5 else 1.0
    xyz_sensor = np.vstack([real[kept_real], sim[keep_sim]])
    xyz_ego = transform_points(mount, xyz_sensor).astype(np.float32)
    box_times = _centre_times(vehicles, sensor, sensor_from_world, t_k) if vehicles else np.zeros(0, np.int64)
    boxes = []
    for v, t in zip(vehicles, box_times, strict=True):
        x, y, z, h = v.states_at(int(t))
        boxes.append(Box(float(x), float(y), float(z), float(h), *v.size))
    return InsertedFrame(
        xyz=xyz_ego,
        intensity=np.concatenate([intensity_real[kept_real], scan.intensity[keep_sim] * scale]).astype(np.float32),
        time_offset_ns=np.concatenate([real_offsets[kept_real], scan.time_offset_ns[keep_sim]]).astype(np.int64),
        instance=np.concatenate([np.full(int(kept_real.sum()), -1, np.int32), scan.instance[keep_sim]]).astype(np.int32),
        boxes=boxes, box_times_ns=np.asarray(box_times, dtype=np.int64),
        removed_real=int(occluded.sum()), removed_inserted=int(blocked.sum()))
