"""``bev_grid``: a bird's-eye-view occupancy and velocity grid of the tracked objects, per frame, ego-centred.

An example of a third-party sot-apps app (README.md of this package): it uses only the App protocol
(:mod:`sot_apps.apps`), the readers and writers of :mod:`sot_apps.io` and the ``tracker`` package's geometry.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sot_apps.apps import AppBase, RunContext, UnitOutput, track_dir

__all__ = ["BevGridConfig", "BevGridApp", "bev_grids"]

FILE_NAME = "bev_grid.npz"


@dataclass(frozen=True)
class BevGridConfig:
    extent_m: float = 40.0      # the grid covers [-extent_m, extent_m] around the ego, in x and y
    cell_m: float = 0.5         # cell size
    min_quality: float = 0.0    # track frames of lower quality are left out

    def __post_init__(self) -> None:
        if not (self.extent_m > 0 and self.cell_m > 0 and self.cell_m <= self.extent_m):
            raise ValueError("extent_m and cell_m must be > 0 with cell_m <= extent_m")


class BevGridApp(AppBase):
    name = "bev_grid"
    config_type = BevGridConfig
    description = "BEV occupancy, instance and velocity grids of the tracked objects per frame (ego-centred .npz)"
    outputs = (f"<sequence>/{FILE_NAME}",)

    def plan(self, config: BevGridConfig, run: RunContext) -> list:
        return self.per_sequence(run, lambda s: [self.sequence_unit(s, frames=list(s.frames))])

    def run(self, config: BevGridConfig, out: Path, sequence: str, path: str, format: str | None,
            frames: list[int], object_ids: list[str]) -> UnitOutput:
        from sot_apps.io import open_sequence
        from sot_apps.io.atomic import write_npz
        from sot_apps.io.tracks import read_track

        seq = open_sequence(path, format=format)
        indices = np.arange(frames[0], frames[1] + 1)
        world_from_ego = np.stack([seq.frames[k].world_from_ego for k in indices])
        stamps = np.array([seq.frames[k].timestamp_ns for k in indices], np.int64)
        objects = []
        for object_id in object_ids:
            _, track = read_track(track_dir(out, sequence, object_id))
            kept = track.select(track.scores >= config.min_quality)   # scores: the tracker's quality
            objects.append((kept.frames, kept.timestamps_ns, kept.states, track.size[:2]))
        occupancy, instance, velocity = bev_grids(indices, world_from_ego, objects, config.extent_m, config.cell_m)
        target = Path(out) / sequence / FILE_NAME
        write_npz(target, occupancy=occupancy, instance=instance, velocity_ego=velocity, frames=indices,
                  timestamps_ns=stamps, object_ids=np.array(object_ids, dtype=str),
                  cell_m=np.float64(config.cell_m), extent_m=np.float64(config.extent_m))
        return UnitOutput([target], {"sequence": sequence, "frames": int(len(indices)), "objects": len(object_ids),
                                     "occupied_cells": int(occupancy.sum())})


def world_velocity(stamps_ns: np.ndarray, states: np.ndarray) -> np.ndarray:
    """(N, 2) world-frame velocity (m/s) of a track's centre: finite differences over its frames' timestamps
    (one-sided at the ends; zero for a single frame)."""
    if len(stamps_ns) < 2:
        return np.zeros((len(stamps_ns), 2))
    t = (stamps_ns - stamps_ns[0]) * 1e-9
    return np.stack([np.gradient(states[:, 0], t), np.gradient(states[:, 1], t)], axis=1)


def bev_grids(frames: np.ndarray, world_from_ego: np.ndarray, objects: list, extent_m: float, cell_m: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per frame an ego-centred grid (row i = y, column j = x, cell centres from -extent_m + cell_m / 2):
    ``occupancy`` (T, H, W) uint8 (a cell centre inside a tracked box's footprint), ``instance`` (T, H, W) int16
    (index into the objects, -1 = free; a later object wins an overlap) and ``velocity_ego`` (T, H, W, 2) float32,
    the occupying object's ground velocity (m/s) in the ego frame's x/y axes. ``objects``: per object
    (frames, timestamps_ns, states (N, 4) world x, y, z, heading, (length, width))."""
    n = int(round(2 * extent_m / cell_m))
    centres = -extent_m + cell_m * (np.arange(n) + 0.5)
    xs, ys = np.meshgrid(centres, centres)                       # (H, W): row = y, column = x
    occupancy = np.zeros((len(frames), n, n), np.uint8)
    instance = np.full((len(frames), n, n), -1, np.int16)
    velocity = np.zeros((len(frames), n, n, 2), np.float32)
    slot = {int(k): i for i, k in enumerate(frames)}
    ego_from_world = np.linalg.inv(world_from_ego)
    for index, (obj_frames, stamps, states, (length, width)) in enumerate(objects):
        v_world = world_velocity(stamps, states)
        for k, state, v in zip(obj_frames, states, v_world, strict=True):
            if int(k) not in slot:
                continue
            t = slot[int(k)]
            rot = ego_from_world[t, :2, :2]
            cx, cy = rot @ state[:2] + ego_from_world[t, :2, 3]
            heading = state[3] + np.arctan2(rot[1, 0], rot[0, 0])
            du, dv = xs - cx, ys - cy
            along = du * np.cos(heading) + dv * np.sin(heading)
            across = -du * np.sin(heading) + dv * np.cos(heading)
            inside = (np.abs(along) <= length / 2) & (np.abs(across) <= width / 2)
            occupancy[t][inside] = 1
            instance[t][inside] = index
            velocity[t][inside] = rot @ v
    return occupancy, instance, velocity
