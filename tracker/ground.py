"""Ground removal: Ground Plane Fitting (GPF, Zermas et al. 2017) with per-segment planes.

The scene is split into square cells along its principal direction (segments along a road, a grid for a
large scene) and each cell gets its own plane, so slopes and large scenes work. Within a cell:

1. a robust first plane goes through a low point (10 % quantile in z) of every 2 m BEV bin, refitted
   without the bins far from it (a vehicle's underside, a wall); heights are measured from it;
2. sub-ground noise is rejected: real sweeps hold returns metres below the road (multipath), which would
   drag the lowest-point representative (LPR) down. Points deeper than ``outlier_depth`` below the first
   plane are ignored while fitting and always classified as ground;
3. LPR = mean height of the ``lpr_count`` lowest remaining points; seeds = points below LPR + ``seed_threshold``;
4. ``iterations`` times: fit a plane to the current ground set (least squares via the covariance's smallest
   eigenvector), then ground = points whose signed height above the plane is below ``distance_threshold``.
"""

from __future__ import annotations

import numpy as np

from .ground_params import GroundParams

__all__ = ["GroundParams", "ground_mask", "remove_ground", "fit_plane"]


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


def _low_plane(points: np.ndarray, params: GroundParams) -> tuple[np.ndarray, float] | None:
    """A robust first guess of the road plane: fitted through a low point of each ``bin_size`` BEV bin.

    A bin's low point is its ``low_quantile`` point in z (not its minimum: isolated sub-ground returns
    do not move it); bins whose low point is far from the plane (a vehicle's underside, a cluster of
    multipath returns, a wall) are dropped and the plane is refitted.
    """
    step = max(1, len(points) // (4 * params.max_fit_points))
    points = points[::step]  # quantiles per bin do not need every point
    cell = np.floor(points[:, :2] / params.bin_size).astype(np.int64)
    key = (cell[:, 0] - cell[:, 0].min()) * (int(cell[:, 1].max() - cell[:, 1].min()) + 1) + (cell[:, 1] - cell[:, 1].min())
    order = np.lexsort((points[:, 2], key))
    sorted_key = key[order]
    starts = np.flatnonzero(np.r_[True, sorted_key[1:] != sorted_key[:-1]])
    counts = np.diff(np.r_[starts, len(order)])
    enough = counts >= 3
    if enough.sum() < 3:
        return None
    pick = order[starts[enough] + np.floor(params.low_quantile * (counts[enough] - 1)).astype(np.int64)]
    low = points[pick]
    keep = np.ones(len(low), dtype=bool)
    plane = None
    min_nz = np.cos(np.radians(params.max_slope_deg))
    for it in range(8):
        if keep.sum() < 3:
            break
        normal, d = fit_plane(low[keep])
        if normal[2] < min_nz:  # too steep for a road: a level plane through the kept bins instead
            normal, d = np.array([0.0, 0.0, 1.0]), -float(np.median(low[keep, 2]))
        plane = (normal, d)
        residual = low @ normal + d
        # the road is the lower envelope: drop bins above the plane (vehicles, walls) and, once the plane
        # is near the road, the few bins far below it (clusters of multipath returns)
        new_keep = residual <= params.distance_threshold * 0.5
        if it > 0:
            new_keep &= residual >= -params.outlier_depth
        if new_keep.sum() < 3 or np.array_equal(new_keep, keep):
            break
        keep = new_keep
    return plane


def _gpf(points: np.ndarray, params: GroundParams,
         reference: tuple[np.ndarray, float] | None = None) -> tuple[np.ndarray, tuple[np.ndarray, float] | None]:
    """GPF on one region, with heights measured from ``reference`` (default: the region's low plane).

    Sub-ground outliers (deeper than ``outlier_depth`` below the reference) are ignored while fitting and
    always classified as ground. Returns the ground mask and the fitted plane (None if none fitted).
    """
    reference_from_low = reference is None
    if reference is None:
        reference = _low_plane(points, params)
    reference_from_low = reference_from_low and reference is not None
    if reference is None:  # too few points for bins: plain z with the lowest points as the floor
        z = points[:, 2]
        n_low = min(len(z), max(params.lpr_count, int(0.05 * len(z))))
        valid = z >= float(np.median(np.partition(z, n_low - 1)[:n_low])) - params.outlier_depth
        reference_normal = np.array([0.0, 0.0, 1.0])
    else:
        z = points @ reference[0] + reference[1]
        valid = z >= -params.outlier_depth
        reference_normal = reference[0]
    zv = z[valid]
    if len(zv) < 3:
        return ~valid, None
    k = min(len(zv), params.lpr_count)
    lpr = float(np.partition(zv, k - 1)[:k].mean())
    ground = valid & (z < lpr + params.seed_threshold)
    min_nz = np.cos(np.radians(params.max_slope_deg))
    min_rel = np.cos(np.radians(0.5 * params.max_slope_deg))
    plane: tuple[np.ndarray, float] | None = None
    step = max(1, int(np.ceil(len(points) / params.max_fit_points)))
    fit_points, fit_valid, ground = points[::step], valid[::step], ground[::step]
    for _ in range(params.iterations):
        if ground.sum() < 3:
            break
        normal, d = fit_plane(fit_points[ground])
        if normal[2] < min_nz or normal @ reference_normal < min_rel:
            break  # a wall or a vehicle's side, not the road: keep the previous plane
        plane = (normal, d)
        new_ground = fit_valid & (fit_points @ normal + d < params.distance_threshold)
        if np.array_equal(new_ground, ground):
            break
        ground = new_ground
    if plane is None:  # GPF's seeds gave no road-like plane (a vehicle filled them): use the first plane
        if reference_from_low and params.low_plane_fallback:
            return ~valid | (z < params.distance_threshold), reference
        return ~valid | (z < lpr + params.distance_threshold), None
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

    Each cell of a grid along the scene's principal direction gets its own GPF plane (cells with too few
    points use the plane of the whole region).
    """
    params = params or GroundParams()
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) < 3:
        return np.zeros(len(points), dtype=bool)
    cells = _cells(points[:, :2], params.segment_length)
    if cells.max() == 0:
        return _gpf(points, params)[0]
    mask = np.zeros(len(points), dtype=bool)
    whole: np.ndarray | None = None
    order = np.argsort(cells, kind="stable")
    sorted_cells = cells[order]
    starts = np.flatnonzero(np.r_[True, sorted_cells[1:] != sorted_cells[:-1]])
    ends = np.r_[starts[1:], len(order)]
    for s, e in zip(starts, ends, strict=True):
        members = order[s:e]
        cell_plane = None
        if e - s >= params.min_cell_points:
            cell_mask, cell_plane = _gpf(points[members], params)
        if cell_plane is None:
            if whole is None:
                whole = _gpf(points, params)[0]
            cell_mask = whole[members]
        mask[members] = cell_mask
    return mask


def remove_ground(points: np.ndarray, params: GroundParams | None = None) -> np.ndarray:
    """The (M, 3) points of ``points`` that are not ground."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return points[~ground_mask(points, params)]
