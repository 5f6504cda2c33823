"""What the benchmark needs to know about a real background sequence: where there is free ground, where the
real objects are, and how its sensor sweeps.

Free ground (:class:`GroundMap`, world frame, square cells of ``cell`` metres) from the sweeps of the chosen
frames, with the points inside any real annotated box (grown by 1.5 m at each end, 0.5 m at each side) left out (real objects are avoided
per frame, box against box):

- a cell's ground height is the lowest point in it, or, where that is no road (no points, something standing,
  off the terrain), the road surface around it: the median road height of 4 m blocks, interpolated;
- a cell is *blocked* when a point stands 0.3-3.5 m above its ground (walls, poles, trees, unannotated
  objects), or when its lowest point is more than 0.6 m off the terrain (the 20th percentile of the cell
  heights over 18 m: roofs, canopies, wall tops) or off an 8 % grade from the terrain under the ego;
  blocked cells are grown by ``margin`` metres;
- a cell is *ground* when it, or a cell within ``reach`` metres, has points and is not blocked (far away the
  rings on the road are metres apart; the gaps between them are road too). Placement asks for no blocked
  cell under a vehicle and ground under 90 % of its footprint.

The scan phase (:func:`fit_scan_start`): a spinning LiDAR fires azimuth ``start + direction * 2 pi (t + T) / T``
at time ``t`` (relative to the frame timestamp, which ends the sweep); the real per-point times give
``start`` (circular mean), so inserted vehicles are swept at the same instants as the real scene.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage

from tracker import Box, invert_transform, points_in_box, transform_points

from ..io.sequence import Sequence
from .deps import Sensor, Trajectory

__all__ = ["GroundMap", "MAX_GRADE", "build_ground_map", "fit_scan_start", "fitted_sensor", "sensor_path", "ego_from_sensor", "to_states",
           "STANDING_MIN_M", "STANDING_MAX_M"]

STANDING_MIN_M = 0.3
STANDING_MAX_M = 3.5
TERRAIN_WINDOW_M = 18.0
TERRAIN_TOLERANCE_M = 0.6
MAX_GRADE = 0.08
ROAD_BLOCK_M = 4.0
ROAD_BLOCK_MIN_CELLS = 3


@dataclass(frozen=True)
class GroundMap:
    origin: np.ndarray        # (2,) world x, y of cell (0, 0)'s corner
    cell: float
    height: np.ndarray        # (H, W) ground z: a road cell's lowest point; every other cell's from the road surface around it
    ground: np.ndarray        # (H, W) bool: free ground
    known: np.ndarray         # (H, W) bool: cells with points
    blocked: np.ndarray       # (H, W) bool: something stands there (grown by the margin)

    def index(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Row, column and in-map flag of (N, 2) world points."""
        col = ((xy[:, 0] - self.origin[0]) * (1.0 / self.cell)).astype(np.int64)  # truncation: >= 0 inside
        row = ((xy[:, 1] - self.origin[1]) * (1.0 / self.cell)).astype(np.int64)
        h, w = self.ground.shape
        inside = (col >= 0) & (col < w) & (row >= 0) & (row < h) & (xy[:, 0] >= self.origin[0]) & \
            (xy[:, 1] >= self.origin[1])
        return np.where(inside, row, 0), np.where(inside, col, 0), inside

    def free(self, xy: np.ndarray) -> np.ndarray:
        r, c, inside = self.index(xy)
        return inside & self.ground[r, c]

    def blocked_at(self, xy: np.ndarray) -> np.ndarray:
        r, c, inside = self.index(xy)
        return inside & self.blocked[r, c]

    def z(self, xy: np.ndarray) -> np.ndarray:
        r, c, _ = self.index(xy)
        return self.height[r, c]


def _frame_points(seq: Sequence, k: int, stride: int) -> np.ndarray:
    pts = seq.points_world(k)[::stride]
    for ann in (seq.annotations[k] if seq.annotations else []):
        b = ann.box  # grown 1.5 m at each end: a moving object's points smear along its motion over a sweep
        pts = pts[~points_in_box(pts, b, scale=((b.length + 3.0) / b.length, (b.width + 1.0) / b.width, 1.2))]
    return pts


