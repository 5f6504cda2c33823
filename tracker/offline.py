"""Offline refinement: after the online pass, re-estimate all states jointly (issue 7 §6).

Data-generation users have the whole sequence, so nothing forces the estimate of frame k to ignore
frames k+1, k+2, .... Given an online :class:`~tracker.sotracker.TrackResult`:

1. every frame's points near its online box (ground removed as the tracker removes it: the cached
   whole-sweep plane with ``ground.remover="sweep"``, else planes fitted on the region with its GPF
   parameters; cropped with the box scaled ``region_scale``) are gathered once (world frame);
2. frames are split into ``folds`` interleaved folds (k mod folds). For each fold a shape is rebuilt from
   the frames NOT in it: points in the current boxes (scale 1.0), moved to the object frame, voxelised
   (5 cm centres; ``dense_voxel`` where the frames hold a median of ``dense_points`` object points or more), with
   normals n from a PCA of each shape point's neighbours. A frame is registered
   only to the shape of the other folds: registering a frame to an aggregate that contains its own
   points pins it where it already is (the residuals are ~0 whatever its error);
3. all states S_0..S_{K-1} minimise, jointly,

       Σ_k c_k Σ_p ρ_Huber(‖A (R(−θ_k)(p − t_k) − m)‖) / σ_p²              (data: frame k's points vs shape)
     + Σ_k Σ_c (S_{k+1,c} − 2 S_{k,c} + S_{k−1,c})² / σ_c²                (smoothness: 2nd differences
                                                                          of x, y, z, heading)
     + Σ_k Σ_c (S_{k,c} − S^online_{k,c})² / σ_anchor,c²                   (weak pull to the online states)
     + Σ_k w_k (θ_k − θ^travel_k)²                                        (heading from travel, ``travel_*``)
     + Σ_k v_k ((z_{k+1} − z_k) − (z̄_{k+1} − z̄_k))²                      (z trend, ``z_trend_*``; off by default)

   with m the nearest shape point of the moved p (pairs farther than ``max_pair_distance`` dropped),
   A = (1 − β) n nᵀ + β I (β = 0: point-to-plane, β = 1: point-to-point; default 0.3), and
   c_k = min(1, ``effective_points`` / N_k), so a dense frame counts as at most that many independent
   points (LiDAR residuals are strongly correlated). It is solved by Gauss–Newton with iteratively
   re-weighted Huber weights on one banded 4K × 4K normal-equation system
   (Cholesky of its band), with a cost check and step halving; correspondences are recomputed at every step.
   θ^travel_k is the direction of the chord from state k − m to state k + m (the refined centres; held through
   a step), w_k = 1/σ_travel² × a speed factor: the smoothness penalises curvature, not a steady drift, so where
   the points pin the heading weakly the travel holds it. z̄ is the online z smoothed over ``z_trend_frames``
   each side (the road under the box, for the tracker's road-based height); v_k = 1/σ_z_trend² (× n0 / (n0 +
   points) with ``z_trend_points``): z changes as the road does, its level is the points';
4. gauge: the joint problem fixes the trajectory only up to where the shape sits in the object frame.
   With ``gauge="regauge"`` (default) all states are free and afterwards every pose is composed with the
   one object-frame correction that maps the refined S_0 onto the given start box (so S_0 is exact and
   all frames keep their relative registration); ``gauge="fix_first"`` holds S_0 fixed instead;
5. steps 2–4 repeat ``outer_iterations`` times; the shape is rebuilt from the final states (all frames);
6. second start (``window_start`` = N > 0; ``full``: 10): where the online pass held the object metres off and
   then re-locked, the solve from the online states keeps the offset stretch (its frames agree with each other,
   so the other fold's shape holds them there: a local minimum), while the fixed-lag window, registering each
   new frame to frames it has already corrected, pulls them toward the object. So the window pass with lag N
   runs on the same points (:func:`~tracker.fixed_lag.window_states`), and when it moved some centre farther than
   ``window_start_moved`` from the online one, steps 2–5 run again from its states (the weak pull still toward
   the online states; with a ``source``, each frame's points also gathered around the window's box). The second
   solution is kept when its boxes hold more than ``window_start_margin`` × the points the first one's hold
   (summed over frames, on the same points; ``full``: 1.0); with backward passes the states are the fused ones,
   which already hold the lost stretch where the window would move it, so the second solve runs whatever the window
   moved; a start from the window alone is no good where the online offset
   is one rigid shift, which the gauge removes but the window, part-corrected, no longer is. Given the points and
   no source, the window pass is skipped when the second solution could never be kept: the first one's boxes hold
   so many points that ``window_start_margin`` x that is at least an upper bound of what any boxes hold
   (:func:`_window_cannot_win`; the result is the same, without the pass's cost). With
   ``window_start_first_moved`` > 0 (``full``: 0.25) the window pass runs only where the online pass lost some
   frame or the first solve moved some centre farther than that from the online one (:func:`_window_not_needed`):
   a track whose first solve agrees with its online states has no offset stretch for the window to correct.
7. gauge from the window (``gauge_window`` = M > 0, with ``window_start``; off by default): the regauge of step 4
   moves every frame by frame 0's own registration error (frame 0 pins the gauge alone; on a sparse start that is
   centimetres, on every frame). The window holds frame 0 at the start box and registers the next frames to it, so
   its first frames average that error out: the kept solution is moved by the mean object-frame correction onto
   the window's states over frames 1..M (frame 0 stays exact; none when its centre part is ``gauge_window_max`` or
   more: the two disagree by more than registration noise) and the shape rebuilt.

The result is a new TrackResult (same frames, sizes and per-frame online ``time_ms``; ``points`` and
``num_points`` recomputed; flag ``"offline"`` added). Deterministic for a given ``config.seed``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solveh_banded
from scipy.spatial import cKDTree

from .bidirectional import fused_result, is_lost
from .config import OfflineParams, TrackerConfig
from .footprint import held_turned
from .frames import FrameSource, LidarFrame
from .geometry import Box, State, points_in_box, transform_points, wrap_angle
from .ground import ground_mask
from .metrics import unique_sorted, voxel_downsample_centres, voxel_downsample_means
from .own_motion import RegionTimes, compensate_track
from .relock_bridge import bridged_result
from .rows import finite3, inside3, norm3, sum3
from .sotracker import FrameEstimate, LocalCrop, TrackResult, deskew_points
from .sweep_ground import cached_sweep_ground_mask
from .voxel_nearest import VoxelNearest

__all__ = ["Anchors", "OfflineParams", "OfflineProblem", "frame_region_points", "frame_region_points_timed",
           "gather_frame_points", "refine_states",
           "refine_offline"]


@dataclass
class OfflineProblem:
    """Per-frame point sets (world) for the refinement, and the state trajectory (K, 4)."""

    points: list[np.ndarray]
    states: np.ndarray
    size: np.ndarray


@dataclass(frozen=True)
class Anchors:
    """Given states at some frames (keyframes) for :func:`refine_states`: ``frames`` (n,) indices into the
    trajectory, ``states`` (n, 4) their x, y, z, heading. ``sigma`` None: held exactly (hard constraints; the
    gauge is theirs, no re-gauging); else (4,) the sigma of a pull toward them (x, y, z, heading). ``pull``: (K, 4)
    every frame's sigma of its pull toward its online state, instead of the params' ``anchor_sigma_*``."""

    frames: np.ndarray
    states: np.ndarray
    sigma: np.ndarray | None = None
    pull: np.ndarray | None = None


def _box(state: np.ndarray, size: np.ndarray) -> Box:
    return Box(float(state[0]), float(state[1]), float(state[2]), float(wrap_angle(state[3])),
               float(size[0]), float(size[1]), float(size[2]))


def _square_candidates(points_ego: np.ndarray, world_from_ego: np.ndarray, centre_xy: np.ndarray,
                       reach: float) -> np.ndarray:
    """Indices of the ego points whose world x, y may lie within ``reach`` of ``centre_xy`` (a superset:
    a single-precision test padded by 1 cm, so the exact test on the survivors decides as on all points)."""
    rotation = np.ascontiguousarray(world_from_ego[:2, :3], dtype=np.float32)
    rel = (np.asarray(centre_xy, dtype=np.float64) - world_from_ego[:2, 3]).astype(np.float32)
    xy = rotation @ np.asarray(points_ego).astype(np.float32, copy=False).T  # (2, N): contiguous rows
    xy -= rel[:, None]
    np.abs(xy, out=xy)
    return np.flatnonzero(np.maximum(xy[0], xy[1]) <= np.float32(reach + 0.01))  # NaN: False


def _deskew_reach(points_ego: np.ndarray, frame: LidarFrame, previous: tuple[int, np.ndarray]) -> float:
    """Upper bound (m) of how far de-skew moves any point of ``frame`` from its plain world position:
    the pose at a point's time differs from the frame's by at most |1 - s| of the frame-to-frame motion
    (translation, and rotation angle times the point's range)."""
    dt = float(frame.timestamp_ns - previous[0])
    if dt == 0:
        return 0.0
    offsets = np.asarray(frame.point_time_offset_ns, dtype=np.float64)
    s_off = float(np.max(np.abs(offsets))) / abs(dt) if len(offsets) else 0.0
    r0, r1 = previous[1][:3, :3], np.asarray(frame.world_from_ego, dtype=np.float64)[:3, :3]
    angle = float(np.arccos(np.clip((np.trace(r0.T @ r1) - 1.0) / 2.0, -1.0, 1.0)))
    shift = float(np.linalg.norm(np.asarray(frame.world_from_ego)[:3, 3] - previous[1][:3, 3]))
    finite = np.asarray(points_ego)[np.all(np.isfinite(points_ego), axis=1)]
    radius = float(np.sqrt(np.max(np.sum(finite.astype(np.float64) ** 2, axis=1)))) if len(finite) else 0.0
    return s_off * (shift + angle * radius) + 0.1


def frame_region_points(frame: LidarFrame, box: Box, config: TrackerConfig, params: OfflineParams,
                        previous: tuple[int, np.ndarray] | None = None,
                        world: np.ndarray | None = None, crop: LocalCrop | None = None) -> np.ndarray:
    """Ground-removed world points of ``frame`` inside ``box`` scaled ``region_scale``: the points of
    :func:`frame_region_points_timed`, without their capture times."""
    return frame_region_points_timed(frame, box, config, params, previous, world, crop, with_times=False)[0]


def frame_region_points_timed(frame: LidarFrame, box: Box, config: TrackerConfig, params: OfflineParams,
                              previous: tuple[int, np.ndarray] | None = None, world: np.ndarray | None = None,
                              crop: LocalCrop | None = None, with_times: bool = True
                              ) -> tuple[np.ndarray, RegionTimes | None]:
    """Ground-removed world points of ``frame`` inside ``box`` scaled ``region_scale``.

    The ground is the tracker's (``params.ground="tracker"``): with ``ground.remover="sweep"`` the whole-sweep
    plane's, cached per sweep so the online step has already paid for it; else (or with ``"local"``) planes
    fitted on the region grown by ``ground_margin``.
    ``previous``: (timestamp_ns, world_from_ego) of the frame before (de-skew only); ``world``: the frame's
    world points (all of the sweep's, in its order) when the caller has them cached; ``crop``: the points the
    online step searched in this frame (:class:`~tracker.sotracker.LocalCrop`), used when the region lies
    inside it and its ground is this one (the same points, in the same order, without another pass over the
    sweep). With ``with_times`` and the sweep's point times, also each point's capture time
    (:class:`~tracker.own_motion.RegionTimes`, from the crop's own when it is used), else None."""
    pts_ego = np.asarray(frame.points_ego)
    removes_ground = config.ground.remover != "none"
    sweep_ground = config.ground.remover == "sweep" and params.ground == "tracker"
    offsets = frame.point_time_offset_ns
    times = (np.asarray(offsets) if with_times and offsets is not None and len(offsets) == len(pts_ego)
             else None)  # the capture times of the points kept so far
    if (crop is not None and crop.frame == frame.index and crop.ground == ("sweep" if sweep_ground else "none")
            and (sweep_ground or not removes_ground) and crop.contains(box, params.region_scale)
            and (times is None or crop.time_offsets_ns is not None)):
        inside = points_in_box(crop.points, box, params.region_scale)
        return crop.points[inside], (None if times is None or crop.time_offsets_ns is None
                                     else RegionTimes(int(frame.timestamp_ns), crop.time_offsets_ns[inside]))
    above_ground = ~cached_sweep_ground_mask(pts_ego, *config.ground.sweep_args()) if sweep_ground else None
    reach = 0.5 * max(box.length, box.width) * params.region_scale + params.ground_margin
    deskew_from = previous if (config.deskew and frame.point_time_offset_ns is not None
                               and len(frame.point_time_offset_ns) == len(pts_ego)) else None
    if world is None:  # only the part of the sweep that can reach the region is moved to the world frame
        world_from_ego = np.asarray(frame.world_from_ego, dtype=np.float64)
        pad = _deskew_reach(pts_ego, frame, deskew_from) if deskew_from is not None else 0.0
        idx = _square_candidates(pts_ego, world_from_ego, box.center[:2], reach + pad)
        if above_ground is not None:
            idx = idx[above_ground[idx]]
        times = None if times is None else times[idx]
        if deskew_from is not None:
            world = deskew_points(pts_ego[idx], np.asarray(frame.point_time_offset_ns)[idx], frame.timestamp_ns,
                                  world_from_ego, deskew_from[0], deskew_from[1])
        else:
            world = transform_points(world_from_ego, pts_ego[idx])
    else:
        if deskew_from is not None:
            world = deskew_points(pts_ego, np.asarray(frame.point_time_offset_ns), frame.timestamp_ns,
                                  frame.world_from_ego, deskew_from[0], deskew_from[1])
        if above_ground is not None:
            world = world[above_ground]
            times = None if times is None else times[above_ground]
    near = (np.abs(world[:, 0] - box.x) <= reach) & (np.abs(world[:, 1] - box.y) <= reach)  # NaN: False
    local = world[near]
    finite = finite3(local)
    local = local[finite]
    times = None if times is None else times[near][finite]
    if removes_ground and not sweep_ground and len(local) >= 3:
        above = ~ground_mask(local, config.ground.params())
        local = local[above]
        times = None if times is None else times[above]
    inside = points_in_box(local, box, params.region_scale)
    return local[inside], None if times is None else RegionTimes(int(frame.timestamp_ns), times[inside])


def gather_frame_points(source: FrameSource, result: TrackResult, config: TrackerConfig,
                        params: OfflineParams) -> list[np.ndarray]:
    """Ground-removed world points inside each online box scaled ``region_scale`` (one array per frame); with
    ``params.own_motion_spread`` > 0 the object's own motion during each sweep is taken out of them
    (:func:`~tracker.own_motion.compensate_track`, the velocities of ``result``'s boxes)."""
    out: list[np.ndarray] = []
    times: list[RegionTimes | None] = []
    previous = None
    getter = getattr(source, "points_world", None)
    compensate = params.own_motion_spread > 0
    for est in result.estimates:
        frame = source.lidar_frame(est.frame)
        points, when = frame_region_points_timed(frame, est.box, config, params, previous,
                                                 getter(est.frame) if callable(getter) and not config.deskew else None,
                                                 with_times=compensate)
        out.append(points)
        times.append(when)
        previous = (int(frame.timestamp_ns), np.asarray(frame.world_from_ego, dtype=np.float64))
    if compensate:
        return compensate_track(out, times, [e.box for e in result.estimates], params.own_motion_spread)
    return out


def _to_object_per_point(points: np.ndarray, states: np.ndarray, frame: np.ndarray) -> np.ndarray:
    """Points (N, 3) in the object frame of their frames' states (``states[frame]``)."""
    c, s = np.cos(states[:, 3])[frame], np.sin(states[:, 3])[frame]
    d = points - states[frame, :3]
    return np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)


