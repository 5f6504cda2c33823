"""A model-free vehicle detector: accumulated sweeps, ground removal, range-adaptive BEV clustering, L-shape
boxes completed with vehicle size priors, and a score calibrated on exact ground truth.

No learned network. Per frame k (ego frame of k, boxes moved to the world at the end):

1. the sweeps k, k-1, ..., k-``sweeps``+1 in the ego frame of k (:mod:`.accumulate`), within ``max_range``;
2. ground removal on the current sweep (GPF per cell, :func:`tracker.ground_mask`); points of every sweep
   between ``min_height`` and ``max_height`` above the local ground (median ground height per ``ground_cell``);
3. sweep-to-sweep differences: a current point with no point of the oldest sweep near it is MOVING; an
   earlier point is kept only where the current sweep has a point near it (static surfaces densified,
   moving objects not smeared);
4. clustering in bird's-eye view with a range-adaptive link radius (:mod:`.clustering`); a cluster larger
   than any vehicle is split again with a smaller radius (``split_factors``: parked cars in a row), and so is
   one typed truck or bus, whose parts replace it when they give >= 2 boxes;
5. per cluster a rectangle: heading from the L-shape fit (:mod:`.lshape`, Zhang et al. 2017, variance
   criterion: straight sides whatever their length, suited to partial views) on the visible
   contour (:func:`visible_contour`); the longer
   side is the length, except for a short single face (<= ``max_face_width``): then the length runs along the
   axis nearer the line of sight (the rear or front of a vehicle seen end-on); a MOVING cluster's heading
   is the L-shape axis nearer its direction of travel when that travel is measurable (see ``_motion``);
6. the nearest vehicle type (``VEHICLE_TYPES``: car, van, truck, bus; nuScenes' mean sizes) completes a
   partially seen side to the type's size, away from the sensor (the visible face is the near one);
7. gates (the visible extent fits in a vehicle, is long enough not to be a pole, its height is a
   vehicle's); the score is a logistic model of the cluster's features (:func:`cluster_features`: support,
   range, fit to the size priors, share of the type seen, L-shape quality, motion, and clutter cues: how
   high the cluster floats, how ragged its outline is, how much of its rectangle it fills) whose weights
   were fitted on synthetic worlds with roadside clutter and rows of parked cars and on the generated
   benchmark, exact boxes (``python -m sot_apps.detection.calibrate``): the probability that the box
   overlaps a vehicle at BEV IoU >= 0.5.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from tracker import FrameDetections, GroundParams, ground_mask, transform_points, wrap_angle

from .accumulate import near_mask, to_current_ego
from .clustering import cluster_bev
from .lshape import fit_rectangle

__all__ = ["VEHICLE_TYPES", "FEATURES", "DetectorConfig", "Candidate", "fit_rectangle", "visible_contour", "cluster_features",
           "frame_candidates", "detect_frame", "detect_sequence"]

# (name, length, width, height): nuScenes' mean annotated sizes of car, (construction-free) truck, bus; the
# van is between car and truck (SUVs, vans)
VEHICLE_TYPES: tuple[tuple[str, float, float, float], ...] = (
    ("car", 4.63, 1.96, 1.74), ("van", 5.3, 2.1, 2.1), ("truck", 6.9, 2.5, 2.8), ("bus", 11.0, 2.9, 3.5))

FEATURES = ("log_points", "range", "height_fit", "oversize", "length_seen", "width_seen", "edge_share",
            "moving_share", "bottom", "roughness", "fill")


@dataclass(frozen=True)
class DetectorConfig:
    """Parameters of the model-free detector (metres, radians)."""

    max_range: float = 60.0
    sweeps: int = 3                     # the current sweep and the 2 before it
    past_distance: float = 0.15         # an earlier point is kept within this of a current point (BEV)
    moving_distance: float = 0.3        # a current point farther than this from the oldest sweep is moving
    min_height: float = 0.25            # above the local ground (drops curbs, road markings' noise)
    max_height: float = 2.5             # above it: tree canopies, awnings (they join vehicles to trees)
    ground_segment: float = 10.0
    ground_cell: float = 4.0            # local ground height: median per cell of this size
    link_base: float = 0.3              # clustering link radius: base + slope * range, at most link_max
    link_slope: float = 0.008
    link_max: float = 0.6
    split_factors: tuple[float, ...] = (0.6, 0.4)
    resplit_keep: tuple[str, ...] = ("car", "van")   # other types are split again when that gives >= 2 boxes
    min_points: int = 8
    heading_steps: int = 90             # over [0, 90) degrees
    lshape_criterion: str = "variance"   # or "closeness" (.lshape.CRITERIA)
    contour_arc: float = 0.1            # the L-shape is fitted to the nearest point per azimuth bin this wide
    max_length: float = 12.0            # a cluster whose visible extent exceeds this is not a vehicle
    max_width: float = 3.2
    max_face_width: float = 2.4         # a single face no longer than this may be a vehicle's rear or front
    end_on: bool = True                 # such a face: the length runs along the line of sight
    min_box_height: float = 0.9
    max_box_height: float = 4.0
    min_visible_length: float = 1.0     # poles, trunks: shorter than any visible vehicle side
    seen_share: float = 0.85            # a side seen over >= this share of its type's size is taken as seen
    edge_distance: float = 0.2
    min_travel: float = 0.6             # a moving cluster's heading follows its travel when it moved this far
    min_score: float = 0.05             # candidates scored lower are not reported
    # logistic score: bias, then one weight per FEATURES entry (python -m sot_apps.detection.calibrate)
    score_weights: tuple[float, ...] = (-1.995, -0.312, 0.039, -0.126, -1.652, 4.952, 5.573, -0.670, 1.862, -1.798,
                                        -1.267, -1.324)


@dataclass(frozen=True)
class Candidate:
    """One fitted cluster: its box (7,) in the EGO frame, the (len(FEATURES),) features, its type."""

    box: np.ndarray
    features: np.ndarray
    vehicle_type: str


def _complete(lo: float, hi: float, size: float, sensor: float) -> tuple[float, float]:
    """[lo, hi] grown to ``size`` away from ``sensor`` (the sensor's coordinate on this axis)."""
    if hi - lo >= size:
        return lo, hi
    if abs(sensor - lo) < abs(sensor - hi):   # the near face is lo: grow towards +
        return lo, lo + size
    return hi - size, hi


def _vehicle_type(visible: np.ndarray, height: float) -> tuple[str, float, float, float]:
    """The type whose size fits the visible (length, width) and height best (larger than seen is free)."""
    def misfit(t):
        _, length, width, h = t
        return ((max(visible[0] - length, 0.0) / 0.5) ** 2 + (max(visible[1] - width, 0.0) / 0.3) ** 2
                + ((height - h) / (0.2 * h)) ** 2)
    return min(VEHICLE_TYPES, key=misfit)


def cluster_features(n_current: int, range_m: float, visible: np.ndarray, height: float, prior: tuple,
                     edge_share: float, moving_share: float, bottom: float, roughness: float, fill: float
                     ) -> np.ndarray:
    """The score's inputs (order of FEATURES). ``bottom``: height above the ground below which a tenth of the
    points lie (m; a tree's canopy floats); ``roughness``: median distance of the visible outline from the
    rectangle's sides (m; foliage is ragged, a car's or a wall's side straight); ``fill``: share of the
    visible rectangle's 0.3 m cells that hold points (a bush is seen all over, a car's side and roof less)."""
    _, length, width, h = prior
    oversize = (max(visible[0] - length, 0.0) / 0.5) ** 2 + (max(visible[1] - width, 0.0) / 0.3) ** 2
    return np.array([np.log1p(n_current), range_m / 40.0, min(((height - h) / (0.2 * h)) ** 2, 9.0),
                     min(oversize, 9.0), min(visible[0] / length, 1.5), min(visible[1] / width, 1.5),
                     edge_share, moving_share, min(bottom, 2.5), min(roughness / 0.1, 5.0), fill])


def _score(features: np.ndarray, weights: tuple[float, ...]) -> np.ndarray:
    w = np.asarray(weights, dtype=np.float64)
    return 1.0 / (1.0 + np.exp(-(w[0] + features @ w[1:])))


def _motion(points_xy: np.ndarray, oldest_xy: np.ndarray, oldest_tree: cKDTree | None, reach: float
            ) -> np.ndarray | None:
    """Travel (2,) of a moving cluster since the oldest sweep: centroid of its current points minus the
    centroid of the oldest sweep's moving-candidate points within ``reach`` of them; None when unknown."""
    if oldest_tree is None or len(points_xy) == 0:
        return None
    centre = points_xy.mean(axis=0)
    near = oldest_tree.query_ball_point(centre, reach + float(np.max(np.hypot(*(points_xy - centre).T))))
    if len(near) < 5:
        return None
    return centre - oldest_xy[near].mean(axis=0)


def visible_contour(xy: np.ndarray, sensor_xy: np.ndarray, arc: float) -> np.ndarray:
    """The cluster's outline as the sensor sees it: per azimuth bin (``arc`` metres wide at the cluster's
    range) the point nearest the sensor. The L-shape criterion is meant for such a scan line; a near
    vehicle seen from above also returns from its roof and bonnet, which would pull the fit off its sides."""
    d = xy - sensor_xy
    rng = np.hypot(d[:, 0], d[:, 1])
    mean = np.arctan2(d[:, 1].mean(), d[:, 0].mean())   # azimuths from the cluster's mean: no +-pi cut
    angle = np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - mean)))
    bins = np.floor((angle - angle.min()) * max(float(np.median(rng)), 1.0) / arc).astype(np.int64)
    order = np.lexsort((rng, bins))           # by bin, nearest first
    first = order[np.r_[True, bins[order][1:] != bins[order][:-1]]]
    return xy[first]