def build_ground_map(seq: Sequence, frames: list[int], cell: float = 0.5, margin: float = 0.5, reach: float = 4.0,
                     stride: int = 2) -> GroundMap:
    """The free-ground map of ``frames`` (see the module doc)."""
    pts = np.vstack([_frame_points(seq, k, stride) for k in frames])
    lo = pts[:, :2].min(axis=0) - 5.0
    shape = tuple((np.ceil((pts[:, :2].max(axis=0) + 5.0 - lo) / cell)).astype(int)[::-1])
    ij = np.floor((pts[:, :2] - lo) / cell).astype(np.int64)
    flat = ij[:, 1] * shape[1] + ij[:, 0]
    low = np.full(shape[0] * shape[1], np.inf)
    np.minimum.at(low, flat, pts[:, 2])
    rel = pts[:, 2] - low[flat]
    standing = np.zeros(shape[0] * shape[1], dtype=bool)
    standing[flat[(rel > STANDING_MIN_M) & (rel < STANDING_MAX_M)]] = True
    known = np.isfinite(low).reshape(shape)
    height = low.reshape(shape)
    # fill unknown heights from the nearest known cell
    _, (ri, ci) = ndimage.distance_transform_edt(~known, return_indices=True)
    height = np.where(known, height, height[ri, ci])
    # a cell whose lowest point is well above the terrain (a roof, a canopy, a wall top) is no ground
    step = max(1, int(round(2.0 / cell)))
    coarse = height[::step, ::step]
    terrain = ndimage.percentile_filter(coarse, 20, size=max(3, int(round(TERRAIN_WINDOW_M / (step * cell))) | 1))
    terrain = np.repeat(np.repeat(terrain, step, axis=0), step, axis=1)[:shape[0], :shape[1]]
    off_terrain = known & (np.abs(height - terrain) > TERRAIN_TOLERANCE_M)
    # and no road climbs more than MAX_GRADE from the ground under the ego
    ego = np.array([(seq.frames[k].world_from_ego @ seq.ego_from_lidar)[:3, 3] for k in frames])
    ego_ij = np.floor((ego[:, :2] - lo) / cell).astype(np.int64)
    # the terrain there, not the lowest point of the ego's own cell (that is its roof or body when the ego hides
    # the road under it: then every true ground cell near the ego was 'off the grade')
    ego_ground = float(np.median(terrain[ego_ij[:, 1], ego_ij[:, 0]]))
    rows, cols = np.indices(shape)
    centre = ego[:, :2].mean(axis=0)
    dist = np.hypot(lo[0] + (cols + 0.5) * cell - centre[0], lo[1] + (rows + 0.5) * cell - centre[1])
    off_terrain |= known & (np.abs(height - ego_ground) > MAX_GRADE * dist + TERRAIN_TOLERANCE_M)
    blocked = ndimage.binary_dilation(standing.reshape(shape) | off_terrain, iterations=max(1, int(round(margin / cell))))
    reach_cells = max(1, int(round(reach / cell)))
    near_known = ndimage.binary_dilation(known & ~blocked, iterations=reach_cells)
    return GroundMap(lo, cell, _road_heights(low.reshape(shape), known & ~standing.reshape(shape) & ~off_terrain,
                                             height, cell), near_known & ~blocked, known, blocked)


def _road_heights(low: np.ndarray, road: np.ndarray, fallback: np.ndarray, cell: float) -> np.ndarray:
    """Every cell's ground height: a *road* cell's (known, nothing standing in it, on the terrain) lowest point;
    any other cell's from the road surface around it (:func:`_road_surface`)."""
    if not road.any():
        return fallback
    return np.where(road, low, _road_surface(low, road, cell))


