"""Ground removal on a whole sweep with ONE plane, as the authors' preprocessing does it.

The authors' implementation (LiDAR_SOT, ``ground_removal.get_ground``) removes the ground once per sweep,
before tracking, in the sensor frame: GPF (Zermas et al. 2017) with a single plane for the whole sweep —
LPR = mean height of the ``lpr_count`` lowest points, seeds below LPR + ``seed_threshold``, then
``iterations`` rounds of plane fit + "ground = signed height above the plane below ``distance_threshold``".
The reference boxes in ``../shared/data/upstream_lidar_sot`` were made with one change, kept here: the LPR
ignores the lowest ``ignore_lowest`` share of the heights (PandaSet sweeps hold sub-ground multipath returns
metres below the road). The plane's normal points up (upstream takes the SVD's sign; on the PandaSet sweeps
that is up: 16–20k of ~106k points are removed).

Used by ``full`` and ``faithful`` (``ground.remover="sweep"``): by their online steps, their fixed-lag window
and their offline refinement; ``ground.remover="local"`` fits planes on the tracker's local region
(:mod:`tracker.ground`).
"""

from __future__ import annotations

import math
import weakref
from functools import partial

import numpy as np

__all__ = ["sweep_ground_mask", "cached_sweep_ground_mask", "remember_sweep_ground_mask"]

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
    of one matrix-vector product over the sweep per round (test_faithful checks the two agree). That product
    runs in single precision; the few points whose single-precision height is within its error bound of the
    threshold are decided in double precision, so every point is classified as in double precision.
    """
    given = np.asarray(points).reshape(-1, 3)
    all_finite = bool(np.isfinite(given).all())
    finite = None if all_finite else np.isfinite(given).all(axis=1)
    valid = given if all_finite else given[finite]
    if len(valid) < 3:
        return np.ones(len(given), dtype=bool)
    z = valid[:, 2]  # exact in float64: the same heights
    skip = int(ignore_lowest * len(z))
    count = max(1, min(lpr_count, len(z) - skip))
    lowest = np.sort(np.partition(z, skip + count - 1)[:skip + count])[skip:].astype(np.float64)
    ground = z < np.float64(lowest.mean() + seed_threshold)  # compared in float64
    seeds = valid[ground].astype(np.float64)
    if iterations > 0 and len(seeds) >= 3:
        origin = seeds.mean(axis=0)
        centred = seeds - origin
        first, second, n_ground = centred.sum(axis=0), centred.T @ centred, len(seeds)
        heights = _SinglePrecisionHeights(valid)
        for _ in range(iterations):
            if n_ground < 3:
                break
            mean = first / n_ground
            normal = _upward_smallest_eigenvector(second / n_ground - np.outer(mean, mean))
            below = heights.below(normal, distance_threshold + float(normal @ (mean + origin)))
            changed = np.flatnonzero(below != ground)
            if changed.size == 0:
                break
            sign = np.where(below[changed], 1.0, -1.0)
            moved = valid[changed].astype(np.float64) - origin
            first = first + sign @ moved
            second = second + (moved * sign[:, None]).T @ moved
            n_ground += int(sign.sum())
            ground = below
    if all_finite:
        return ground
    mask = np.ones(len(given), dtype=bool)
    mask[finite] = ground
    return mask


class _SinglePrecisionHeights:
    """``points @ normal < threshold`` for many planes over the same finite (N, 3) points, decided as in double
    precision: the heights are computed in single precision, and the points whose single-precision height
    lies within a bound of its error from the threshold (rarely any) are computed again in double precision."""

    def __init__(self, points: np.ndarray) -> None:
        self.points = points
        self.single = points if points.dtype == np.float32 else points.astype(np.float32)
        self.heights = np.empty(len(points), dtype=np.float32)
        # the rounding of p (when given in double), of the unit normal and of the three-term product is each a
        # few units of 2^-24 of |p|_1 <= 3 max|p_i|: 1e-6 of 3 max|p_i| is ample
        flat = self.single.reshape(-1)
        self.tolerance = 3e-6 * (max(float(flat.max()), -float(flat.min())) + 1.0)

    def below(self, normal: np.ndarray, threshold: float) -> np.ndarray:
        np.matmul(self.single, normal.astype(np.float32), out=self.heights)
        margin = self.tolerance + 1e-6 * abs(threshold)
        surely = self.heights < np.float32(threshold - margin)
        maybe = self.heights < np.float32(threshold + margin)
        if np.count_nonzero(maybe) != np.count_nonzero(surely):
            near = np.flatnonzero(maybe != surely)
            surely[near] = self.points[near].astype(np.float64) @ normal < threshold
        return surely


def _upward_smallest_eigenvector(a: np.ndarray) -> np.ndarray:
    """The unit eigenvector of the smallest eigenvalue of the symmetric 3x3 ``a``, with z >= 0 (a plane's
    upward normal). Closed form on Python floats (``numpy.linalg.eigh`` costs ~60 us a call, ten calls a
    sweep): the eigenvalue from the characteristic cubic's trigonometric solution, the vector as the longest
    cross product of two rows of a - lambda I; ``eigh`` where that is ill-conditioned (repeated eigenvalues)."""
    xx, yy, zz = float(a[0, 0]), float(a[1, 1]), float(a[2, 2])
    xy, xz, yz = float(a[0, 1]), float(a[0, 2]), float(a[1, 2])
    q = (xx + yy + zz) / 3.0
    p = math.sqrt(((xx - q) ** 2 + (yy - q) ** 2 + (zz - q) ** 2 + 2.0 * (xy * xy + xz * xz + yz * yz)) / 6.0)
    vector = None
    if p > 0.0 and math.isfinite(p):
        bx, by, bz, cxy, cxz, cyz = (xx - q) / p, (yy - q) / p, (zz - q) / p, xy / p, xz / p, yz / p
        det = bx * (by * bz - cyz * cyz) - cxy * (cxy * bz - cyz * cxz) + cxz * (cxy * cyz - by * cxz)
        phi = math.acos(min(1.0, max(-1.0, det / 2.0))) / 3.0
        lam = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
        r0, r1, r2 = (xx - lam, xy, xz), (xy, yy - lam, yz), (xz, yz, zz - lam)
        best, length = None, 0.0
        for u, v in ((r0, r1), (r0, r2), (r1, r2)):
            c = (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])
            n = math.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2])
            if n > length:
                best, length = c, n
        if best is not None and length > 1e-6 * p * p:
            vector = np.array(best) / length
    if vector is None:
        vector = np.linalg.eigh(a)[1][:, 0]
    return vector if vector[2] >= 0 else -vector


def _forget(key: int, _ref: object) -> None:
    _CACHE.pop(key, None)


def cached_sweep_ground_mask(points: np.ndarray, lpr_count: int, seed_threshold: float, distance_threshold: float,
                             iterations: int) -> np.ndarray:
    """:func:`sweep_ground_mask` of ``points`` remembered while the array lives (several trackers on the
    same sweep — an evaluation, a multi-object run — compute it once). Treat the array as read-only."""
    params = (lpr_count, seed_threshold, distance_threshold, iterations)
    key = id(points)
    entry = _CACHE.get(key)
    if entry is not None and entry[0]() is points and entry[1] == params:
        return entry[2]
    return remember_sweep_ground_mask(points, sweep_ground_mask(points, *params), *params)


def remember_sweep_ground_mask(points: np.ndarray, mask: np.ndarray, *params: float) -> np.ndarray:
    """Make ``mask`` — :func:`sweep_ground_mask` ``(points, *params)`` computed before, e.g. stored with the sweep —
    what :func:`cached_sweep_ground_mask` returns for ``points`` while the array lives; returns ``mask``."""
    key = id(points)
    try:
        ref = weakref.ref(points, partial(_forget, key))
    except TypeError:  # not weak-referenceable (a view of a foreign buffer): no caching
        return mask
    _CACHE[key] = (ref, params, mask)
    return mask
