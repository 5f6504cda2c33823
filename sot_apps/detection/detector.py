"""A model-free vehicle detector: ground removal, BEV clustering, L-shape box fitting, size gates, a score.

No learned weights. Per sweep (ego frame, then boxes moved to the world):

1. keep points within ``max_range`` (BEV) and remove the ground (GPF per cell, :mod:`tracker.ground`);
   keep what lies between ``min_height`` and ``max_height`` above the local ground;
2. cluster in bird's-eye view: occupied ``cell`` m cells, 8-connected components (scipy.ndimage.label);
3. fit a rectangle to each cluster: a search over headings in [0, 90) degrees maximising the L-shape
   closeness criterion (Zhang et al., "Efficient L-shape fitting for vehicle detection using laser
   scanners", 2017), the rectangle = the points' extent in that frame; the longer side is the length;
4. complete partial views: a side shorter than a vehicle's minimum is grown to that minimum AWAY from the
   sensor (the visible face is the near one); the box spans from the ground to the cluster's top;
5. gates: the fitted (visible) extent must fit in a vehicle (``max_length`` x ``max_width``) and its longer
   side be at least ``min_visible_length`` (poles, trunks), the height in
   [``min_box_height``, ``max_box_height``], at least ``min_points`` points;
6. score in [0, 1] = fit quality (share of the points within ``edge_distance`` of the two visible edges)
   x point support (1 - exp(-n / ``support_points``)) x (1 + size plausibility) / 2 (the completed box's
   length, width and height against a typical car's, Gaussian).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from tracker import FrameDetections, GroundParams, ground_mask, transform_points, wrap_angle

__all__ = ["DetectorConfig", "fit_rectangle", "detect_frame", "detect_sequence"]


@dataclass(frozen=True)
class DetectorConfig:
    """Parameters of the model-free detector (metres, radians)."""

    max_range: float = 60.0
    min_height: float = 0.25            # above the local ground (drops curbs, road markings' noise)
    max_height: float = 3.5
    cell: float = 0.35                  # BEV clustering cell
    min_points: int = 8
    heading_steps: int = 90             # over [0, 90) degrees
    min_length: float = 3.9             # partial views are completed to at least this length / width
    min_width: float = 1.6
    max_length: float = 10.0            # a cluster whose visible extent exceeds this is not a vehicle
    max_width: float = 3.2
    min_box_height: float = 1.0
    max_box_height: float = 4.0
    min_visible_length: float = 1.0     # poles, trunks, bushes: shorter than any visible vehicle side
    typical_size: tuple[float, float, float] = (4.6, 1.9, 1.7)
    edge_distance: float = 0.2
    support_points: float = 30.0
    ground_segment: float = 10.0


def fit_rectangle(xy: np.ndarray, heading_steps: int = 90) -> tuple[float, np.ndarray, np.ndarray]:
    """L-shape fit of (N, 2) points: (heading, min corner, max corner) of the best rectangle, the corners
    in the rotated frame (u along ``heading``, v across). Closeness criterion, vectorised over headings."""
    angles = np.arange(heading_steps) * (0.5 * np.pi / heading_steps)
    c, s = np.cos(angles), np.sin(angles)
    u = np.outer(c, xy[:, 0]) + np.outer(s, xy[:, 1])        # (H, N)
    v = np.outer(-s, xy[:, 0]) + np.outer(c, xy[:, 1])
    du = np.minimum(u.max(axis=1, keepdims=True) - u, u - u.min(axis=1, keepdims=True))
    dv = np.minimum(v.max(axis=1, keepdims=True) - v, v - v.min(axis=1, keepdims=True))
    d = np.maximum(np.minimum(du, dv), 0.01)
    score = (1.0 / d).sum(axis=1)
    best = int(np.argmax(score))
    lo = np.array([u[best].min(), v[best].min()])
    hi = np.array([u[best].max(), v[best].max()])
    return float(angles[best]), lo, hi


def _complete(lo: float, hi: float, minimum: float, sensor: float) -> tuple[float, float]:
    """Grow [lo, hi] to ``minimum`` away from ``sensor`` (the coordinate of the sensor on this axis)."""
    if hi - lo >= minimum:
        return lo, hi
    if abs(sensor - lo) < abs(sensor - hi):   # the near face is lo: grow towards +
        return lo, lo + minimum
    return hi - minimum, hi


def _box_from_cluster(points: np.ndarray, ground_z: float, sensor_xy: np.ndarray | tuple[float, float],
                      config: DetectorConfig) -> tuple[np.ndarray, float] | None:
    """(7,) box and its score for one cluster, or None when a gate rejects it."""
    span = points[:, :2].max(axis=0) - points[:, :2].min(axis=0)
    if np.hypot(*span) > np.hypot(config.max_length, config.max_width):   # larger than any vehicle in any heading
        return None
    step = max(1, len(points) // 400)   # the heading search on at most ~400 points, the extent on all
    heading, _, _ = fit_rectangle(points[::step, :2], config.heading_steps)
    c, s = np.cos(heading), np.sin(heading)
    uv = points[:, :2] @ np.array([[c, -s], [s, c]])
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    extent = hi - lo
    if extent[1] > extent[0]:                     # the length is the longer side
        heading += 0.5 * np.pi
        lo, hi = np.array([lo[1], -hi[0]]), np.array([hi[1], -lo[0]])
        extent = hi - lo
    if extent[0] > config.max_length or extent[1] > config.max_width or extent[0] < config.min_visible_length:
        return None
    top = float(points[:, 2].max())
    height = top - ground_z
    if not config.min_box_height <= height <= config.max_box_height:
        return None
    c, s = np.cos(heading), np.sin(heading)
    su, sv = c * sensor_xy[0] + s * sensor_xy[1], -s * sensor_xy[0] + c * sensor_xy[1]
    u0, u1 = _complete(lo[0], hi[0], config.min_length, su)
    v0, v1 = _complete(lo[1], hi[1], config.min_width, sv)
    cu, cv = 0.5 * (u0 + u1), 0.5 * (v0 + v1)
    centre = np.array([c * cu - s * cv, s * cu + c * cv])
    box = np.array([centre[0], centre[1], ground_z + 0.5 * height, wrap_angle(heading), u1 - u0, v1 - v0, height])
    # fit quality: share of points near the two visible edges (the faces nearest the sensor)
    pu = c * points[:, 0] + s * points[:, 1]
    pv = -s * points[:, 0] + c * points[:, 1]
    near_u = u0 if abs(su - u0) < abs(su - u1) else u1
    near_v = v0 if abs(sv - v0) < abs(sv - v1) else v1
    on_edge = (np.abs(pu - near_u) <= config.edge_distance) | (np.abs(pv - near_v) <= config.edge_distance)
    quality = float(on_edge.mean())
    support = 1.0 - np.exp(-len(points) / config.support_points)
    typical_l, typical_w, typical_h = config.typical_size
    plausible = float(np.exp(-0.5 * (((u1 - u0) - typical_l) / 2.0) ** 2 - 0.5 * (((v1 - v0) - typical_w) / 0.5) ** 2
                             - 0.5 * ((height - typical_h) / 0.8) ** 2))
    return box, float(np.clip(quality * support * (0.5 + 0.5 * plausible), 0.0, 1.0))


def detect_frame(points_ego: np.ndarray, world_from_ego: np.ndarray, config: DetectorConfig = DetectorConfig(),
                 sensor_xy: np.ndarray | tuple[float, float] = (0.0, 0.0)) -> FrameDetections:
    """Vehicle boxes (WORLD frame) in one sweep given in the ego frame (``sensor_xy``: the LiDAR in it)."""
    pts = np.asarray(points_ego, dtype=np.float64).reshape(-1, 3)
    pts = pts[np.isfinite(pts).all(axis=1)]
    pts = pts[np.hypot(pts[:, 0], pts[:, 1]) <= config.max_range]
    if len(pts) < config.min_points:
        return FrameDetections.empty()
    is_ground = ground_mask(pts, GroundParams(segment_length=config.ground_segment))
    ground, objects = pts[is_ground], pts[~is_ground]
    if len(ground) < 3 or len(objects) < config.min_points:
        return FrameDetections.empty()
    # local ground height: median ground z per coarse cell, nearest cell for cells without ground
    coarse = 4.0
    gkey = np.floor(ground[:, :2] / coarse).astype(np.int64)
    ukeys, inverse = np.unique(gkey, axis=0, return_inverse=True)
    order = np.argsort(inverse, kind="stable")
    splits = np.cumsum(np.bincount(inverse.ravel()))[:-1]
    heights = np.array([np.median(z) for z in np.split(ground[order, 2], splits)])
    _, nearest = cKDTree((ukeys + 0.5) * coarse).query(objects[:, :2])
    ground_z = heights[nearest]
    above = objects[:, 2] - ground_z
    keep = (above >= config.min_height) & (above <= config.max_height)
    objects, ground_z = objects[keep], ground_z[keep]
    if len(objects) < config.min_points:
        return FrameDetections.empty()
    # BEV connected components
    key = np.floor(objects[:, :2] / config.cell).astype(np.int64)
    low = key.min(axis=0)
    key -= low
    grid = np.zeros(key.max(axis=0) + 1, dtype=bool)
    grid[key[:, 0], key[:, 1]] = True
    labels, _ = ndimage.label(grid, structure=np.ones((3, 3), dtype=bool))
    point_label = labels[key[:, 0], key[:, 1]]
    order = np.argsort(point_label, kind="stable")
    counts = np.bincount(point_label)
    boxes, scores = [], []
    start = 0
    for lab, n in enumerate(counts):
        idx = order[start:start + n]
        start += n
        if lab == 0 or n < config.min_points:
            continue
        fitted = _box_from_cluster(objects[idx], float(np.median(ground_z[idx])), sensor_xy, config)
        if fitted is not None:
            boxes.append(fitted[0])
            scores.append(fitted[1])
    if not boxes:
        return FrameDetections.empty()
    boxes_ego = np.array(boxes)
    world = boxes_ego.copy()
    world[:, :3] = transform_points(world_from_ego, boxes_ego[:, :3])
    world[:, 3] = wrap_angle(boxes_ego[:, 3] + np.arctan2(world_from_ego[1, 0], world_from_ego[0, 0]))
    return FrameDetections(world, np.array(scores), ("car",) * len(boxes))


def detect_sequence(sequence, config: DetectorConfig = DetectorConfig(), frames=None, progress=None
                    ) -> dict[int, FrameDetections]:
    """Detections of every frame (or ``frames``) of a :class:`~sot_apps.io.Sequence`."""
    frames = range(len(sequence)) if frames is None else frames
    out = {}
    for k in (progress(frames) if progress else frames):
        out[k] = detect_frame(sequence.sweep(k).xyz, np.asarray(sequence.frames[k].world_from_ego), config,
                              np.asarray(sequence.ego_from_lidar)[:2, 3])
    return out