def _stack_frames(points: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """All frames' points (N, 3) and each point's frame index (N,)."""
    counts = [len(p) for p in points]
    if sum(counts) == 0:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    return np.vstack([p for p in points if len(p)]), np.repeat(np.arange(len(points)), counts)


def _object_points(stacked: tuple[np.ndarray, np.ndarray], states: np.ndarray, size: np.ndarray,
                   per_frame: int = 0, local: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Object-frame points inside each frame's box (each frame's at most ``per_frame``, an even subsample
    when > 0) and their frame indices, from :func:`_stack_frames` output (``local``: its points already in
    the object frames of ``states``)."""
    pts, frame = stacked
    if local is None:
        local = _to_object_per_point(pts, states, frame)
    keep = inside3(local, np.asarray(size, dtype=np.float64) / 2.0)
    if per_frame > 0 and keep.any():
        frame_in = frame[keep]
        counts = np.bincount(frame_in, minlength=len(states))
        first = np.cumsum(counts) - counts  # frames are contiguous in ``stacked``
        rank = np.arange(len(frame_in)) - first[frame_in]
        step = np.maximum(1, -(-counts // per_frame))[frame_in]  # ceil(n / per_frame): n <= per_frame keeps all
        keep[np.flatnonzero(keep)] = rank % step == 0
    return local[keep], frame[keep]


def _rebuild_shape(points: list[np.ndarray], states: np.ndarray, size: np.ndarray, voxel: float,
                   per_frame: int = 0) -> np.ndarray:
    """The shape (object frame, voxel centres) of the points inside each frame's box."""
    return voxel_downsample_centres(_object_points(_stack_frames(points), states, size, per_frame)[0], voxel)


def _normals(shape: np.ndarray, k: int, tree: cKDTree | None = None, rows: np.ndarray | None = None) -> np.ndarray:
    """Unit normals (M, 3) by PCA of each point's k nearest neighbours (smallest-eigenvalue direction);
    ``tree``: a kd-tree of ``shape`` when the caller has one; ``rows``: only these points' normals (each row
    is computed as it is for the whole shape)."""
    if min(k, len(shape)) < 3:
        return np.tile([0.0, 0.0, 1.0], (len(shape) if rows is None else len(rows), 1))
    return _smallest_eigenvectors(*_neighbour_covariances(shape, k, tree or cKDTree(shape), rows))


def _neighbour_covariances(shape: np.ndarray, k: int, tree: cKDTree, rows: np.ndarray | None = None
                           ) -> tuple[np.ndarray, ...]:
    """The six entries (xx, yy, zz, xy, xz, yz) of the covariance of each point's k nearest neighbours in
    ``shape`` (k <= len(shape), at least 3); ``rows``: only these points."""
    k = int(min(k, len(shape)))
    _, idx = tree.query(shape if rows is None else shape[rows], k=k)
    # the neighbours' coordinates as (3, k, M) rows, summed over k one row at a time: the mean and the products'
    # sums in the order numpy sums them over the neighbour axis of shape[idx] (mean(axis=1), and einsum
    # "mk,mk->m" of two of its strided coordinates, from 0), in whole-array operations. A reduction over the
    # middle axis adds its rows in order into the first one (((row 0 + row 1) + row 2) + ...; the pairwise
    # summation is for the contiguous last axis only), as mean(axis=1) does.
    nb = shape.T[:, idx.T]
    mean = np.add.reduce(nb, axis=1)
    nb -= (mean / k)[:, None]
    sums = np.zeros((6, len(idx)))
    products = np.empty((6, len(idx)))
    for j in range(k):  # neighbour j's six products (xx, yy, zz, xy, xz, yz), added in neighbour order
        col = nb[:, j]
        np.multiply(col, col, out=products[:3])
        np.multiply(col[0], col[1:], out=products[3:5])
        np.multiply(col[1], col[2], out=products[5])
        sums += products
    return tuple(sums / k)


def _smallest_eigenvectors(xx: np.ndarray, yy: np.ndarray, zz: np.ndarray, xy: np.ndarray, xz: np.ndarray,
                           yz: np.ndarray) -> np.ndarray:
    """Unit eigenvectors of the smallest eigenvalue of symmetric 3x3 matrices given by their six entries.

    Closed form: the smallest eigenvalue by the trigonometric solution of the characteristic cubic, the
    eigenvector as the largest cross product of two rows of A - lambda I. Where that is ill-conditioned
    (a repeated smallest eigenvalue: points on a line or a blob), ``numpy.linalg.eigh`` decides."""
    q = (xx + yy + zz) / 3.0
    off = xy**2 + xz**2 + yz**2
    p = np.sqrt(((xx - q) ** 2 + (yy - q) ** 2 + (zz - q) ** 2 + 2.0 * off) / 6.0)
    safe = np.where(p > 0, p, 1.0)
    bx, by, bz = (xx - q) / safe, (yy - q) / safe, (zz - q) / safe
    cxy, cxz, cyz = xy / safe, xz / safe, yz / safe
    det = bx * (by * bz - cyz**2) - cxy * (cxy * bz - cyz * cxz) + cxz * (cxy * cyz - by * cxz)
    phi = np.arccos(np.clip(det / 2.0, -1.0, 1.0)) / 3.0
    lam = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
    r0, r1, r2 = (xx - lam, xy, xz), (xy, yy - lam, yz), (xz, yz, zz - lam)  # rows of A - lambda I
    crosses = np.empty((3, 3, len(xx)))  # (pair, component, point)
    for j, (u, v) in enumerate(((r0, r1), (r0, r2), (r1, r2))):  # u x v, written out (as numpy.cross computes it)
        crosses[j, 0] = u[1] * v[2] - u[2] * v[1]
        crosses[j, 1] = u[2] * v[0] - u[0] * v[2]
        crosses[j, 2] = u[0] * v[1] - u[1] * v[0]
    squares = crosses * crosses
    norms = np.sqrt((squares[:, 0] + squares[:, 1]) + squares[:, 2])  # (3, M); numpy's order for a row of 3
    if np.isnan(norms).any():
        best = np.argmax(norms, axis=0)
    else:  # argmax over the 3 pairs (the first of equal ones), without numpy's slow reduction over a short axis
        best = np.where(norms[1] > norms[0], 1, 0)
        best = np.where(norms[2] > np.maximum(norms[0], norms[1]), 2, best)
    every = np.arange(len(best))
    length = norms[best, every]
    out = crosses[best, :, every] / np.maximum(length, 1e-300)[:, None]
    # the cross product's length is ~ the product of the other two eigenvalue gaps (times |A|^2 scale)
    bad = ~(length > 1e-6 * np.maximum(p, 1e-300) ** 2)
    if bad.any():
        bxx, byy, bzz, bxy, bxz, byz = (v[bad] for v in (xx, yy, zz, xy, xz, yz))
        a = np.stack([np.stack([bxx, bxy, bxz], 1), np.stack([bxy, byy, byz], 1), np.stack([bxz, byz, bzz], 1)], 1)
        out[bad] = np.linalg.eigh(a)[1][:, :, 0]
    return out


_SECOND_DIFFERENCE = np.array([1.0, -2.0, 1.0])
_BANDS = 8  # super-diagonals of the 4K x 4K normal equations: 3 within a frame's block, 4 and 8 for the prior


def _second_difference(x: np.ndarray) -> np.ndarray:
    """Second differences along axis 0 (rows k-1, k, k+1 -> row k-1); (K-2, ...) or empty."""
    return x[2:] - 2.0 * x[1:-1] + x[:-2]


def _second_difference_transpose(v: np.ndarray, k: int) -> np.ndarray:
    """D' v for the (k-2, k) second-difference operator D (the adjoint of :func:`_second_difference`)."""
    out = np.zeros((k,) + v.shape[1:])
    for a, coefficient in enumerate(_SECOND_DIFFERENCE):
        out[a:a + len(v)] += coefficient * v
    return out


def _prior_band(k: int, sig: np.ndarray, anchor: np.ndarray) -> np.ndarray:
    """Upper band storage (``scipy.linalg.solveh_banded``, 8 super-diagonals) of the prior's 4K x 4K Hessian
    kron(D'D, diag(1/sig^2)) + kron(I, diag(1/anchor^2)), variables ordered 4 * frame + component (``anchor``: (4,)
    or per frame (k, 4))."""
    band = np.zeros((_BANDS + 1, 4 * k))
    dtd = np.zeros((3, k))  # dtd[q, j]: (D'D)[j - q, j], the q-th super-diagonal at column j
    for q in range(3):
        for a in range(3 - q):  # row r of D touches columns r + a and r + a + q
            dtd[q, a + q:a + q + max(k - 2, 0)] += _SECOND_DIFFERENCE[a] * _SECOND_DIFFERENCE[a + q]
    inv_sig, inv_anchor = 1.0 / sig**2, 1.0 / anchor**2
    for q in range(3):
        band[_BANDS - 4 * q] = (dtd[q][:, None] * inv_sig[None, :]).ravel()
    band[_BANDS] += np.broadcast_to(inv_anchor, (k, 4)).ravel()
    return band


def _z_trend(online_z: np.ndarray, frames: int) -> np.ndarray:
    """Frame-to-frame changes (K - 1,) of the online z smoothed by a moving mean over ``frames`` each side (the
    window shrinks at the ends, so a constant slope stays exact)."""
    k, m = len(online_z), max(int(frames), 0)
    m_at = np.minimum(np.minimum(np.arange(k), k - 1 - np.arange(k)), m)  # symmetric window inside the track
    cum = np.r_[0.0, np.cumsum(online_z)]
    smooth = (cum[np.arange(k) + m_at + 1] - cum[np.arange(k) - m_at]) / (2 * m_at + 1)
    return np.diff(smooth)


# The entries (a, b), a <= b, of a frame's symmetric 4x4 J'WJ that _Solver._data sums over the points (row by row),
# and where the diagonal and the (x, theta), (y, theta) entries sit among them; per point: these 10 and 4 gradients.
_UPPER_A, _UPPER_B = np.triu_indices(4)
_DIAGONAL = [int(np.flatnonzero((_UPPER_A == a) & (_UPPER_B == a))[0]) for a in range(4)]
_THETA_X, _THETA_Y = (int(np.flatnonzero((_UPPER_A == a) & (_UPPER_B == 3))[0]) for a in (0, 1))
_BLOCK = len(_UPPER_A) + 4


def _d_transpose(c: np.ndarray, s: np.ndarray, lx: np.ndarray, ly: np.ndarray, v: np.ndarray,
                 out: np.ndarray) -> np.ndarray:
    """D'v (P, 4) of per-point vectors ``v`` (P, 3), written into ``out``: D = d(local)/d(tx, ty, tz, theta) of
    :meth:`_Solver._data`, rows (-c, -s, 0, ly), (s, -c, 0, -lx), (0, 0, -1, 0)."""
    out[:, 0] = -c * v[:, 0] + s * v[:, 1]
    out[:, 1] = -s * v[:, 0] - c * v[:, 1]
    np.negative(v[:, 2], out=out[:, 2])
    out[:, 3] = ly * v[:, 0] - lx * v[:, 1]
    return out


class _Solver:
    """Gauss–Newton over all states with the shape (and its normals) held fixed."""

    def __init__(self, points: list[np.ndarray], online: np.ndarray, size: np.ndarray, params: OfflineParams,
                 rng: np.random.Generator, fixed: int = 0, anchors: Anchors | None = None) -> None:
        self.params = params
        self.fixed = fixed
        self.size = size
        self.online = online
        self.k = len(online)
        self.stacked = _stack_frames(points)
        self.rng = rng
        sig = np.array([params.smooth_sigma_xy, params.smooth_sigma_xy, params.smooth_sigma_z, params.smooth_sigma_heading])
        sigma_z = params.anchor_sigma_z if params.anchor_sigma_z > 0 else params.anchor_sigma_xyz
        anchor = np.array([params.anchor_sigma_xyz] * 2 + [sigma_z, params.anchor_sigma_heading])
        if anchors is not None and anchors.pull is not None:   # per-frame pulls toward the online states
            anchor = np.asarray(anchors.pull, dtype=np.float64)
        self.h_prior = _prior_band(self.k, sig, anchor)  # variable order: 4 * frame + component
        self.z_trend = _z_trend(online[:, 2], params.z_trend_frames) if params.z_trend_sigma > 0 and self.k >= 2 else None
        if self.z_trend is not None:  # D1' W D1 on z / sigma^2, D1 first differences
            self.z_weight = np.full(self.k - 1, 1.0 / params.z_trend_sigma**2)
            if params.z_trend_points > 0:
                local = _to_object_per_point(self.stacked[0], online, self.stacked[1])
                inside = inside3(local, size / 2.0)
                n = np.bincount(self.stacked[1][inside], minlength=self.k).astype(np.float64)
                self.z_weight *= params.z_trend_points / (params.z_trend_points + 0.5 * (n[1:] + n[:-1]))
            self.h_prior[_BANDS, 2::4] += np.r_[self.z_weight, 0.0] + np.r_[0.0, self.z_weight]
            self.h_prior[_BANDS - 4, 6::4] -= self.z_weight
        self.sig = sig
        self.anchor = anchor
        self.anchors = anchors
        self.held = np.zeros(0, dtype=np.int64)  # variables (4 * frame + component) held by hard anchors
        if anchors is not None and anchors.sigma is None:
            self.held = (4 * np.asarray(anchors.frames, dtype=np.int64)[:, None] + np.arange(4)).ravel()
        elif anchors is not None:
            self.h_prior[_BANDS, (4 * np.asarray(anchors.frames)[:, None] + np.arange(4)).ravel()] += np.tile(
                1.0 / np.asarray(anchors.sigma, dtype=np.float64) ** 2, len(anchors.frames))
        self._matched: tuple[np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None
        self._travel = (np.zeros(self.k), np.zeros(self.k))  # heading targets and weights (_travel_targets)
        self._turn = np.zeros((max(self.k - 2, 0), 2))  # x, y second differences of a turn (_turn_targets)
        self._object_cache: tuple[np.ndarray, np.ndarray] | None = None
        self._residual: tuple[np.ndarray, tuple] | None = None   # the last states' residuals (_residuals)

    def set_shapes(self, states: np.ndarray) -> bool:
        """Build, for each fold f, the shape from the frames NOT in f (a frame never matches its own points).

        Returns False when a shape is too small to register to."""
        p = self.params
        folds = max(2, int(p.folds))
        self.folds = folds
        self.shapes, self.trees, self.normals, self.has_normal = [], [], [], []
        self.nearest: list[VoxelNearest] = []
        local, frame = _object_points(self.stacked, states, self.size, p.shape_points_per_frame,
                                      self._object_frame(states))
        downsample = voxel_downsample_means if p.shape_voxel == "means" else voxel_downsample_centres
        blocks = -(-self.k // p.shape_frames) if p.shape_frames > 0 else 1
        for g in range(folds * blocks):   # group g: fold g % folds, block g // folds (shape_frames)
            f = g % folds
            shape = downsample(local[frame % folds != f], p.voxel)
            if len(shape) < p.min_shape_points:
                return False
            if blocks > 1:   # the frames of the block and its neighbours only, where they give a shape
                near = (frame % folds != f) & (np.abs(frame // p.shape_frames - g // folds) <= 1)
                local_shape = downsample(local[near], p.voxel)
                shape = local_shape if len(local_shape) >= p.min_shape_points else shape
            self.shapes.append(shape)
            self.trees.append(cKDTree(shape))
            self.nearest.append(VoxelNearest(shape, p.voxel, self.trees[-1]))   # the tree's answers, most by look-up
            self.normals.append(np.zeros((len(shape), 3)))   # computed for the points matched (_match)
            self.has_normal.append(np.zeros(len(shape), dtype=bool))
        self._matched = self._residual = None
        return True

    def _object_frame(self, states: np.ndarray) -> np.ndarray:
        """Every gathered point in its frame's object frame at ``states`` (kept for the next call with the
        same states: a shape rebuild and the data selection that follows it)."""
        if self._object_cache is not None and np.array_equal(self._object_cache[0], states):
            return self._object_cache[1]
        raw, raw_frame = self.stacked
        local = _to_object_per_point(raw, states, raw_frame)
        self._object_cache = (states.copy(), local)
        return local

    def _match(self, local: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Distance, matched shape point and its normal for each data point (against its fold's shape)."""
        dist = np.empty(len(local))
        m = np.empty_like(local)
        n = np.empty_like(local)
        matched, missing = [], []
        for f, sel in enumerate(self.fold_rows):
            if not len(sel):
                continue
            d, idx = self.nearest[f].query(local[sel])
            matched.append((f, sel, d, idx))
            rows = unique_sorted(idx[~self.has_normal[f][idx]])
            if len(rows) and min(self.params.normal_neighbours, len(self.shapes[f])) < 3:
                self.normals[f][rows] = _normals(self.shapes[f], self.params.normal_neighbours, rows=rows)
                self.has_normal[f][rows] = True
            elif len(rows):  # matched for the first time: their normals (as _normals gives them), all folds' at once
                missing.append((f, rows, _neighbour_covariances(self.shapes[f], self.params.normal_neighbours,
                                                                self.trees[f], rows)))
        if missing:
            normals = _smallest_eigenvectors(*(np.concatenate(parts)
                                               for parts in zip(*(c for _, _, c in missing), strict=True)))
            start = 0
            for f, rows, _ in missing:
                self.normals[f][rows] = normals[start:start + len(rows)]
                self.has_normal[f][rows] = True
                start += len(rows)
        for f, sel, d, idx in matched:
            dist[sel], m[sel], n[sel] = d, self.shapes[f][idx], self.normals[f][idx]
        return dist, m, n

    def select(self, states: np.ndarray) -> None:
        """Data points of each free frame: inside the current box scaled crop_scale, random subset (fixed
        for a shape). A held frame's data term is a constant, so its points are left out (its random draw
        is still made, so the free frames' subsets do not depend on how many frames are held)."""
        p = self.params
        raw, raw_frame = self.stacked
        local = self._object_frame(states)
        inside = inside3(local, self.size * p.crop_scale / 2.0)
        counts = np.bincount(raw_frame[inside], minlength=self.k)
        self.any_points = bool(inside.any())
        keep = inside & (raw_frame >= self.fixed)
        bounds = np.searchsorted(raw_frame, np.arange(self.k + 1))  # frames are contiguous in ``stacked``
        for k in np.flatnonzero(counts > p.max_points):  # the same draws, in frame order, as frame by frame
            chosen = np.sort(self.rng.choice(counts[k], p.max_points, replace=False))
            if k >= self.fixed:
                members = bounds[k] + np.flatnonzero(inside[bounds[k]:bounds[k + 1]])
                keep[members] = False
                keep[members[chosen]] = True
        self.pts = raw[keep]
        self.frame_idx = raw_frame[keep]
        counts = np.bincount(self.frame_idx, minlength=self.k).astype(np.float64)
        scale = np.where(counts > 0, np.minimum(1.0, p.effective_points / np.maximum(counts, 1.0)), 0.0)
        scale[0] *= p.first_frame_weight
        self.point_scale = scale[self.frame_idx] / p.point_sigma**2
        self.slots = (self.frame_idx[:, None] * _BLOCK + np.arange(_BLOCK)).ravel()  # (frame, block entry) of _data
        group = self.frame_idx % self.folds
        if p.shape_frames > 0:
            group = group + self.folds * (self.frame_idx // p.shape_frames)
        self.fold_rows = [np.flatnonzero(group == g) for g in range(len(self.shapes))]
        self._matched = self._residual = None

    def _residuals(self, states: np.ndarray, pairs: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None):
        """(cos, sin of each point's heading, lx, ly, normals, ne, r, |r|, weight, cost) of :meth:`_data` at
        ``states``. Without ``pairs`` the last result is kept: a step's accepted trial is where the next step
        linearises (the same points, states and pairs give the same numbers)."""
        if pairs is None and self._residual is not None and np.array_equal(self._residual[0], states):
            return self._residual[1]
        p = self.params
        beta = p.tangent_weight
        c, si = np.cos(states[:, 3])[self.frame_idx], np.sin(states[:, 3])[self.frame_idx]
        d = self.pts - states[self.frame_idx, :3]
        lx = c * d[:, 0] + si * d[:, 1]
        ly = -si * d[:, 0] + c * d[:, 1]
        local = np.stack([lx, ly, d[:, 2]], axis=1)
        if pairs is not None:
            dist, m, n = pairs
        elif self._matched is not None and np.array_equal(self._matched[0], states):
            dist, m, n = self._matched[1]  # the accepted trial of the previous step: same states, same pairs
        else:
            dist, m, n = self._match(local)
            self._matched = (states.copy(), (dist, m, n))
        e = local - m
        ne = sum3(n * e)
        r = (1.0 - beta) * n * ne[:, None] + beta * e
        norm = norm3(r)
        delta = p.huber_delta
        rho = np.where(norm <= delta, norm**2, 2 * delta * norm - delta**2)
        weight = self.point_scale * (dist <= p.max_pair_distance)
        cost = float(np.sum(weight * rho))
        out = (c, si, lx, ly, n, ne, r, norm, weight, cost)
        if pairs is None:
            self._residual = (states.copy(), out)
        return out

    def _data(self, states: np.ndarray, with_jacobian: bool,
              pairs: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None):
        """Data cost and, optionally, per-frame 4x4 Gauss-Newton blocks J'WJ and gradients J'Wr. J'WJ is symmetric:
        only its upper triangle is summed over the points, and mirrored.

        Residual r = A e with e = local - m and A = (1 - beta) n n' + beta I, i.e.
        r = (1 - beta) n (n.e) + beta e. ``pairs``: (distance, shape point, normal) of each data point to
        use instead of matching the points at ``states`` to the shape.
        """
        c, si, lx, ly, n, ne, r, norm, weight, cost = self._residuals(states, pairs)
        beta, delta = self.params.tangent_weight, self.params.huber_delta
        if not with_jacobian:
            return cost, None, None
        w = weight * np.where(norm <= delta, 1.0, delta / np.maximum(norm, 1e-12))
        # J = A D with D = d(local)/d(tx, ty, tz, theta), rows (-c, -s, 0, ly), (s, -c, 0, -lx), (0, 0, -1, 0).
        # With |n| = 1, A'A = (1 - beta^2) n n' + beta^2 I, so J'J = (1 - beta^2) (D'n)(D'n)' + beta^2 D'D
        # and J'r = D'A'r = (1 - beta) (D'n)(n.e) + beta D'r (n.r = n.e); D'D is 1 on the diagonal but
        # (theta, theta) = lx^2 + ly^2, with (tx, theta) = -c ly - s lx and (ty, theta) = c lx - s ly.
        nj = _d_transpose(c, si, lx, ly, n, np.empty((len(w), 4)))  # D'n, (P, 4)
        per_point = np.empty((len(w), _BLOCK))   # the upper triangle of J'J (_UPPER_A, _UPPER_B), then J'r
        jtj = per_point[:, :len(_UPPER_A)]
        np.multiply(nj[:, _UPPER_A], ((1.0 - beta**2) * nj)[:, _UPPER_B], out=jtj)
        b2 = beta**2
        for col in _DIAGONAL[:3]:
            jtj[:, col] += b2
        jtj[:, _DIAGONAL[3]] += b2 * (lx**2 + ly**2)
        for col, g in ((_THETA_X, -c * ly - si * lx), (_THETA_Y, c * lx - si * ly)):
            g *= b2
            jtj[:, col] += g
        gradient = per_point[:, len(_UPPER_A):]
        np.multiply((1.0 - beta) * nj, ne[:, None], out=gradient)
        dr = _d_transpose(c, si, lx, ly, r, nj)  # D'r (in nj's place: nj is no longer needed)
        dr *= beta
        gradient += dr
        per_point *= w[:, None]
        sums = np.bincount(self.slots, weights=per_point.ravel(), minlength=_BLOCK * self.k).reshape(self.k, _BLOCK)
        blocks = np.empty((self.k, 4, 4))   # symmetric: each upper entry mirrored below the diagonal
        blocks[:, _UPPER_A, _UPPER_B] = blocks[:, _UPPER_B, _UPPER_A] = sums[:, :len(_UPPER_A)]
        return cost, blocks, sums[:, len(_UPPER_A):]

    def _prior(self, states: np.ndarray) -> tuple[float, np.ndarray]:
        diff2 = _second_difference(states)
        if self.params.smooth_turn:   # x, y: the departure from a turn at the heading's rate, not from a line
            diff2[:, :2] -= self._turn
        dev = states - self.online
        cost = float(np.sum(diff2**2 / self.sig**2) + np.sum(dev**2 / self.anchor**2))
        grad = _second_difference_transpose(diff2 / self.sig**2, self.k) + dev / self.anchor**2
        if self.z_trend is not None:  # z's changes follow the online z's (smoothed) changes
            r = (np.diff(states[:, 2]) - self.z_trend) * self.z_weight
            cost += float(np.sum(r * (np.diff(states[:, 2]) - self.z_trend)))
            grad[:-1, 2] -= r
            grad[1:, 2] += r
        if self.anchors is not None and self.anchors.sigma is not None:  # soft anchors: a pull toward them
            pull = (states[self.anchors.frames] - self.anchors.states) / np.asarray(self.anchors.sigma) ** 2
            cost += float(np.sum(pull * (states[self.anchors.frames] - self.anchors.states)))
            np.add.at(grad, self.anchors.frames, pull)
        return cost, grad

    def _travel_targets(self, states: np.ndarray) -> None:
        """Heading from travel (``travel_sigma_heading`` > 0): frame k's heading toward the direction of the
        chord from state k - m to state k + m (m = ``travel_frames``; the heading at k in a steady turn), weight
        1 / sigma^2 x a speed factor (0 below ``travel_min_step`` m per frame over the chord, 1 from twice it);
        frames without both ends, or whose chord is more than 0.5 rad off their heading, get none. The targets
        are held through a Gauss-Newton step (its cost check included)."""
        p = self.params
        m, k = max(int(p.travel_frames), 1), self.k
        self._travel = (np.zeros(k), np.zeros(k))
        if p.travel_sigma_heading <= 0 or k <= 2 * m:
            return
        chord = states[2 * m:, :2] - states[:-2 * m, :2]
        step = np.linalg.norm(chord, axis=1) / (2 * m)
        direction = np.arctan2(chord[:, 1], chord[:, 0])
        heading = states[m:k - m, 3]
        offset = wrap_angle(direction - heading)
        offset = np.where(np.abs(offset) > 0.5 * np.pi, wrap_angle(offset + np.pi), offset)  # reversing
        weight = np.clip(step / p.travel_min_step - 1.0, 0.0, 1.0) / p.travel_sigma_heading**2
        weight = np.where(np.abs(offset) > 0.5, 0.0, weight)
        if p.travel_rear_axle > 0:   # the centre's sideslip in a turn (forward only): travel = heading + slip
            rate = wrap_angle(states[2 * m:, 3] - states[:-2 * m, 3]) / (2 * m)
            slip = np.arcsin(np.clip(p.travel_rear_axle * rate / np.maximum(step, 1e-6), -0.5, 0.5))
            offset = offset - np.where(np.abs(wrap_angle(direction - heading)) > 0.5 * np.pi, 0.0, slip)
        target, w = np.zeros(k), np.zeros(k)
        target[m:k - m], w[m:k - m] = heading + offset, weight
        self._travel = (target, w)

    def _turn_targets(self, states: np.ndarray) -> None:
        """The x, y second differences of a steady turn (``smooth_turn``): at frame k the velocity turns with the
        heading, p_k+1 - 2 p_k + p_k-1 = 2 tan(w / 2) J (p_k+1 - p_k-1) / 2 with w = (heading_k+1 - heading_k-1) / 2
        and J the quarter turn (exact for a constant turn rate and speed); held through a Gauss-Newton step."""
        if not self.params.smooth_turn or self.k < 3:
            return
        rate = wrap_angle(states[2:, 3] - states[:-2, 3]) / 2.0
        chord = (states[2:, :2] - states[:-2, :2]) / 2.0
        scale = 2.0 * np.tan(np.clip(rate, -0.5, 0.5) / 2.0)
        self._turn = scale[:, None] * np.stack([-chord[:, 1], chord[:, 0]], axis=1)

    def _travel_cost(self, states: np.ndarray) -> tuple[float, np.ndarray]:
        target, w = self._travel
        r = states[:, 3] - target
        return float(np.sum(w * r**2)), w * r

    def cost(self, states: np.ndarray, pairs: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> float:
        return self._data(states, False, pairs)[0] + self._prior(states)[0] + self._travel_cost(states)[0]

    def step(self, states: np.ndarray) -> np.ndarray:
        self._turn_targets(states)
        cost_d, blocks, grads = self._data(states, True)
        assert self._matched is not None   # _data without pairs records the pairs it matched at ``states``
        pairs = self._matched[1] if self.params.trial_pairs == "fixed" else None  # the pairs at ``states``
        cost_p, grad_p = self._prior(states)
        self._travel_targets(states)
        cost_t, grad_t = self._travel_cost(states)
        cost_p += cost_t
        grad_p[:, 3] += grad_t
        h = self.h_prior.copy()  # + the data's 4x4 block of each frame (upper band storage)
        h[_BANDS, 3::4] += self._travel[1]
        for a in range(4):
            for b in range(a, 4):
                h[_BANDS + a - b, b::4] += blocks[:, a, b]
        h[_BANDS] += 1e-9 * (1.0 + h[_BANDS])
        g = (grads + grad_p).reshape(-1)
        if len(self.held):  # hard anchors: their rows and columns become the identity, their steps zero
            for d in range(_BANDS + 1):
                h[_BANDS - d, self.held[self.held + d < h.shape[1]] + d] = 0.0
                h[_BANDS - d, self.held] = 0.0
            h[_BANDS, self.held] = 1.0
            g[self.held] = 0.0
        delta = np.zeros(4 * self.k)
        first = 4 * self.fixed  # the free variables are the trailing ones: their block is a band too
        try:
            delta[first:] = -solveh_banded(h[:, first:], g[first:], check_finite=False)
        except np.linalg.LinAlgError:
            return states
        if not np.all(np.isfinite(delta)):
            return states
        before = cost_d + cost_p
        step = delta.reshape(self.k, 4)
        for _ in range(4):
            trial = states + step
            if self.cost(trial, pairs) <= before:
                return trial
            step = step / 2.0
        return states


def _regauge(states: np.ndarray, given_first: np.ndarray, heading_share: float = 1.0) -> np.ndarray:
    """Apply to every pose the same OBJECT-frame correction that maps refined pose 0 onto the given one.

    The joint problem fixes the trajectory only up to where the shape sits in the object frame; the start
    box is given, so pose_k <- pose_k o delta with delta = pose_0^-1 o given_0 (4-DOF). ``heading_share`` < 1:
    only that share of delta's rotation (refined pose 0's heading is pinned by frame 0's points alone, and a
    sparse frame 0 would turn the whole trajectory); its centre still maps onto the given one. 0: no
    correction at all (frame 0 has no points: refined pose 0 is where the smoothness put it, not a measurement).
    """
    if heading_share <= 0.0:
        return states
    d_theta = given_first[3] - states[0, 3]
    if heading_share < 1.0:
        d_theta = heading_share * wrap_angle(d_theta)
    c, s = np.cos(states[0, 3]), np.sin(states[0, 3])
    diff = given_first[:3] - states[0, :3]
    d_t = np.array([c * diff[0] + s * diff[1], -s * diff[0] + c * diff[1], diff[2]])
    return _composed(states, d_t, d_theta)


def _composed(states: np.ndarray, d_t: np.ndarray, d_theta: float) -> np.ndarray:
    """Every pose composed with one object-frame correction: translation ``d_t`` (along, left, up), then turn."""
    out = states.copy()
    ck, sk = np.cos(states[:, 3]), np.sin(states[:, 3])
    out[:, 0] += ck * d_t[0] - sk * d_t[1]
    out[:, 1] += sk * d_t[0] + ck * d_t[1]
    out[:, 2] += d_t[2]
    out[:, 3] += d_theta
    return out


def _window_gauge(states: np.ndarray, window: np.ndarray, frames: int, max_offset: float) -> np.ndarray:
    """``states`` moved by one object-frame correction: the mean over frames 1..``frames`` of the correction that
    maps each refined pose onto the window pass's (frame 0, the start box, stays exact); unchanged when its centre
    part is ``max_offset`` or more (the window and the solve disagree by more than registration noise)."""
    n = min(frames, len(states) - 1)
    if n < 1:
        return states
    s, w = states[1:n + 1], window[1:n + 1]
    c, si = np.cos(s[:, 3]), np.sin(s[:, 3])
    diff = w[:, :3] - s[:, :3]
    d_t = np.c_[c * diff[:, 0] + si * diff[:, 1], -si * diff[:, 0] + c * diff[:, 1], diff[:, 2]].mean(axis=0)
    d_theta = float(np.angle(np.exp(1j * wrap_angle(w[:, 3] - s[:, 3])).mean()))
    if np.linalg.norm(d_t) >= max_offset:
        return states
    out = _composed(states, d_t, d_theta)
    out[:, 3] = wrap_angle(out[:, 3])
    out[0] = states[0]
    return out


def refine_states(points: list[np.ndarray], online_states: np.ndarray, size: np.ndarray,
                  params: OfflineParams = OfflineParams(), seed: int = 0, initial: np.ndarray | None = None,
                  fixed: int = 0, with_shape: bool = True, anchors: Anchors | None = None
                  ) -> tuple[np.ndarray, np.ndarray | None]:
    """Jointly refined states (K, 4) and the shape rebuilt from them (object frame), given each frame's
    world points (``points[k]``) and the online states (the anchors).

    ``initial``: the states to start from (default: the online ones). ``fixed`` > 0: the first ``fixed``
    states are held (a sliding window behind final states); else state 0 (the given start box) is kept
    exactly, by re-gauging after each solve (see :func:`_regauge`) or by holding it (``gauge="fix_first"``).
    ``with_shape=False``: the shape is not rebuilt (None). ``anchors``: states given at some frames (keyframes,
    :class:`Anchors`): hard ones start there and are held exactly, soft ones pull; either way they fix the gauge
    (no re-gauging, no ``fix_first``)."""
    online = np.asarray(online_states, dtype=np.float64).copy()
    online[:, 3] = np.unwrap(online[:, 3])
    states = online.copy() if initial is None else np.asarray(initial, dtype=np.float64).copy()
    states[:, 3] = online[:, 3] + wrap_angle(states[:, 3] - online[:, 3])
    size = np.asarray(size, dtype=np.float64)
    if anchors is not None:  # headings on the unwrapped branch of the online ones; hard anchors start exact
        given = np.asarray(anchors.states, dtype=np.float64).copy()
        given[:, 3] = online[anchors.frames, 3] + wrap_angle(given[:, 3] - online[anchors.frames, 3])
        anchors = dataclasses.replace(anchors, frames=np.asarray(anchors.frames, dtype=np.int64), states=given)
        if anchors.sigma is None:
            states[anchors.frames] = given
    if len(states) < 2:
        return states, _rebuild_shape(points, states, size, params.voxel)
    regauge = fixed == 0 and params.gauge == "regauge" and anchors is None
    if fixed == 0 and params.gauge == "fix_first" and anchors is None:
        fixed = 1
    heading_share = 1.0
    if regauge and params.gauge_heading_points > 0:
        first = points_in_box(points[0], _box(online[0], size), 1.0).sum() if len(points[0]) else 0
        heading_share = min(1.0, float(first) / params.gauge_heading_points)
    shape_voxel = params.voxel  # the returned shape's grid
    params = _dense_params(points, online, size, params)
    solver = _Solver(points, online, size, params, np.random.default_rng(seed), fixed, anchors)
    for _ in range(params.outer_iterations):
        if not solver.set_shapes(states):
            break
        solver.select(states)
        if not solver.any_points:
            break
        for _ in range(params.gn_iterations):
            states = solver.step(states)
        if regauge:
            states = _regauge(states, online[0], heading_share)
    out = states.copy()
    if heading_share < 1.0:
        out[0] = online[0]  # the start box, exact
    out[:, 3] = wrap_angle(out[:, 3])
    return out, _rebuild_shape(points, states, size, shape_voxel) if with_shape else None


def _dense_params(points: list[np.ndarray], online: np.ndarray, size: np.ndarray, params: OfflineParams
                  ) -> OfflineParams:
    """``params`` with the dense grid (``dense_voxel``, ``dense_shape_points``) where the frames hold a median of at
    least ``dense_points`` object points in their online boxes: fold shapes of voxel centres pull a dense car's frames
    onto the grid's layers (a bias of up to half a voxel in each axis that the other folds' shapes share), which a
    sparse car's few points cannot resolve, while its shape needs the coarse grid's neighbours for its normals."""
    if params.dense_voxel <= 0:
        return params
    if float(np.median(_box_counts(points, online, size))) < params.dense_points:
        return params
    return dataclasses.replace(params, voxel=params.dense_voxel, shape_points_per_frame=params.dense_shape_points)


def _box_counts(points: list[np.ndarray], states: np.ndarray, size: np.ndarray) -> np.ndarray:
    """Each frame's points inside its box."""
    return np.array([points_in_box(p, _box(s, size), 1.0).sum() if len(p) else 0
                     for p, s in zip(points, states, strict=True)], dtype=np.int64)


def _support(points: list[np.ndarray], states: np.ndarray, size: np.ndarray) -> int:
    """How many of the frames' points lie inside their boxes (all frames)."""
    return int(_box_counts(points, states, size).sum())


def _support_bound(points: list[np.ndarray], height: float) -> int:
    """An upper bound of :func:`_support` for ANY states (boxes of height ``height``): per frame, the most of its
    points whose z lie within ``height`` (+1e-9 m for rounding) of each other, which a level box holds at most."""
    bound = 0
    for p in points:
        if len(p):
            z = np.sort(p[:, 2])
            bound += int(np.max(np.searchsorted(z, z + (height + 1e-9), side="right") - np.arange(len(z))))
    return bound


def _window_cannot_win(points: list[np.ndarray], states: np.ndarray, size: np.ndarray, params: OfflineParams) -> bool:
    """Whether step 6 cannot change the result on these points whatever the window pass gives: the solve from the
    online states holds so many of them that no states' boxes hold ``window_start_margin`` x as many (the window
    pass, the most expensive part of the solve, is then not run; ``gauge_window`` needs it: never skipped)."""
    if params.gauge_window > 0:
        return False
    held = _support(points, states, size)
    return params.window_start_margin * held >= _support_bound(points, float(size[2]))


def _window_not_needed(result: TrackResult, online: np.ndarray, states: np.ndarray, params: OfflineParams) -> bool:
    """Whether step 6 is not tried (``window_start_first_moved``): no online frame lost the car (prior-only,
    coasting, waiting, no sweep) and the first solve moved no centre farther than ``window_start_first_moved`` from
    the online one. The second start is for online states the first solve could not move far enough (a lost
    stretch, a car held off its points: the first solve moves them, not all the way); where it agrees with them,
    the window pass (the most expensive part of the solve) finds no better start (docs/tracker-decisions.md)."""
    if params.window_start_first_moved <= 0 or any(is_lost(e, 0) for e in result.estimates):
        return False
    return _largest_move(states, online) <= params.window_start_first_moved


def _largest_move(states: np.ndarray, online: np.ndarray) -> float:
    """The largest horizontal distance (m) between a frame's centre in ``states`` and in ``online``."""
    return float(np.max(np.hypot(states[:, 0] - online[:, 0], states[:, 1] - online[:, 1])))


def _moved_by_backward_passes(fused: TrackResult, result: TrackResult, moved: float) -> bool:
    """Whether the backward passes moved some centre of ``result`` farther than ``moved`` (m): a pass that agrees
    with the forward one within that changes nothing (the solve starts from the online states as without it)."""
    return _largest_move(np.array([e.state.to_array() for e in fused.estimates]),
                         np.array([e.state.to_array() for e in result.estimates])) > moved


def _window_start(source: FrameSource | None, result: TrackResult, config: TrackerConfig, params: OfflineParams,
                  points: list[np.ndarray], online: np.ndarray, window: np.ndarray, states: np.ndarray,
                  shape: np.ndarray | None
                  ) -> tuple[np.ndarray, np.ndarray | None, list[np.ndarray]]:
    """Step 6 of the module docstring: the solve from the fixed-lag window's states (``window``), kept when its
    boxes hold more of the points than the solve from the online states; returns (states, shape, points) of the
    one kept."""
    size = np.asarray(result.size)
    if _largest_move(window, online) <= params.window_start_moved:
        return states, shape, points
    both = points
    if source is not None:  # the points around the window's boxes too (the online regions may not reach them)
        moved = dataclasses.replace(result, estimates=[dataclasses.replace(e, box=_box(w, size))
                                                       for e, w in zip(result.estimates, window, strict=True)])
        around = gather_frame_points(source, moved, config, params)
        both = [np.unique(np.vstack([a, b]), axis=0) if len(b) else a for a, b in zip(points, around, strict=True)]
    second, second_shape = refine_states(both, online, size, params, seed=config.seed, initial=window)
    if _support(both, second, size) > params.window_start_margin * _support(both, states, size):
        return second, second_shape, both
    return states, shape, points


def footprint_carried_back(result: TrackResult, config: TrackerConfig) -> TrackResult:
    """``result`` with each footprint turn (:attr:`FrameEstimate.turn`, tracker/footprint.py) carried back over
    the frames before it that were held turned too (:func:`~tracker.footprint.held_turned`: dense, their points
    line up nearer the turned heading), back to the first that was not or to the shape's (re)start: each such box
    turned by the same amount about its centre. Online those frames are final; the whole-sequence solve starts
    from them, and a turn left at frame k with the frames before it held turned is a kink that the solve's
    smoothness and fold shapes spread over both sides."""
    turns = [i for i, e in enumerate(result.estimates) if e.turn != 0.0]
    if not turns:
        return result
    estimates = list(result.estimates)
    for i in turns:
        turn = estimates[i].turn
        j = i - 1
        while (j > 0 and not {"init", "reacquired"} & set(estimates[j].flags)
               and held_turned(estimates[j].points, estimates[j].box.heading, turn, config.footprint)):
            e = estimates[j]
            box = dataclasses.replace(e.box, heading=float(wrap_angle(e.box.heading + turn)))
            estimates[j] = dataclasses.replace(e, box=box, state=box.state)
            j -= 1
    return dataclasses.replace(result, estimates=estimates)


def refine_offline(source: FrameSource | None, result: TrackResult, config: TrackerConfig | None = None,
                   params: OfflineParams | None = None, points: list[np.ndarray] | None = None,
                   point_times: list[RegionTimes | None] | None = None) -> TrackResult:
    """Offline-refined copy of an online ``result`` (see the module docstring); ``params`` default to
    ``config.refinement.offline``. With ``config.refinement.backward`` (and a ``source``) the states of backward
    passes from the track's anchors replace its weak runs first (tracker/bidirectional.py), when they move some
    frame's centre farther than ``params.window_start_moved``; with ``config.refinement.relock_bridge`` the
    stretches a lost track searched on someone else's points before a re-lock are bridged before that
    (tracker/relock_bridge.py). ``points``: each frame's region points as :func:`gather_frame_points` gives them,
    when the caller gathered them while tracking (then ``source`` is not read and may be None), and ``point_times``
    their capture times (:func:`frame_region_points_timed`; needed to take the object's own motion out of them, as
    :func:`gather_frame_points` does, when ``params.own_motion_spread`` > 0)."""
    config = config or result.config
    params = params or config.refinement.offline
    if points is not None and point_times is not None and params.own_motion_spread > 0:
        points = compensate_track(points, point_times, [e.box for e in result.estimates], params.own_motion_spread)
    if config.footprint.carry_back:
        carried = footprint_carried_back(result, config)
        if carried is not result and points is None and source is not None:
            # each frame's points around its online box, as a tracking pass gathers them while it tracks
            points = gather_frame_points(source, result, config, params)
        result = carried
    if config.refinement.relock_bridge != "none" and (bridged := bridged_result(
            result, config.refinement.backward_lost_points)) is not result:
        if points is None and source is not None:
            points = gather_frame_points(source, result, config, params)   # around the online boxes, as a pass does
        if points is not None:   # a bridged frame holds no points
            points = [p if a is b else np.zeros((0, 3)) for p, a, b in zip(points, result.estimates,
                                                                            bridged.estimates, strict=True)]
        result = bridged
    return _refine_offline(source, result, config, params, points)


def _refine_offline(source: FrameSource | None, result: TrackResult, config: TrackerConfig, params: OfflineParams,
                    points: list[np.ndarray] | None) -> TrackResult:
    if config.refinement.backward != "none" and source is not None and _moved_by_backward_passes(
            fused := fused_result(source, result, config), result, params.window_start_moved):
        # bidirectional: the backward passes moved a lost stretch, the fused states are the data
        if points is not None:
            points = [p if a is b else frame_region_points(source.lidar_frame(b.frame), b.box, config, params)
                      for p, a, b in zip(points, result.estimates, fused.estimates, strict=True)]
        result = fused
        # the fused states already hold the lost stretch where the window would move it: its move tests nothing
        params = dataclasses.replace(params, window_start_moved=0.0)
    if points is None:
        if source is None:
            raise ValueError("refine_offline needs a source to read when no points are given")
        points = gather_frame_points(source, result, config, params)
    online = np.array([e.state.to_array() for e in result.estimates])
    states, shape = refine_states(points, online, np.asarray(result.size), params, seed=config.seed)
    # (without a source the second solve sees these points only: when it cannot win, its window is not run)
    if (params.window_start > 0 and len(online) > 2 and not _window_not_needed(result, online, states, params)
            and not (source is None and _window_cannot_win(points, states, np.asarray(result.size), params))):
        from .fixed_lag import window_states

        window = window_states(points, result, params.window_start, config)
        states, shape, points = _window_start(source, result, config, params, points, online, window, states, shape)
        size = np.asarray(result.size)
        if params.window_keep and (_support(points, window, size)
                                   > params.window_start_margin * _support(points, states, size)):
            states = window.copy()
            states[:, 3] = wrap_angle(states[:, 3])
            shape = _rebuild_shape(points, states, size, params.voxel)
        if params.gauge_window > 0:
            gauged = _window_gauge(states, window, params.gauge_window, params.gauge_window_max)
            if gauged is not states:
                states, shape = gauged, _rebuild_shape(points, gauged, size, params.voxel)
    assert shape is not None   # with_shape=True
    estimates: list[FrameEstimate] = []
    for est, pts, s in zip(result.estimates, points, states, strict=True):
        box = _box(s, result.size)
        obj = pts[points_in_box(pts, box, 1.0)]
        flags = tuple(dict.fromkeys(list(est.flags) + ["offline"]))
        estimates.append(dataclasses.replace(est, state=State.from_array(box.to_array()[:4]), box=box,
                                             num_points=len(obj), points=obj, flags=flags))
    return TrackResult(estimates, np.asarray(result.size), shape, config, mode="offline")