def _road_surface(low: np.ndarray, road: np.ndarray, cell: float) -> np.ndarray:
    """The road's height at every cell, smooth over ROAD_BLOCK_M: the median of the road cells' heights in each
    block of ROAD_BLOCK_M (blocks with fewer than ROAD_BLOCK_MIN_CELLS road cells take the nearest block that has
    them), interpolated bilinearly between block centres.

    Far from the sensor a vehicle's footprint has few cells with points, and the lowest point of a lone cell is
    noisy (0.3-0.5 m low on PandaSet 002 at 50 m): the nearest road cell alone gave a path a false 0.4 m drop."""
    block = max(1, int(round(ROAD_BLOCK_M / cell)))
    rows, cols = np.nonzero(road)
    shape = (-(-low.shape[0] // block), -(-low.shape[1] // block))
    ids = (rows // block) * shape[1] + cols // block
    heights = low[rows, cols]
    order = np.lexsort((heights, ids))
    ids, heights = ids[order], heights[order]
    first = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    counts = np.diff(np.r_[first, len(ids)])
    enough = counts >= ROAD_BLOCK_MIN_CELLS
    use = enough if enough.any() else np.ones_like(enough)   # no block with enough road: each block's own median
    median = np.full(shape[0] * shape[1], np.nan)
    median[ids[first][use]] = 0.5 * (heights[first + (counts - 1) // 2] + heights[first + counts // 2])[use]
    median = median.reshape(shape)
    _, (bi, bj) = ndimage.distance_transform_edt(~np.isfinite(median), return_indices=True)
    median = median[bi, bj]
    r = (np.arange(low.shape[0]) + 0.5) / block - 0.5
    c = (np.arange(low.shape[1]) + 0.5) / block - 0.5
    rr, cc = np.meshgrid(r, c, indexing="ij")
    return ndimage.map_coordinates(median, [rr, cc], order=1, mode="nearest")


def fit_scan_start(seq: Sequence, frames: list[int], sensor: Sensor) -> float | None:
    """Azimuth (deg, LiDAR frame) of the first column, from the real per-point times; None without times."""
    lidar_from_ego = invert_transform(seq.ego_from_lidar)
    angles = []
    period = sensor.period_s
    for k in frames[:: max(1, len(frames) // 5)]:
        sweep = seq.sweep(k)
        if sweep.time_offset_ns is None:
            return None
        xyz = transform_points(lidar_from_ego, sweep.xyz[::20])
        az = np.arctan2(xyz[:, 1], xyz[:, 0])
        t = sweep.time_offset_ns[::20] * 1e-9
        angles.append(az - sensor.direction * 2.0 * math.pi * (t + period) / period)
    a = np.concatenate(angles)
    return float(np.degrees(np.angle(np.mean(np.exp(1j * a)))))


def fitted_sensor(seq: Sequence, frames: list[int], sensor: Sensor) -> Sensor:
    start = fit_scan_start(seq, frames, sensor)
    return sensor if start is None else replace(sensor, scan_start_deg=round(start, 2))


def to_states(matrices: np.ndarray) -> np.ndarray:
    """(..., 4, 4) -> (..., 4) x, y, z, yaw."""
    return np.concatenate([matrices[..., :3, 3], np.arctan2(matrices[..., 1, 0], matrices[..., 0, 0])[..., None]],
                          axis=-1)


def ego_from_sensor(seq: Sequence, origin: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """The simulated sensor (the optical centre: ``origin`` in the LiDAR frame) in the ego frame."""
    lidar_from_sensor = np.eye(4)
    lidar_from_sensor[:3, 3] = origin
    return seq.ego_from_lidar @ lidar_from_sensor


def sensor_path(seq: Sequence, k: int, origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
                ) -> tuple[np.ndarray, Trajectory]:
    """``world_from_sensor`` at frame k's time and the sensor's trajectory over the sweep in THAT frame.

    The poses of frames k-1, k, k+1 (those that exist) relative to frame k, as x, y, z, yaw (roll and
    pitch change by hundredths of a degree over a sweep). ``origin``: the optical centre in the LiDAR frame.
    """
    mount = ego_from_sensor(seq, origin)
    world_from_sensor = seq.frames[k].world_from_ego @ mount
    sensor_from_world = invert_transform(world_from_sensor)
    ks = [j for j in (k - 1, k, k + 1) if 0 <= j < len(seq)]
    rel = np.array([sensor_from_world @ seq.frames[j].world_from_ego @ mount for j in ks])
    states = to_states(rel)
    states[:, 3] = np.unwrap(states[:, 3])
    return world_from_sensor, Trajectory(np.array([seq.frames[j].timestamp_ns for j in ks], dtype=np.int64), states)


def boxes_array(boxes: list[Box]) -> np.ndarray:
    return np.array([[b.x, b.y, b.z, b.heading, b.length, b.width, b.height] for b in boxes], dtype=np.float64
                    ).reshape(-1, 7)
