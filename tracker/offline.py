"""Offline refinement: after the online pass, re-estimate all states jointly (issue 7 §6).

Data-generation users have the whole sequence, so nothing forces the estimate of frame k to ignore
frames k+1, k+2, .... Given an online :class:`~tracker.sotracker.TrackResult`:

1. every frame's points near its online box (ground removed with the tracker's GPF parameters, cropped
   with the box scaled ``region_scale``) are gathered once (world frame);
2. frames are split into ``folds`` interleaved folds (k mod folds). For each fold a shape is rebuilt from
   the frames NOT in it: points in the current boxes (scale 1.0), moved to the object frame, voxelised
   (5 cm centres), with normals n from a PCA of each shape point's neighbours. A frame is registered
   only to the shape of the other folds: registering a frame to an aggregate that contains its own
   points pins it where it already is (the residuals are ~0 whatever its error);
3. all states S_0..S_{K-1} minimise, jointly,

       Σ_k c_k Σ_p ρ_Huber(‖A (R(−θ_k)(p − t_k) − m)‖) / σ_p²              (data: frame k's points vs shape)
     + Σ_k Σ_c (S_{k+1,c} − 2 S_{k,c} + S_{k−1,c})² / σ_c²                (smoothness: 2nd differences
                                                                          of x, y, z, heading)
     + Σ_k Σ_c (S_{k,c} − S^online_{k,c})² / σ_anchor,c²                   (weak pull to the online states)

   with m the nearest shape point of the moved p (pairs farther than ``max_pair_distance`` dropped),
   A = (1 − β) n nᵀ + β I (β = 0: point-to-plane, β = 1: point-to-point; default 0.3), and
   c_k = min(1, ``effective_points`` / N_k), so a dense frame counts as at most that many independent
   points (LiDAR residuals are strongly correlated). It is solved by Gauss–Newton with iteratively
   re-weighted Huber weights on one sparse (block-tridiagonal) 4K × 4K normal-equation system
   (scipy.sparse), with a cost check and step halving; correspondences are recomputed at every step;
4. gauge: the joint problem fixes the trajectory only up to where the shape sits in the object frame.
   With ``gauge="regauge"`` (default) all states are free and afterwards every pose is composed with the
   one object-frame correction that maps the refined S_0 onto the given start box (so S_0 is exact and
   all frames keep their relative registration); ``gauge="fix_first"`` holds S_0 fixed instead;
5. steps 2–4 repeat ``outer_iterations`` times; the shape is rebuilt from the final states (all frames).

The result is a new TrackResult (same frames, sizes and per-frame online ``time_ms``; ``points`` and
``num_points`` recomputed; flag ``"offline"`` added). Deterministic for a given ``config.seed``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree

from .config import TrackerConfig
from .frames import FrameSource
from .geometry import Box, State, points_in_box, wrap_angle
from .ground import ground_mask
from .metrics import voxel_downsample_centres
from .sotracker import FrameEstimate, TrackResult, deskew_points

__all__ = ["OfflineParams", "OfflineProblem", "gather_frame_points", "refine_states", "refine_offline"]


@dataclass(frozen=True)
class OfflineParams:
    """Parameters of the offline refinement (metres, radians)."""

    outer_iterations: int = 8           # shape rebuilds
    gn_iterations: int = 3              # Gauss-Newton steps per shape
    region_scale: float = 1.6           # points gathered around the online box (l, w and h)
    crop_scale: float = 1.15            # data-term points: inside the current box scaled by this
    ground_margin: float = 3.0          # ground planes are fitted on the region grown by this (BEV)
    max_points: int = 250               # per frame, random subset (seeded)
    point_sigma: float = 0.05
    effective_points: float = 40.0
    huber_delta: float = 0.1
    tangent_weight: float = 0.3         # beta: 0 = point-to-plane, 1 = point-to-point
    max_pair_distance: float = 0.8
    normal_neighbours: int = 10
    smooth_sigma_xy: float = 0.03       # per frame^2 (10 Hz: 3 m/s^2 -> 0.03 m)
    smooth_sigma_z: float = 0.02
    smooth_sigma_heading: float = 0.01
    anchor_sigma_xyz: float = 1.0
    anchor_sigma_heading: float = 0.3
    voxel: float = 0.05
    min_shape_points: int = 10
    folds: int = 2                      # frame k registers to the shape of the frames not in fold k % folds
    first_frame_weight: float = 1.0     # data weight of frame 0 (its registration sets the gauge)
    gauge: str = "regauge"              # "regauge": all free, then moved so frame 0 is the start box; "fix_first"


@dataclass
class OfflineProblem:
    """Per-frame point sets (world) for the refinement, and the state trajectory (K, 4)."""

    points: list[np.ndarray]
    states: np.ndarray
    size: np.ndarray


def _box(state: np.ndarray, size: np.ndarray) -> Box:
    return Box(float(state[0]), float(state[1]), float(state[2]), float(wrap_angle(state[3])),
               float(size[0]), float(size[1]), float(size[2]))


def gather_frame_points(source: FrameSource, result: TrackResult, config: TrackerConfig,
                        params: OfflineParams) -> list[np.ndarray]:
    """Ground-removed world points inside each online box scaled ``region_scale`` (one array per frame)."""
    ground = config.ground_params()
    out: list[np.ndarray] = []
    previous = None
    for est in result.estimates:
        frame = source.lidar_frame(est.frame)
        box = est.box
        pts_ego = np.asarray(frame.points_ego)
        reach = 0.5 * max(box.length, box.width) * params.region_scale + params.ground_margin
        getter = getattr(source, "points_world", None)
        use_deskew = (config.deskew and previous is not None and frame.point_time_offset_ns is not None
                      and len(frame.point_time_offset_ns) == len(pts_ego))
        if use_deskew:
            world = deskew_points(pts_ego, frame.point_time_offset_ns, frame.timestamp_ns, frame.world_from_ego,
                                  previous[0], previous[1])
        elif callable(getter):
            world = getter(est.frame)
        else:
            world = frame.points_world()
        previous = (int(frame.timestamp_ns), np.asarray(frame.world_from_ego, dtype=np.float64))
        world = world[np.all(np.isfinite(world), axis=1)]
        local = world[np.all(np.abs(world[:, :2] - box.center[:2]) <= reach, axis=1)]
        if config.ground_removal and len(local) >= 3:
            local = local[~ground_mask(local, ground)]
        out.append(local[points_in_box(local, box, params.region_scale)])
    return out


def _to_object(points: np.ndarray, state: np.ndarray) -> np.ndarray:
    c, s = np.cos(state[3]), np.sin(state[3])
    d = points - state[:3]
    return np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)


def _rebuild_shape(points: list[np.ndarray], states: np.ndarray, size: np.ndarray, voxel: float) -> np.ndarray:
    parts = [_to_object(p[points_in_box(p, _box(s, size), 1.0)], s) for p, s in zip(points, states) if len(p)]
    return voxel_downsample_centres(np.vstack(parts), voxel) if parts else np.zeros((0, 3))


def _normals(shape: np.ndarray, k: int) -> np.ndarray:
    """Unit normals (M, 3) by PCA of each point's k nearest neighbours (smallest-eigenvalue direction)."""
    k = int(min(k, len(shape)))
    if k < 3:
        return np.tile([0.0, 0.0, 1.0], (len(shape), 1))
    _, idx = cKDTree(shape).query(shape, k=k)
    nb = shape[idx] - shape[idx].mean(axis=1, keepdims=True)
    cov = np.einsum("mki,mkj->mij", nb, nb) / k
    _, vectors = np.linalg.eigh(cov)
    return vectors[:, :, 0]


