"""Simulating one sweep of a spinning LiDAR over static and moving meshes.

Rolling scan: column ``j`` of the sweep fires at its own time (``Sensor.column_time_offsets_ns``); the
sensor pose and every moving object's pose are taken at that time, exactly (per ray), when
``Realism.motion_distortion`` is on, else everything is frozen at the frame time.

Static meshes (ground, walls, parked cars) live in one ``RaycastScene`` in the world frame, one mesh each
(a flat ground rectangle is intersected analytically). Each moving object has its own Embree scene in its object frame; rays that pass near it are
transformed into its frame at their firing time and traced there; the nearest hit wins.

Output points are in the sensor frame AT THE FRAME TIME (ego motion compensated, as PandaSet stores them
after our reader); objects that move keep their rolling-scan distortion. ``time_offset_ns`` gives each
point's firing time relative to the frame timestamp (which marks the end of the sweep).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tracker import invert_transform

from ..objects.trajectory import Trajectory
from ..raycast import RaycastScene, RayHits
from ..raycast.compiled import ReturnModels, SweepReturns, compiled_sweep_returns
from .model import Sensor
from .noise import (
    GRAZING_DROP,
    NOISE,
    RANDOM_DROP,
    RANGE_DROP,
    Realism,
    grazing_drop_probability,
    incidence_cosine,
    lambertian_intensity,
    ray_draws,
)

__all__ = ["SimObject", "Scan", "simulate_scan", "range_image", "build_static_scene"]


def rotate(rotation: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N, 3) points rotated by a 3x3 matrix: three fused multiply-add columns, no BLAS (OpenBLAS threads
    stall on a pinned, loaded core) and no einsum (4x slower here)."""
    points = np.asarray(points)
    rotation = np.asarray(rotation)
    out = np.empty(points.shape, dtype=np.result_type(points.dtype, rotation.dtype))
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    for i in range(3):
        np.multiply(x, rotation[i, 0], out=out[:, i])
        out[:, i] += y * rotation[i, 1]
        out[:, i] += z * rotation[i, 2]
    return out


@dataclass
class SimObject:
    """A mesh in its own frame and where it is over time.

    ``instance`` >= 0 marks an annotated object (the value is reported per point), -1 background.
    """

    vertices: np.ndarray
    faces: np.ndarray
    trajectory: Trajectory
    instance: int = -1
    reflectivity: float = 0.5
    name: str = ""

    def radius(self) -> float:
        return float(np.linalg.norm(self.vertices, axis=1).max())


@dataclass
class Scan:
    """One simulated sweep. All arrays have one row per return."""

    xyz: np.ndarray                # (N, 3) float32, sensor frame at the frame time
    instance: np.ndarray           # (N,) int32, -1 background
    intensity: np.ndarray          # (N,) float32 in [0, 1] (0 when intensity is off)
    time_offset_ns: np.ndarray     # (N,) int64 relative to the frame timestamp
    beam: np.ndarray               # (N,) int32
    column: np.ndarray             # (N,) int32
    distance: np.ndarray           # (N,) float32 measured range
    object_index: np.ndarray       # (N,) int32 index into the objects list (-1 never)
    num_beams: int = 0
    num_columns: int = 0
    extra: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.xyz.shape[0])


def range_image(scan: Scan) -> np.ndarray:
    """(B, C) float32 organised range image; 0 where there is no return."""
    image = np.zeros((scan.num_beams, scan.num_columns), dtype=np.float32)
    image[scan.beam, scan.column] = scan.distance
    return image


def _near_sphere(origins: np.ndarray, dirs: np.ndarray, centres: np.ndarray, radius: float,
                 max_range: float) -> np.ndarray:
    d = centres - origins
    t = np.einsum("ij,ij->i", d, dirs)
    perp2 = np.einsum("ij,ij->i", d, d) - t * t
    return (perp2 <= radius * radius) & (t >= -radius) & (t <= max_range + radius)


