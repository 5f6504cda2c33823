"""How close simulated vehicles come to real scans (leave-one-frame-out).

For each annotated track (default: the 9 PandaSet dev tracks) and up to ``--frames-per-track`` frames k
(evenly spread over the frames where the real box holds at least ``--min-points`` points):

1. a bank entry is built from the track's points in every frame EXCEPT k (de-skewed into the object frame
   with boxes interpolated at each point's capture time, ground cut 0.15 m above the box bottom), meshed
   with surfels (with and without mirror completion);
2. it is simulated with the sensor (default ``pandaset_pandar64``) at frame k's box pose relative to the sensor,
   inserted into frame k's real sweep (the real returns inside the box are removed first) so real
   occluders hide it as they hid the real car; range noise and grazing drop on;
3. simulated and real points in the box at frame k (object frame, same ground cut) are compared:
   symmetric Chamfer distance (mean of both nearest-neighbour directions, metres) and point-count ratio
   simulated / real.

A plain cuboid of the annotated box size, simulated the same way, is the baseline.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracker import chamfer_distance

__all__ = ["evaluate_realism", "format_tables", "chamfer", "Row"]


def chamfer(a: np.ndarray, b: np.ndarray) -> float:
    """Symmetric Chamfer distance: (mean NN distance a->b + mean NN distance b->a) / 2 (NaN if one is empty)."""
    return 0.5 * chamfer_distance(a, b, voxel=None, symmetric_mean=True)


@dataclass
class Row:
    track: str
    frame: int
    range_m: float
    real_points: int
    variant: str
    sim_points: int
    chamfer_m: float

    @property
    def ratio(self) -> float:
        return self.sim_points / self.real_points if self.real_points else float("nan")


def evaluate_realism(seq, track_prefixes, sensor_name: str = "pandaset_pandar64", frames_per_track: int = 3,
                     min_points: int = 20, origin_z: float = 0.0, seed: int = 0, progress: bool = True,
                     origin: tuple[float, float, float] | None = None) -> list[Row]:
    from tqdm import tqdm

    from tracker import Box, invert_transform, points_in_box, transform_points

    from ..objects.bank import GROUND_CLEARANCE, track_points_by_frame
    from ..objects.meshes import SurfelParams, box_mesh, surfel_mesh
    from ..objects.trajectory import Trajectory
    from ..sensor.model import load_sensor
    from ..sensor.noise import Realism
    from ..sensor.occlusion import angular_tolerance, blocked_by_real
    from ..sensor.scan import SimObject, simulate_scan

    sensor = load_sensor(sensor_name)
    ids = [seq.resolve_track_id(p) for p in track_prefixes]
    per_frame = track_points_by_frame(seq, ids, progress=progress)
    tracks = seq.tracks()
    jobs = []
    for tid in ids:
        good = [k for k, pts in sorted(per_frame[tid].items()) if len(pts) >= min_points]
        if len(good) < 2:
            continue
        picks = sorted(set(good[int(round(i))] for i in np.linspace(0, len(good) - 1, min(frames_per_track, len(good)))))
        jobs += [(tid, k) for k in picks]
    rows: list[Row] = []

    # the simulated optical centre in the LiDAR frame (``origin`` wins over ``origin_z``)
    centre = np.asarray(origin if origin is not None else (0.0, 0.0, origin_z), dtype=np.float64)
    lidar_from_ego = invert_transform(seq.ego_from_lidar)
    for tid, k in tqdm(jobs, desc="realism", unit="job", disable=not progress, leave=False):
        box_world = tracks[tid].box_at(k)
        real = per_frame[tid][k]
        others = np.vstack([p for j, p in per_frame[tid].items() if j != k])
        size = box_world.size
        cuboid = box_mesh(*(float(v) for v in size))
        meshes = {"box": (cuboid.vertices, cuboid.faces)}
        for variant, mirror in (("surfel", False), ("surfel+mirror", True)):
            v, f, _ = surfel_mesh(others, SurfelParams(), mirror=mirror)
            meshes[variant] = (v, f)
        sensor_from_world = lidar_from_ego @ invert_transform(seq.frames[k].world_from_ego)
        box_sensor: Box = box_world.transformed(sensor_from_world)
        sweep = seq.sweep(k)
        bg = transform_points(lidar_from_ego, sweep.xyz)
        bg = bg[~points_in_box(bg, box_sensor, scale=(1.1, 1.1, 1.05))] - centre
        bg_r = np.linalg.norm(bg, axis=1)
        bg, bg_r = bg[bg_r > 1e-6], bg_r[bg_r > 1e-6]
        rng_m = float(np.hypot(box_sensor.x, box_sensor.y))
        pose = Trajectory.static(box_sensor.x - centre[0], box_sensor.y - centre[1], box_sensor.z - centre[2],
                                 box_sensor.heading)
        realism = Realism(range_noise=True, drop_grazing=True, intensity=False, motion_distortion=False, seed=seed + k)
        for variant in ("box", "surfel", "surfel+mirror"):
            scan = simulate_scan(sensor, [SimObject(*meshes[variant], pose, instance=0)], np.eye(4), realism=realism)
            sim = scan.xyz.astype(np.float64)
            sim_r = np.linalg.norm(sim, axis=1)
            hidden = blocked_by_real(bg / bg_r[:, None], bg_r, sim / sim_r[:, None], sim_r, angular_tolerance(sensor))
            sim = sim[~hidden] + centre
            local = transform_points(box_sensor.object_from_world(), sim)
            local = local[local[:, 2] > -box_sensor.height / 2 + GROUND_CLEARANCE]
            rows.append(Row(tid[:8], k, rng_m, len(real), variant, len(local), chamfer(local, real)))
    return rows


def format_tables(rows: list[Row], sensor: str, seconds: float) -> str:
    variants = ("box", "surfel", "surfel+mirror")
    lines = [f"realism (leave-one-frame-out), sensor {sensor}; Chamfer in cm, ratio = simulated / real points", "",
             "| track | frames | range (m) | real pts | " + " | ".join(f"{v} CD | {v} ratio" for v in variants) + " |",
             "|---|---:|---:|---:|" + "---:|---:|" * len(variants)]
    for track in dict.fromkeys(r.track for r in rows):
        sel = [r for r in rows if r.track == track]
        frames = sorted({r.frame for r in sel})
        base = [r for r in sel if r.variant == "box"]
        cells = []
        for v in variants:
            vs = [r for r in sel if r.variant == v]
            cells.append(f"{np.nanmean([r.chamfer_m for r in vs]) * 100:.1f} | {np.nanmean([r.ratio for r in vs]):.2f}")
        lines.append(f"| {track} | {','.join(map(str, frames))} | {np.mean([r.range_m for r in base]):.1f} | "
                     f"{np.mean([r.real_points for r in base]):.0f} | " + " | ".join(cells) + " |")
    cells = []
    for v in variants:
        vs = [r for r in rows if r.variant == v]
        cells.append(f"{np.nanmedian([r.chamfer_m for r in vs]) * 100:.1f} | {np.nanmedian([r.ratio for r in vs]):.2f}")
    lines.append(f"| **median** | {len(rows) // len(variants)} jobs | | | " + " | ".join(cells) + " |")
    lines.append("")
    lines.append(f"({seconds:.0f} s)")
    return "\n".join(lines)
