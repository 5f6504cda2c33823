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
from ..raycast.compiled import SweepReturns, compiled_sweep_returns
from .model import Sensor
from .noise import Realism, grazing_drop_probability, incidence_cosine, lambertian_intensity

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
    rng = np.random.default_rng(realism.seed)
    dirs_s, beam, column = sensor.ray_grid()
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
    object_index = obj_of_geom[hits.geom_id]   # a miss (geom -1) picks the last entry, -1
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
    reflect = np.array([o.reflectivity for o in objects] + [0.0], dtype=np.float64)
    # the random draws: every ray of the sweep gets one per effect, in this order, so a seed gives the same scan
    # whatever the scene (and whichever implementation below runs)
    n = len(dist)
    noise = None
    if realism.range_noise and sensor.range_noise_sigma > 0:
        # rng.normal(0, sigma, n) is 0.0 + sigma * standard_normal: the same numbers (a -0.0 becomes +0.0, which
        # adds the same to a range), drawn ~20 % faster
        noise = rng.standard_normal(n)
        noise *= sensor.range_noise_sigma
    range_on = realism.drop_range and sensor.has_range_drop
    u_random = u_grazing = u_range = None
    if realism.drop_random > 0 or realism.drop_grazing or range_on:
        u_random = rng.random(n)
        u_grazing = rng.random(n) if realism.drop_grazing else None
        u_range = rng.random(n) if range_on else None
    returns = compiled_sweep_returns(
        dist, normal, dirs, origins, object_index, reflect[:-1], sensor.min_range, sensor.max_range, noise,
        u_random if realism.drop_random > 0 else None, realism.drop_random, u_grazing, realism.grazing_start_deg,
        u_range, sensor.drop_at_zero_range, sensor.drop_per_m, realism.intensity, realism.attenuation_per_m,
        sensor_from_world)
    if returns is None:   # the compiled loop is not built: the same models in numpy
        returns = _sweep_returns_numpy(sensor, realism, dist, normal, dirs, origins, object_index, reflect, noise,
                                       u_random, u_grazing, u_range, sensor_from_world)
    keep, measured, intensity, xyz = returns.keep, returns.measured, returns.intensity, returns.xyz
    inst_of_obj = np.array([o.instance for o in objects] + [-1], dtype=np.int32)
    kept_object, kept_column = object_index[keep], column[keep]   # each gather once (they cost ~0.3 ms apiece)
    return Scan(xyz=xyz, instance=inst_of_obj[kept_object], intensity=intensity,
                time_offset_ns=col_t[kept_column].astype(np.int64, copy=False), beam=beam[keep], column=kept_column,
                distance=measured.astype(np.float32), object_index=kept_object,
                num_beams=sensor.beams, num_columns=sensor.columns)


def _sweep_returns_numpy(sensor: Sensor, realism: Realism, dist: np.ndarray, normal: np.ndarray, dirs: np.ndarray,
                        origins: np.ndarray, object_index: np.ndarray, reflect: np.ndarray, noise: np.ndarray | None,
                        u_random: np.ndarray | None, u_grazing: np.ndarray | None, u_range: np.ndarray | None,
                        sensor_from_world: np.ndarray) -> SweepReturns:
    """numpy twin of the compiled ``sot_rt_returns`` (the fallback when it is not built; tests compare the two)."""
    valid = np.isfinite(dist) & (dist >= sensor.min_range) & (dist <= sensor.max_range)
    cand = np.flatnonzero(valid)
    cos_cand = incidence_cosine(np.take(dirs, cand, axis=0), np.take(normal, cand, axis=0))  # take: 3x faster
    measured = dist if noise is None else dist + noise
    dropped = np.zeros(len(cand), dtype=bool)
    if u_random is not None:
        dropped |= u_random[cand] < realism.drop_random
    if u_grazing is not None:
        dropped |= u_grazing[cand] < grazing_drop_probability(cos_cand, realism.grazing_start_deg)
    if u_range is not None:
        dropped |= u_range[cand] < sensor.range_drop_probability(dist[cand])
    keep = cand[~dropped]
    if realism.intensity:
        intensity = lambertian_intensity(cos_cand[~dropped], reflect[object_index[keep]], measured[keep],
                                         realism.attenuation_per_m)
    else:
        intensity = np.zeros(len(keep))
    single_origin = origins.ndim == 2 and origins.strides[0] == 0
    pts_world = (origins[0] if single_origin else np.take(origins, keep, axis=0)) + \
        np.take(dirs, keep, axis=0) * measured[keep, None]
    xyz = (rotate(sensor_from_world[:3, :3], pts_world) + sensor_from_world[:3, 3]).astype(np.float32)
    return SweepReturns(keep, measured[keep], intensity.astype(np.float32), xyz)


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