def simulate_scan(sensor: Sensor, objects: list[SimObject], world_from_sensor: Trajectory | np.ndarray,
                  frame_time_ns: int = 0, realism: Realism | None = None,
                  static_scene: RaycastScene | None = None) -> Scan:
    """Simulate one sweep ending at ``frame_time_ns``.

    ``world_from_sensor`` is a 4x4 (fixed sensor) or a Trajectory of the sensor (x, y, z, heading).
    ``static_scene`` may pass a prebuilt scene of the static objects (same order as they appear in
    ``objects``) to save rebuilding it every frame.
    """
    realism = realism or Realism()
    dirs_s, _, column = sensor.ray_grid()
    col_t = sensor.column_time_offsets_ns()
    times = col_t if realism.motion_distortion else np.zeros_like(col_t)
    abs_times = frame_time_ns + times  # per column

    if isinstance(world_from_sensor, Trajectory):
        sensor_T_col = world_from_sensor.poses_at(abs_times)                              # (C, 4, 4)
        world_from_sensor_frame = world_from_sensor.poses_at(int(frame_time_ns))
    else:
        sensor_T_col = np.broadcast_to(np.asarray(world_from_sensor, dtype=np.float64), (sensor.columns, 4, 4))
        world_from_sensor_frame = np.asarray(world_from_sensor, dtype=np.float64)
    if isinstance(world_from_sensor, Trajectory):
        origins = sensor_T_col[column, :3, 3]
        dirs = np.einsum("nij,nj->ni", sensor_T_col[column, :3, :3], dirs_s)
    else:  # a fixed sensor: one rotation for every ray (none when the sensor frame is the world frame)
        origins = np.broadcast_to(world_from_sensor_frame[:3, 3], dirs_s.shape)
        rotation = world_from_sensor_frame[:3, :3]
        dirs = dirs_s if np.array_equal(rotation, np.eye(3)) else rotate(rotation, dirs_s)

    static_idx = [i for i, o in enumerate(objects) if o.trajectory.is_static]
    moving_idx = [i for i, o in enumerate(objects) if not o.trajectory.is_static]
    if static_scene is None:
        static_scene = build_static_scene(objects)
    hits = static_scene.cast(origins, dirs)
    obj_of_geom = np.array(static_idx + [-1], dtype=np.int32)
    if moving_idx:   # moving objects overwrite the object of the rays they hit first (below)
        object_index, object_of = obj_of_geom[hits.geom_id], None   # a miss (geom -1) picks the last entry, -1
    else:            # the returns pass maps geometry ids to objects itself (no gather over every ray)
        object_index, object_of = hits.geom_id, obj_of_geom[:-1]
    # moving objects overwrite the nearer hits below; without any, the cast's arrays are only read
    dist, normal = (hits.distance.copy(), hits.normal.copy()) if moving_idx else (hits.distance, hits.normal)

    for i in moving_idx:
        o = objects[i]
        states_col = o.trajectory.states_at(abs_times)                 # (C, 4)
        centres = states_col[column, :3]
        cand = np.flatnonzero(_near_sphere(origins, dirs, centres, o.radius(), sensor.max_range))
        if cand.size == 0:
            continue
        object_from_world = invert_transform_batch(o.trajectory.poses_at(abs_times))[column[cand]]
        o_obj = np.einsum("nij,nj->ni", object_from_world[:, :3, :3], origins[cand]) + object_from_world[:, :3, 3]
        d_obj = np.einsum("nij,nj->ni", object_from_world[:, :3, :3], dirs[cand])
        scene = RaycastScene()
        scene.add_mesh(o.vertices, o.faces)
        h: RayHits = scene.cast(o_obj, d_obj)
        closer = h.hit & (h.distance < dist[cand])
        sel = cand[closer]
        dist[sel] = h.distance[closer]
        world_from_object_rot = np.transpose(object_from_world[closer, :3, :3], (0, 2, 1))
        normal[sel] = np.einsum("nij,nj->ni", world_from_object_rot, h.normal[closer])
        object_index[sel] = i

    sensor_from_world = invert_transform(world_from_sensor_frame)
    models = ReturnModels(
        sensor.min_range, sensor.max_range, realism.seed,
        noise_sigma=sensor.range_noise_sigma if realism.range_noise else 0.0, drop_random=realism.drop_random,
        drop_grazing=realism.drop_grazing, grazing_start_deg=realism.grazing_start_deg,
        drop_range=realism.drop_range and sensor.has_range_drop, range_a=sensor.drop_at_zero_range,
        range_b=sensor.drop_per_m, intensity=realism.intensity, attenuation=realism.attenuation_per_m)
    reflectivity = np.array([o.reflectivity for o in objects], dtype=np.float64)
    instance = np.array([o.instance for o in objects], dtype=np.int32)
    # the random draws are counter-based (noise.ray_draws): each ray's number per effect depends on the seed and
    # the ray only, so a seed gives the same scan whatever the scene and whichever implementation below runs
    args = (dist, normal, dirs, origins, object_index, reflectivity, instance, models, sensor_from_world,
            sensor.columns, col_t, object_of)
    returns = compiled_sweep_returns(*args)
    if returns is None:   # the compiled loop is not built: the same models in numpy
        returns = sweep_returns_numpy(*args)
    return Scan(xyz=returns.xyz, instance=returns.instance, intensity=returns.intensity,
                time_offset_ns=returns.time_offset_ns, beam=returns.beam, column=returns.column,
                distance=returns.distance, object_index=returns.object_index, num_beams=sensor.beams,
                num_columns=sensor.columns)