def _fit_cluster(points: np.ndarray, n_current: int, moving_share: float, travel: np.ndarray | None,
                 ground_z: float, sensor_xy: np.ndarray, config: DetectorConfig) -> Candidate | str | None:
    """The cluster's candidate, "split" when it is larger than a vehicle, None when a gate rejects it."""
    xy = points[:, :2]
    span = xy.max(axis=0) - xy.min(axis=0)
    if np.hypot(*span) > np.hypot(config.max_length, config.max_width) + 0.5:
        return "split"
    contour = visible_contour(xy, sensor_xy, config.contour_arc)
    heading, _, _ = fit_rectangle(contour, config.heading_steps, config.lshape_criterion)
    c, s = np.cos(heading), np.sin(heading)
    uv = xy @ np.array([[c, -s], [s, c]])
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    extent = hi - lo
    centre = xy.mean(axis=0)
    sight = centre - sensor_xy
    axis_u = np.array([c, s])
    along_u = bool(extent[0] >= extent[1])      # the longer side is the length, unless:
    if config.end_on and max(extent) <= config.max_face_width:   # a short face: the length along the line of sight
        along_u = abs(axis_u @ sight) >= abs(np.array([-s, c]) @ sight)
    moved = travel is not None and moving_share >= 0.3 and np.hypot(*travel) >= config.min_travel
    if moved:   # the travel must run along one of the rectangle's axes (within ~35 degrees) to count
        cosine = abs(axis_u @ travel) / np.hypot(*travel)
        moved = max(cosine, np.sqrt(max(0.0, 1.0 - cosine ** 2))) >= 0.82
    if moved and max(extent) < 1.5 * max(min(extent), 1e-3):   # no clear longer side: the travel decides
        along_u = abs(axis_u @ travel) >= abs(np.array([-s, c]) @ travel)
    if not along_u:                             # turn the frame by 90 degrees: u <- v, v <- -u
        heading += 0.5 * np.pi
        lo, hi = np.array([lo[1], -hi[0]]), np.array([hi[1], -lo[0]])
        extent = hi - lo
    if moved:
        if np.array([np.cos(heading), np.sin(heading)]) @ travel < 0:   # face the direction of travel
            heading += np.pi
            lo, hi = -hi, -lo
    if extent[0] > config.max_length or extent[1] > config.max_width:
        return "split"
    if extent[0] < config.min_visible_length:
        return None
    height = float(points[:, 2].max()) - ground_z
    if not config.min_box_height <= height <= config.max_box_height:
        return None
    prior = _vehicle_type(extent, height)
    _, length, width, _ = prior
    c, s = np.cos(heading), np.sin(heading)
    su, sv = c * sensor_xy[0] + s * sensor_xy[1], -s * sensor_xy[0] + c * sensor_xy[1]
    u0, u1 = (lo[0], hi[0]) if extent[0] >= config.seen_share * length else _complete(lo[0], hi[0], length, su)
    v0, v1 = (lo[1], hi[1]) if extent[1] >= config.seen_share * width else _complete(lo[1], hi[1], width, sv)
    cu, cv = 0.5 * (u0 + u1), 0.5 * (v0 + v1)
    box = np.array([c * cu - s * cv, s * cu + c * cv, ground_z + 0.5 * height, wrap_angle(heading),
                    u1 - u0, v1 - v0, height])
    # L-shape quality: share of the points within edge_distance of the two faces nearest the sensor
    pu = c * xy[:, 0] + s * xy[:, 1]
    pv = -s * xy[:, 0] + c * xy[:, 1]
    near_u = u0 if abs(su - u0) < abs(su - u1) else u1
    near_v = v0 if abs(sv - v0) < abs(sv - v1) else v1
    on_edge = (np.abs(pu - near_u) <= config.edge_distance) | (np.abs(pv - near_v) <= config.edge_distance)
    # clutter: the outline's distance from the rectangle of the visible points, how much of it holds points
    cu_, cv_ = contour @ np.array([c, s]), contour @ np.array([-s, c])
    vis_lo = np.array([pu.min(), pv.min()])
    vis_hi = np.array([pu.max(), pv.max()])
    off = np.minimum(np.minimum(cu_ - vis_lo[0], vis_hi[0] - cu_), np.minimum(cv_ - vis_lo[1], vis_hi[1] - cv_))
    cells = np.floor((np.column_stack([pu, pv]) - vis_lo) / 0.3).astype(np.int64)
    n_cells = np.prod(np.floor((vis_hi - vis_lo) / 0.3).astype(np.int64) + 1)
    fill = len(np.unique(cells[:, 0] * (int(cells[:, 1].max()) + 1) + cells[:, 1])) / max(int(n_cells), 1)
    bottom = float(np.percentile(points[:, 2] - ground_z, 10))
    features = cluster_features(n_current, float(np.hypot(*sight)), extent, height, prior, float(on_edge.mean()),
                                moving_share, bottom, float(np.median(np.maximum(off, 0.0))), fill)
    return Candidate(box, features, prior[0])


