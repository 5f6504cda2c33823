"""Ground removal: Ground Plane Fitting (GPF, Zermas et al. 2017) with per-segment planes.

The scene is split into square cells along its principal direction (segments along a road, a grid for a
large scene); a plane is fitted to the whole region, then each cell gets its own plane, so slopes and large scenes work. Within a cell:

1. sub-ground noise is rejected first: real sweeps hold returns metres below the road (multipath), which
   would drag the lowest-point representative (LPR) down. Points deeper than ``outlier_depth`` below
   the median of the lowest few percent of the region (in a cell: below the region's plane) are ignored
   while fitting and always classified as ground;
2. LPR = mean z of the ``lpr_count`` lowest remaining points; seeds = points below LPR + ``seed_threshold``;
3. ``iterations`` times: fit a plane to the current ground set (least squares via the covariance's smallest
   eigenvector), then ground = points whose signed height above the plane is below ``distance_threshold``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["GroundParams", "ground_mask", "remove_ground", "fit_plane"]


@dataclass(frozen=True)
class GroundParams:
    lpr_count: int = 20
    seed_threshold: float = 1.2
    distance_threshold: float = 0.3
    iterations: int = 10
    segment_length: float = 8.0
    outlier_depth: float = 0.5
    min_cell_points: int = 30
    max_fit_points: int = 2000  # planes are fitted on at most this many points (an even subsample)
    max_slope_deg: float = 15.0


def fit_plane(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares plane of (N, 3) points: unit normal (pointing up) and offset d with n.p + d = 0."""
    centroid = points.mean(axis=0)
    centred = points - centroid
    cov = centred.T @ centred / max(len(points), 1)
    _, vectors = np.linalg.eigh(cov)
    normal = vectors[:, 0]
    if normal[2] < 0:
        normal = -normal
    return normal, -float(normal @ centroid)


def _robust_floor(z: np.ndarray, params: GroundParams) -> np.ndarray:
    """Mask of points that are not sub-ground outliers: not deeper than ``outlier_depth`` below the median
    of the lowest 5 % (at least ``lpr_count``) of the points."""
    n = len(z)
    n_low = min(n, max(params.lpr_count, int(0.05 * n)))
    lowest = np.partition(z, n_low - 1)[:n_low]
    return z >= float(np.median(lowest)) - params.outlier_depth


def _gpf(points: np.ndarray, params: GroundParams,
         reference: tuple[np.ndarray, float] | None = None) -> tuple[np.ndarray, tuple[np.ndarray, float] | None]:
    """GPF on one region. Heights are z, or heights above ``reference`` (a coarser plane) when given.

    Returns the ground mask (sub-ground outliers included) and the fitted plane (None if no plane fitted).
    """
    if reference is None:
        z = points[:, 2]
        valid = _robust_floor(z, params)
    else:
        z = points @ reference[0] + reference[1]
        valid = z >= -params.outlier_depth
    zv = z[valid]
    if len(zv) < 3:
        return ~valid, None
    k = min(len(zv), params.lpr_count)
    lpr = float(np.partition(zv, k - 1)[:k].mean())
    ground = valid & (z < lpr + params.seed_threshold)
    min_nz = np.cos(np.radians(params.max_slope_deg))
    plane: tuple[np.ndarray, float] | None = None
    step = max(1, int(np.ceil(len(points) / params.max_fit_points)))
    fit_points, fit_valid, ground = points[::step], valid[::step], ground[::step]
    for _ in range(params.iterations):
        if ground.sum() < 3:
            break
        normal, d = fit_plane(fit_points[ground])
        if normal[2] < min_nz or (reference is not None and normal @ reference[0] < min_nz):
            break  # a wall or a vehicle's side, not the road: keep the previous plane
        plane = (normal, d)
        new_ground = fit_valid & (fit_points @ normal + d < params.distance_threshold)
        if np.array_equal(new_ground, ground):
            break
        ground = new_ground
    if plane is None:
        if reference is None:
            plane = (np.array([0.0, 0.0, 1.0]), -lpr)
        else:
            return ~valid | (z < params.distance_threshold), None
    return ~valid | (points @ plane[0] + plane[1] < params.distance_threshold), plane


def _cells(xy: np.ndarray, segment_length: float) -> np.ndarray:
    """Cell id of each point on a grid aligned with the principal direction of ``xy``."""
    centred = xy - xy.mean(axis=0)
    cov = centred.T @ centred
    _, vectors = np.linalg.eigh(cov)
    uv = centred @ vectors[:, ::-1]  # principal axis first
    extent = uv.max(axis=0) - uv.min(axis=0)
    counts = np.maximum(1, np.round(extent / segment_length)).astype(np.int64)
    size = extent / counts
    idx = np.floor((uv - uv.min(axis=0)) / np.maximum(size, 1e-9)).astype(np.int64)
    idx = np.minimum(idx, counts - 1)
    return idx[:, 0] * counts[1] + idx[:, 1]


def ground_mask(points: np.ndarray, params: GroundParams | None = None) -> np.ndarray:
    """Boolean mask of ground points (True = ground, including sub-ground noise) of (N, 3) world points.

    A plane is fitted to the whole region first (robust: most of a region is road); each cell of the
    grid then fits its own plane with heights measured from that one, and falls back to it when its own
    fit is not a road (too steep against it) or has too few points.
    """
    params = params or GroundParams()
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) < 3:
        return np.zeros(len(points), dtype=bool)
    mask, plane = _gpf(points, params)
    cells = _cells(points[:, :2], params.segment_length)
    if plane is None or cells.max() == 0:
        return mask
    order = np.argsort(cells, kind="stable")
    sorted_cells = cells[order]
    starts = np.flatnonzero(np.r_[True, sorted_cells[1:] != sorted_cells[:-1]])
    ends = np.r_[starts[1:], len(order)]
    for s, e in zip(starts, ends):
        if e - s >= params.min_cell_points:
            members = order[s:e]
            cell_mask, cell_plane = _gpf(points[members], params, reference=plane)
            if cell_plane is not None:
                mask[members] = cell_mask
    return mask


def remove_ground(points: np.ndarray, params: GroundParams | None = None) -> np.ndarray:
    """The (M, 3) points of ``points`` that are not ground."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return points[~ground_mask(points, params)]