def sweep_returns_numpy(distance: np.ndarray, normal: np.ndarray, dirs: np.ndarray, origins: np.ndarray,
                        object_index: np.ndarray, reflectivity: np.ndarray, instance: np.ndarray,
                        models: ReturnModels, target_from_world: np.ndarray, columns: int,
                        column_time_ns: np.ndarray, object_of: np.ndarray | None = None) -> SweepReturns:
    """numpy twin of the compiled ``sot_rt_returns`` (:func:`compiled_sweep_returns`: same arguments, same draws,
    same results; the fallback when the loop is not built; tests compare the two)."""
    m = models
    valid = np.isfinite(distance) & (distance >= m.min_range) & (distance <= m.max_range)
    cand = np.flatnonzero(valid)
    cos_cand = incidence_cosine(np.take(dirs, cand, axis=0), np.take(normal, cand, axis=0))  # take: 3x faster
    dist_cand = distance[cand]
    dropped = np.zeros(len(cand), dtype=bool)
    if m.drop_random > 0:
        dropped |= ray_draws(m.seed, RANDOM_DROP, cand) < m.drop_random
    if m.drop_grazing:
        dropped |= ray_draws(m.seed, GRAZING_DROP, cand) < grazing_drop_probability(cos_cand, m.grazing_start_deg)
    if m.drop_range:
        dropped |= ray_draws(m.seed, RANGE_DROP, cand) < np.clip(m.range_a + m.range_b * dist_cand, 0.0, 1.0)
    keep = cand[~dropped]
    measured = dist_cand[~dropped]
    if m.noise_sigma > 0:
        measured = measured + m.noise_sigma * ray_draws(m.seed, NOISE, keep, normal=True)
    objects = np.asarray(object_index)[keep]
    if object_of is not None:   # geometry ids: their objects
        objects = np.append(np.asarray(object_of, dtype=np.int32), -1)[
            np.where((objects >= 0) & (objects < len(object_of)), objects, -1)]
    known = (objects >= 0) & (objects < len(reflectivity))
    if m.intensity:
        rho = np.where(known, np.append(reflectivity, 0.0)[np.where(known, objects, -1)], 0.0)
        intensity = lambertian_intensity(cos_cand[~dropped], rho, measured, m.attenuation)
    else:
        intensity = np.zeros(len(keep))
    single_origin = origins.ndim == 1 or origins.shape[0] == 1 or origins.strides[0] == 0
    pts_world = (origins.reshape(-1, 3)[0] if single_origin else np.take(origins, keep, axis=0)) + \
        np.take(dirs, keep, axis=0) * measured[:, None]
    target_from_world = np.asarray(target_from_world, dtype=np.float64)
    xyz = (rotate(target_from_world[:3, :3], pts_world) + target_from_world[:3, 3]).astype(np.float32)
    column = (keep % columns).astype(np.int32)
    inst = np.where(known, np.append(np.asarray(instance, dtype=np.int32), -1)[np.where(known, objects, -1)], -1)
    return SweepReturns(keep, xyz, measured.astype(np.float32), intensity.astype(np.float32),
                        (keep // columns).astype(np.int32), column,
                        np.asarray(column_time_ns, dtype=np.int64)[column], objects.astype(np.int32),
                        inst.astype(np.int32))


def build_static_scene(objects: list[SimObject]) -> RaycastScene:
    """One Embree scene (world frame) of the static objects, in list order: geometry id g is the g-th static one."""
    scene = RaycastScene()
    for o in objects:
        if o.trajectory.is_static:
            T = o.trajectory.poses_at(int(o.trajectory.times_ns[0]))
            scene.add_mesh(rotate(T[:3, :3], np.asarray(o.vertices, dtype=np.float64)) + T[:3, 3], o.faces)
    return scene


def invert_transform_batch(target_from_source: np.ndarray) -> np.ndarray:
    """Inverse of (..., 4, 4) rigid transforms."""
    rot = np.swapaxes(target_from_source[..., :3, :3], -1, -2)
    out = np.zeros_like(target_from_source)
    out[..., :3, :3] = rot
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", rot, target_from_source[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out