def _second_difference(k: int) -> sp.csr_matrix:
    if k < 3:
        return sp.csr_matrix((0, k))
    rows = np.repeat(np.arange(k - 2), 3)
    cols = (np.arange(k - 2)[:, None] + np.arange(3)[None, :]).ravel()
    vals = np.tile([1.0, -2.0, 1.0], k - 2)
    return sp.csr_matrix((vals, (rows, cols)), shape=(k - 2, k))


class _Solver:
    """Gauss–Newton over all states with the shape (and its normals) held fixed."""

    def __init__(self, points: list[np.ndarray], online: np.ndarray, size: np.ndarray, params: OfflineParams,
                 rng: np.random.Generator) -> None:
        self.params = params
        self.size = size
        self.online = online
        self.k = len(online)
        self.raw = points
        self.rng = rng
        sig = np.array([params.smooth_sigma_xy, params.smooth_sigma_xy, params.smooth_sigma_z, params.smooth_sigma_heading])
        anchor = np.array([params.anchor_sigma_xyz] * 3 + [params.anchor_sigma_heading])
        d = _second_difference(self.k)
        dtd = (d.T @ d).tocsr()
        # variable order: 4 * frame + component
        self.h_prior = (sp.kron(dtd, sp.diags(1.0 / sig**2)) + sp.kron(sp.identity(self.k), sp.diags(1.0 / anchor**2))).tocsr()
        self.d = d
        self.sig = sig
        self.anchor = anchor

    def set_shapes(self, states: np.ndarray) -> bool:
        """Build, for each fold f, the shape from the frames NOT in f (a frame never matches its own points).

        Returns False when a shape is too small to register to."""
        p = self.params
        folds = max(2, int(p.folds))
        self.folds = folds
        self.shapes, self.trees, self.normals = [], [], []
        frame_fold = np.arange(self.k) % folds
        for f in range(folds):
            others = [pts if frame_fold[k] != f else pts[:0] for k, pts in enumerate(self.raw)]
            shape = _rebuild_shape(others, states, self.size, p.voxel)
            if len(shape) < p.min_shape_points:
                return False
            self.shapes.append(shape)
            self.trees.append(cKDTree(shape))
            self.normals.append(_normals(shape, p.normal_neighbours))
        return True

    def _match(self, local: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Distance, matched shape point and its normal for each data point (against its fold's shape)."""
        dist = np.empty(len(local))
        m = np.empty_like(local)
        n = np.empty_like(local)
        fold = self.frame_idx % self.folds
        for f in range(self.folds):
            sel = fold == f
            if not sel.any():
                continue
            d, idx = self.trees[f].query(local[sel], k=1)
            dist[sel], m[sel], n[sel] = d, self.shapes[f][idx], self.normals[f][idx]
        return dist, m, n

    def select(self, states: np.ndarray) -> None:
        """Data points of each frame: inside the current box scaled crop_scale, random subset (fixed for a shape)."""
        p = self.params
        pts, frame_idx = [], []
        for k, (raw, s) in enumerate(zip(self.raw, states)):
            if len(raw) == 0:
                continue
            sel = raw[points_in_box(raw, _box(s, self.size), p.crop_scale)]
            if len(sel) > p.max_points:
                sel = sel[np.sort(self.rng.choice(len(sel), p.max_points, replace=False))]
            pts.append(sel)
            frame_idx.append(np.full(len(sel), k))
        self.pts = np.vstack(pts) if pts else np.zeros((0, 3))
        self.frame_idx = np.concatenate(frame_idx) if frame_idx else np.zeros(0, dtype=np.int64)
        counts = np.bincount(self.frame_idx, minlength=self.k).astype(np.float64)
        scale = np.where(counts > 0, np.minimum(1.0, p.effective_points / np.maximum(counts, 1.0)), 0.0)
        scale[0] *= p.first_frame_weight
        self.point_scale = scale[self.frame_idx] / p.point_sigma**2

    def _data(self, states: np.ndarray, with_jacobian: bool):
        """Data cost and, optionally, per-frame 4x4 Gauss-Newton blocks J'WJ and gradients J'Wr.

        Residual r = A e with e = local - m and A = (1 - beta) n n' + beta I, i.e.
        r = (1 - beta) n (n.e) + beta e.
        """
        p = self.params
        beta = p.tangent_weight
        s = states[self.frame_idx]
        c, si = np.cos(s[:, 3]), np.sin(s[:, 3])
        d = self.pts - s[:, :3]
        lx = c * d[:, 0] + si * d[:, 1]
        ly = -si * d[:, 0] + c * d[:, 1]
        local = np.stack([lx, ly, d[:, 2]], axis=1)
        dist, m, n = self._match(local)
        e = local - m
        ne = np.sum(n * e, axis=1)
        r = (1.0 - beta) * n * ne[:, None] + beta * e
        norm = np.linalg.norm(r, axis=1)
        delta = p.huber_delta
        rho = np.where(norm <= delta, norm**2, 2 * delta * norm - delta**2)
        weight = self.point_scale * (dist <= p.max_pair_distance)
        cost = float(np.sum(weight * rho))
        if not with_jacobian:
            return cost, None, None
        w = weight * np.where(norm <= delta, 1.0, delta / np.maximum(norm, 1e-12))
        # d(local)/d(tx, ty, tz, theta): rows (-c, -s, 0, ly), (s, -c, 0, -lx), (0, 0, -1, 0)
        zeros = np.zeros_like(c)
        jd = np.stack([np.stack([-c, -si, zeros, ly], 1), np.stack([si, -c, zeros, -lx], 1),
                       np.stack([zeros, zeros, -np.ones_like(c), zeros], 1)], axis=1)  # (P, 3, 4)
        nj = np.sum(n[:, :, None] * jd, axis=1)  # (P, 4)
        j = (1.0 - beta) * n[:, :, None] * nj[:, None, :] + beta * jd
        jtj = np.matmul(j.transpose(0, 2, 1), j)  # (P, 4, 4)
        jtr = np.matmul(j.transpose(0, 2, 1), r[:, :, None])[:, :, 0]  # (P, 4)
        blocks = np.stack([np.bincount(self.frame_idx, weights=w * jtj[:, a, b], minlength=self.k)
                           for a in range(4) for b in range(4)], axis=1).reshape(self.k, 4, 4)
        grads = np.stack([np.bincount(self.frame_idx, weights=w * jtr[:, a], minlength=self.k)
                          for a in range(4)], axis=1)
        return cost, blocks, grads

    def _prior(self, states: np.ndarray) -> tuple[float, np.ndarray]:
        diff2 = self.d @ states
        dev = states - self.online
        cost = float(np.sum(diff2**2 / self.sig**2) + np.sum(dev**2 / self.anchor**2))
        grad = (self.d.T @ (diff2 / self.sig**2)) + dev / self.anchor**2
        return cost, grad

    def cost(self, states: np.ndarray) -> float:
        return self._data(states, False)[0] + self._prior(states)[0]

    def step(self, states: np.ndarray) -> np.ndarray:
        cost_d, blocks, grads = self._data(states, True)
        cost_p, grad_p = self._prior(states)
        h = (sp.block_diag(list(blocks), format="csr") + self.h_prior).tocsc()
        g = (grads + grad_p).reshape(-1)
        h = h + sp.diags(1e-9 * (1.0 + h.diagonal()))
        delta = np.zeros(4 * self.k)
        free = np.arange(4 if self.params.gauge == "fix_first" else 0, 4 * self.k)
        delta[free] = -spsolve(h[free][:, free].tocsc(), g[free])
        if not np.all(np.isfinite(delta)):
            return states
        before = cost_d + cost_p
        step = delta.reshape(self.k, 4)
        for _ in range(4):
            trial = states + step
            if self.cost(trial) <= before:
                return trial
            step = step / 2.0
        return states


def _regauge(states: np.ndarray, given_first: np.ndarray) -> np.ndarray:
    """Apply to every pose the same OBJECT-frame correction that maps refined pose 0 onto the given one.

    The joint problem fixes the trajectory only up to where the shape sits in the object frame; the start
    box is given, so pose_k <- pose_k o delta with delta = pose_0^-1 o given_0 (4-DOF).
    """
    d_theta = given_first[3] - states[0, 3]
    c, s = np.cos(states[0, 3]), np.sin(states[0, 3])
    diff = given_first[:3] - states[0, :3]
    d_t = np.array([c * diff[0] + s * diff[1], -s * diff[0] + c * diff[1], diff[2]])
    out = states.copy()
    ck, sk = np.cos(states[:, 3]), np.sin(states[:, 3])
    out[:, 0] += ck * d_t[0] - sk * d_t[1]
    out[:, 1] += sk * d_t[0] + ck * d_t[1]
    out[:, 2] += d_t[2]
    out[:, 3] += d_theta
    return out


def refine_states(points: list[np.ndarray], online_states: np.ndarray, size: np.ndarray,
                  params: OfflineParams = OfflineParams(), seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Jointly refined states (K, 4) and the shape rebuilt from them (object frame), given each frame's
    world points (``points[k]``) and the online states; state 0 (the given start box) is kept exactly,
    by re-gauging after each solve (see :func:`_regauge`)."""
    online = np.asarray(online_states, dtype=np.float64).copy()
    online[:, 3] = np.unwrap(online[:, 3])
    states = online.copy()
    size = np.asarray(size, dtype=np.float64)
    if len(states) < 2:
        return states, _rebuild_shape(points, states, size, params.voxel)
    solver = _Solver(points, online, size, params, np.random.default_rng(seed))
    for _ in range(params.outer_iterations):
        if not solver.set_shapes(states):
            break
        solver.select(states)
        if len(solver.pts) == 0:
            break
        for _ in range(params.gn_iterations):
            states = solver.step(states)
        if params.gauge == "regauge":
            states = _regauge(states, online[0])
    out = states.copy()
    out[:, 3] = wrap_angle(out[:, 3])
    return out, _rebuild_shape(points, states, size, params.voxel)


def refine_offline(source: FrameSource, result: TrackResult, config: TrackerConfig | None = None,
                   params: OfflineParams | None = None) -> TrackResult:
    """Offline-refined copy of an online ``result`` (see the module docstring)."""
    config = config or result.config
    params = params or OfflineParams()
    points = gather_frame_points(source, result, config, params)
    online = np.array([e.state.to_array() for e in result.estimates])
    states, shape = refine_states(points, online, np.asarray(result.size), params, seed=config.seed)
    estimates: list[FrameEstimate] = []
    for est, pts, s in zip(result.estimates, points, states):
        box = _box(s, result.size)
        obj = pts[points_in_box(pts, box, 1.0)]
        flags = tuple(dict.fromkeys(list(est.flags) + ["offline"]))
        estimates.append(dataclasses.replace(est, state=State.from_array(box.to_array()[:4]), box=box,
                                             num_points=len(obj), points=obj, flags=flags))
    return TrackResult(estimates, np.asarray(result.size), shape, config)