def _local_ground(ground: np.ndarray, query_xy: np.ndarray, cell: float) -> np.ndarray:
    """Ground height under each query point: the median ground height of its cell; a cell without ground
    takes the nearest cell's (a dense grid and a distance transform, no tree)."""
    low = np.minimum(ground[:, :2].min(axis=0), query_xy.min(axis=0))
    key = np.floor((ground[:, :2] - low) / cell).astype(np.int64)
    shape = np.maximum(key.max(axis=0), np.floor((query_xy.max(axis=0) - low) / cell).astype(np.int64)) + 1
    flat = key[:, 0] * shape[1] + key[:, 1]
    order = np.lexsort((ground[:, 2], flat))              # by cell, then height
    cells, starts, counts = np.unique(flat[order], return_index=True, return_counts=True)
    grid = np.full(int(shape[0] * shape[1]), np.nan)
    grid[cells] = ground[order, 2][starts + counts // 2]  # the (upper) median of every cell
    grid = grid.reshape(shape)
    _, (ni, nj) = ndimage.distance_transform_edt(np.isnan(grid), return_indices=True)
    q = np.floor((query_xy - low) / cell).astype(np.int64)
    return grid[ni[q[:, 0], q[:, 1]], nj[q[:, 0], q[:, 1]]]


def _in_band(points: np.ndarray, ground: np.ndarray, config: DetectorConfig) -> tuple[np.ndarray, np.ndarray]:
    """Mask of the points between min_height and max_height above the local ground, and their ground height."""
    ground_z = _local_ground(ground, points[:, :2], config.ground_cell)
    above = points[:, 2] - ground_z
    return (above >= config.min_height) & (above <= config.max_height), ground_z


def frame_candidates(sweeps: list[tuple[np.ndarray, np.ndarray]], config: DetectorConfig = DetectorConfig(),
                     sensor_xy: np.ndarray | None = None) -> list[Candidate]:
    """Every cluster that passes the gates, boxes in the ego frame of ``sweeps[0]``.

    ``sweeps``: (points_ego, world_from_ego) of the current frame first, then the earlier ones, most recent
    first (at most ``config.sweeps`` are used). The ground is removed on the current sweep; earlier points
    are measured against the current sweep's local ground."""
    sensor_xy = np.zeros(2) if sensor_xy is None else np.asarray(sensor_xy, dtype=np.float64)
    sweeps = sweeps[:max(1, config.sweeps)]

    def in_range(points: np.ndarray) -> np.ndarray:
        points = points[np.isfinite(points).all(axis=1)]
        return points[np.hypot(points[:, 0] - sensor_xy[0], points[:, 1] - sensor_xy[1]) <= config.max_range]

    current = in_range(np.asarray(sweeps[0][0], dtype=np.float64).reshape(-1, 3))
    if len(current) < config.min_points:
        return []
    is_ground = ground_mask(current, GroundParams(segment_length=config.ground_segment))
    ground = current[is_ground]
    if len(ground) < 3:
        return []
    current = current[~is_ground]
    band, current_ground = _in_band(current, ground, config)
    current, current_ground = current[band], current_ground[band]
    parts, grounds, ages = [current], [current_ground], [np.zeros(len(current), dtype=np.int64)]
    moving = np.zeros(len(current), dtype=bool)
    oldest_xy = np.zeros((0, 2))
    for age, (points, world_from_ego) in enumerate(sweeps[1:], start=1):
        past = in_range(to_current_ego(points, world_from_ego, sweeps[0][1]))
        band, past_ground = _in_band(past, ground, config)
        past, past_ground = past[band], past_ground[band]
        if age == len(sweeps) - 1:     # the oldest: who moved since, and where moving objects were
            moving = ~near_mask(past[:, :2], current[:, :2], config.moving_distance)
            oldest_xy = past[~near_mask(current[:, :2], past[:, :2], config.moving_distance), :2]
        keep = near_mask(current[:, :2], past[:, :2], config.past_distance)
        parts.append(past[keep])
        grounds.append(past_ground[keep])
        ages.append(np.full(int(keep.sum()), age, dtype=np.int64))
    pts, ground_z, age = np.vstack(parts), np.concatenate(grounds), np.concatenate(ages)
    moving = np.r_[moving, np.zeros(len(pts) - len(current), dtype=bool)]
    oldest_tree = cKDTree(oldest_xy) if len(oldest_xy) >= 5 else None
    if len(pts) < config.min_points:
        return []

    def candidates(members: np.ndarray, factor: float, depth: int) -> list[Candidate]:
        labels = cluster_bev(pts[members, :2], sensor_xy, config.link_base * factor, config.link_slope * factor,
                             config.link_max * factor)
        order = np.argsort(labels, kind="stable")
        counts = np.bincount(labels)
        bounds = np.r_[0, np.cumsum(counts)]
        found: list[Candidate] = []
        for lab in np.flatnonzero(counts >= config.min_points):
            idx = members[order[bounds[lab]:bounds[lab + 1]]]
            current = age[idx] == 0
            n_current = int(current.sum())
            if n_current < config.min_points // 2:
                continue
            moving_share = float(moving[idx][current].mean())
            travel = (_motion(pts[idx][current, :2], oldest_xy, oldest_tree, 2.5)
                      if moving_share >= 0.3 else None)
            fitted = _fit_cluster(pts[idx], n_current, moving_share, travel, float(np.median(ground_z[idx])),
                                  sensor_xy, config)
            finer = depth < len(config.split_factors)
            if isinstance(fitted, Candidate) and finer and fitted.vehicle_type not in config.resplit_keep:
                # larger than a van: two cars close together look like a truck; split if it yields >= 2
                parts = candidates(idx, config.split_factors[depth], depth + 1)
                found += parts if len(parts) >= 2 else [fitted]
            elif isinstance(fitted, Candidate):
                found.append(fitted)
            elif fitted == "split" and finer:
                found += candidates(idx, config.split_factors[depth], depth + 1)
        return found

    return candidates(np.arange(len(pts)), 1.0, 0)


def boxes_to_world(boxes_ego: np.ndarray, world_from_ego: np.ndarray) -> np.ndarray:
    world = boxes_ego.copy()
    world[:, :3] = transform_points(world_from_ego, boxes_ego[:, :3])
    world[:, 3] = wrap_angle(boxes_ego[:, 3] + np.arctan2(world_from_ego[1, 0], world_from_ego[0, 0]))
    return world


def detect_frame(points_ego: np.ndarray, world_from_ego: np.ndarray, config: DetectorConfig = DetectorConfig(),
                 sensor_xy: np.ndarray | None = None,
                 earlier: list[tuple[np.ndarray, np.ndarray]] = ()) -> FrameDetections:
    """Vehicle boxes (WORLD frame) of one sweep given in the ego frame (``sensor_xy``: the LiDAR in it);
    ``earlier``: (points_ego, world_from_ego) of the previous sweeps, most recent first."""
    sweeps = [(np.asarray(points_ego, dtype=np.float64).reshape(-1, 3), np.asarray(world_from_ego))]
    sweeps += [(np.asarray(p, dtype=np.float64).reshape(-1, 3), np.asarray(t)) for p, t in earlier]
    candidates = frame_candidates(sweeps, config, sensor_xy)
    if not candidates:
        return FrameDetections.empty()
    scores = _score(np.array([c.features for c in candidates]), config.score_weights)
    keep = scores >= config.min_score
    if not keep.any():
        return FrameDetections.empty()
    boxes = boxes_to_world(np.array([c.box for c in candidates])[keep], np.asarray(world_from_ego, dtype=np.float64))
    return FrameDetections(boxes, scores[keep], ("car",) * int(keep.sum()))


def sweep_window(sequence, k: int, config: DetectorConfig) -> list[tuple[np.ndarray, np.ndarray]]:
    """(points_ego, world_from_ego) of frame k and the ``config.sweeps`` - 1 frames before it that have a sweep."""
    out = []
    for j in range(k, max(-1, k - config.sweeps), -1):
        if sequence.frames[j].has_sweep or j == k:
            out.append((sequence.sweep(j).xyz, np.asarray(sequence.frames[j].world_from_ego)))
    return out


def detect_sequence(sequence, config: DetectorConfig = DetectorConfig(), frames=None, progress=None
                    ) -> dict[int, FrameDetections]:
    """Detections of every frame (or ``frames``) of a :class:`~sot_apps.io.Sequence`."""
    frames = range(len(sequence)) if frames is None else frames
    sensor_xy = np.asarray(sequence.ego_from_lidar)[:2, 3]
    out = {}
    for k in (progress(frames) if progress else frames):
        window = sweep_window(sequence, k, config)
        out[k] = detect_frame(window[0][0], window[0][1], config, sensor_xy, window[1:])
    return out
