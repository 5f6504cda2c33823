"""Ground removal on a whole sweep with ONE plane, as the authors' preprocessing does it.

The authors' implementation (LiDAR_SOT, ``ground_removal.get_ground``) removes the ground once per sweep,
before tracking, in the sensor frame: GPF (Zermas et al. 2017) with a single plane for the whole sweep —
LPR = mean height of the ``lpr_count`` lowest points, seeds below LPR + ``seed_threshold``, then
``iterations`` rounds of plane fit + "ground = signed height above the plane below ``distance_threshold``".
The reference boxes in ``../shared/data/upstream_lidar_sot`` were made with one change, kept here: the LPR
ignores the lowest ``ignore_lowest`` share of the heights (PandaSet sweeps hold sub-ground multipath returns
metres below the road). The plane's normal points up (upstream takes the SVD's sign; on the PandaSet sweeps
that is up: 16–20k of ~106k points are removed).

Used by ``full``, ``full_v3`` and ``faithful`` (``TrackerConfig.ground_scope="sweep"``): by their online
steps, their fixed-lag window and their offline refinement; ``full_v1`` and ``full_v2`` fit planes on the
tracker's local region (:mod:`tracker.ground`).
"""

from __future__ import annotations

import weakref

import numpy as np

__all__ = ["sweep_ground_mask", "cached_sweep_ground_mask"]

# id(points) -> (weak reference to points, parameters, mask); an entry dies with its array
_CACHE: dict[int, tuple[weakref.ref, tuple, np.ndarray]] = {}


def sweep_ground_mask(points: np.ndarray, lpr_count: int = 20, seed_threshold: float = 1.2,
                      distance_threshold: float = 0.3, iterations: int = 10,
                      ignore_lowest: float = 0.001) -> np.ndarray:
    """Boolean ground mask of the (N, 3) sweep ``points`` (sensor frame, z up); non-finite points are ground.

    Each round fits the least-squares plane of the current ground points and takes every point below
    ``distance_threshold`` above it as the next ground. The plane's moments (sum and scatter about the
    seeds' centroid) are updated with only the points that changed side, and the rounds stop early once
    no point changes (later rounds would repeat the same plane): the mask is the plain refit's, at the cost
    of one matrix-vector product over the sweep per round (test_faithful checks the two agree).
    """
    given = np.asarray(points).reshape(-1, 3)  # tests on the sweep as given (float32: half the memory traffic)
    all_finite = bool(np.isfinite(given).all())
    finite = None if all_finite else np.isfinite(given).all(axis=1)
    pts = np.ascontiguousarray(given, dtype=np.float64)
    valid = pts if all_finite else pts[finite]
    if len(valid) < 3:
        return np.ones(len(pts), dtype=bool)
    z = given[:, 2] if all_finite else given[finite, 2]  # exact in float64: the same heights
    skip = int(ignore_lowest * len(z))
    count = max(1, min(lpr_count, len(z) - skip))
    lowest = np.sort(np.partition(z, skip + count - 1)[:skip + count])[skip:].astype(np.float64)
    ground = z < np.float64(lowest.mean() + seed_threshold)  # compared in float64
    seeds = valid[ground]
    if iterations > 0 and len(seeds) >= 3:
        origin = seeds.mean(axis=0)
        centred = seeds - origin
        first, second, n_ground = centred.sum(axis=0), centred.T @ centred, len(seeds)
        heights = np.empty(len(valid))
        for _ in range(iterations):
            if n_ground < 3:
                break
            mean = first / n_ground
            _, vectors = np.linalg.eigh(second / n_ground - np.outer(mean, mean))
            normal = vectors[:, 0] if vectors[2, 0] >= 0 else -vectors[:, 0]
            np.matmul(valid, normal, out=heights)
            below = np.less(heights, distance_threshold + float(normal @ (mean + origin)))
            changed = np.flatnonzero(below != ground)
            if changed.size == 0:
                break
            sign = np.where(below[changed], 1.0, -1.0)
            moved = valid[changed] - origin
            first = first + sign @ moved
            second = second + (moved * sign[:, None]).T @ moved
            n_ground += int(sign.sum())
            ground = below
    if all_finite:
        return ground
    mask = np.ones(len(pts), dtype=bool)
    mask[finite] = ground
    return mask


def cached_sweep_ground_mask(points: np.ndarray, *params: float) -> np.ndarray:
    """:func:`sweep_ground_mask` of ``points`` remembered while the array lives (several trackers on the
    same sweep — an evaluation, a multi-object run — compute it once). Treat the array as read-only."""
    key = id(points)
    entry = _CACHE.get(key)
    if entry is not None and entry[0]() is points and entry[1] == params:
        return entry[2]
    mask = sweep_ground_mask(points, *params)
    try:
        ref = weakref.ref(points, lambda _, k=key: _CACHE.pop(k, None))
    except TypeError:  # not weak-referenceable (a view of a foreign buffer): no caching
        return mask
    _CACHE[key] = (ref, params, mask)
    return mask
