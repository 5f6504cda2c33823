"""SOTracker: the streaming tracker (``Tracker.start`` / ``Tracker.step``) and ``track()``.

Per frame k (the paper's Algorithms 1 and 2):

1. predict S^_k = S_{k-1} + dS_prior;
2. take the sweep's points near the prediction (a cheap radius test in the EGO frame first, so only
   those points are moved to the world — de-skewed if asked), and remove the ground there (GPF);
3. outer loop: crop the local points with S^_k scaled gamma_in, pair the ICP source (previous-frame
   object points + sub-shape, moved by the current estimate) with the crop by 1-NN, pair the shape
   (placed likewise) with the crop and keep RANSAC's inliers, then minimise the loss over
   [dx, dy, dz, dtheta] (Levenberg–Marquardt, analytic Jacobians); stop when the update is tiny;
4. keep the object points, grow the shape at key frames and update the motion prior.

Frame 1 has no motion prior: an ICP-only search in the start box scaled 3.0 precedes the normal step.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .association import NearestNeighbors, random_subset, ransac_rigid_2d
from .config import TrackerConfig
from .frames import FrameSource, LidarFrame
from .geometry import Box, State, invert_transform, points_in_box, transform_points, wrap_angle
from .ground import ground_mask
from .motion import MotionPrior
from .shape import ShapeModel, SubShape, to_object_frame, to_world_frame
from .solver import solve
from .terms import ResidualBlock, apply_motion, motion_consistency_block, motion_prior_block, point_pair_block

__all__ = ["FrameEstimate", "TrackResult", "Tracker", "track", "deskew_points"]


@dataclass(frozen=True)
class FrameEstimate:
    """The tracker's output for one frame (world frame).

    ``num_points``: object points (ground removed) in the estimated box; ``points``: those points (N, 3);
    ``quality``: 0..1 (share of those points that the registration explains, scaled down when sparse);
    ``flags``: e.g. "init", "no_points", "prior_only", "low_points", "nan_points", "no_shape_inliers",
    "no_sweep" (the frame has no sweep: a prediction only, see :meth:`Tracker.step`).
    """

    frame: int
    state: State
    box: Box
    num_points: int
    quality: float
    flags: tuple[str, ...]
    time_ms: float
    points: np.ndarray = field(repr=False)


@dataclass
class TrackResult:
    """A whole track: one estimate per frame from ``start`` to ``end`` (the start frame is the init box)."""

    estimates: list[FrameEstimate]
    size: np.ndarray          # (length, width, height)
    shape: np.ndarray         # (M, 3) object-frame points
    config: TrackerConfig

    @property
    def frames(self) -> list[int]:
        return [e.frame for e in self.estimates]

    @property
    def states(self) -> list[State]:
        return [e.state for e in self.estimates]

    @property
    def boxes(self) -> list[Box]:
        return [e.box for e in self.estimates]

    def diagnostics(self) -> list[dict]:
        return [{"frame": e.frame, "num_points": e.num_points, "quality": e.quality, "flags": list(e.flags),
                 "time_ms": e.time_ms} for e in self.estimates]


def _axis_angle(rotation: np.ndarray) -> tuple[np.ndarray, float]:
    """Unit axis and angle of a 3x3 rotation."""
    angle = float(np.arccos(np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0)))
    axis = np.array([rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0], rotation[1, 0] - rotation[0, 1]])
    norm = np.linalg.norm(axis)
    if norm < 1e-12:
        return np.array([0.0, 0.0, 1.0]), 0.0
    return axis / norm, angle


def deskew_points(points_ego: np.ndarray, offsets_ns: np.ndarray, timestamp_ns: int, world_from_ego: np.ndarray,
                  previous_timestamp_ns: int, previous_world_from_ego: np.ndarray) -> np.ndarray:
    """World points with each point moved by the ego pose at its capture time.

    The pose at time t is interpolated between the previous frame's pose and this frame's (SLERP of the
    rotation, linear translation); times outside the interval extrapolate.
    """
    dt = float(timestamp_ns - previous_timestamp_ns)
    s = 1.0 + np.asarray(offsets_ns, dtype=np.float64) / dt if dt != 0 else np.ones(len(points_ego))
    r0, r1 = previous_world_from_ego[:3, :3], world_from_ego[:3, :3]
    t0, t1 = previous_world_from_ego[:3, 3], world_from_ego[:3, 3]
    axis, angle = _axis_angle(r0.T @ r1)
    p = np.asarray(points_ego, dtype=np.float64)
    a = s * angle
    ca, sa = np.cos(a)[:, None], np.sin(a)[:, None]
    rotated = p * ca + np.cross(axis, p) * sa + np.outer(p @ axis, axis) * (1.0 - ca)  # Rodrigues
    return rotated @ r0.T + t0 + s[:, None] * (t1 - t0)


class _Target:
    """A frame's local (non-ground) points with one kd-tree and lazily computed normals."""

    def __init__(self, points: np.ndarray) -> None:
        self.nn = NearestNeighbors(points)
        self.normals = np.zeros((len(points), 3))
        self.has_normal = np.zeros(len(points), dtype=bool)


class _Anderson:
    """Anderson acceleration of the outer (ICP-style) fixed-point iteration x <- F(x) (AA-ICP).

    ``step(x, F(x) - x)`` returns the next iterate: the plain step while the history is short or the
    extrapolation jumps implausibly far from the plain step (0.5 m, 0.15 rad), else the Anderson mix.
    """

    def __init__(self, depth: int) -> None:
        self.depth = depth
        self.xs: list[np.ndarray] = []
        self.fs: list[np.ndarray] = []

    def step(self, x: np.ndarray, f: np.ndarray) -> np.ndarray:
        self.xs.append(x.copy())
        self.fs.append(f.copy())
        self.xs, self.fs = self.xs[-(self.depth + 1):], self.fs[-(self.depth + 1):]
        plain = x + f
        if len(self.xs) < 2:
            return plain
        dx = np.diff(np.array(self.xs), axis=0).T   # (4, m)
        df = np.diff(np.array(self.fs), axis=0).T
        gamma, *_ = np.linalg.lstsq(df, f, rcond=None)
        mixed = plain - (dx + df) @ gamma
        jump = np.abs(mixed - plain)
        if not np.isfinite(mixed).all() or np.any(jump > np.array([0.5, 0.5, 0.3, 0.15])):
            return plain
        return mixed


def _ground_height(ground: np.ndarray, centre_xy: np.ndarray, box: Box, min_points: int = 20) -> float | None:
    """Height of the road under ``centre_xy``: a plane z = a x + b y + c through the ground points around the
    box (outside its footprint, within 3 m), refitted without outliers; None with too few points."""
    if len(ground) < min_points:
        return None
    d = ground[:, :2] - centre_xy
    ca, sa = np.cos(box.heading), np.sin(box.heading)
    u = np.abs(d @ np.array([ca, sa])) - 0.5 * box.length
    v = np.abs(d @ np.array([-sa, ca])) - 0.5 * box.width
    near = ground[(u <= 3.0) & (v <= 3.0)]
    if len(near) < min_points:
        return None
    keep = np.abs(near[:, 2] - np.median(near[:, 2])) < 0.5  # sub-ground noise is classified ground too
    for _ in range(2):
        if keep.sum() < min_points:
            return None
        a = np.column_stack([near[keep, 0] - centre_xy[0], near[keep, 1] - centre_xy[1], np.ones(keep.sum())])
        coef, *_ = np.linalg.lstsq(a, near[keep, 2], rcond=None)
        residual = near[:, 0:2] - centre_xy
        pred = residual @ coef[:2] + coef[2]
        keep = np.abs(near[:, 2] - pred) < 0.15
    return float(coef[2])


def _box_moved(box: Box, x: np.ndarray) -> Box:
    return Box(box.x + x[0], box.y + x[1], box.z + x[2], float(wrap_angle(box.heading + x[3])),
               box.length, box.width, box.height)


class Tracker:
    """Online SOTracker. ``start(frame, box)`` once, then ``step(frame)`` for each following frame."""

    def __init__(self, config: TrackerConfig | None = None) -> None:
        self.config = config or TrackerConfig()
        c = self.config
        self.ground_params = c.ground_params()
        self._started = False

    # ------------------------------------------------------------------ points
    def _local_points(self, frame: LidarFrame, box: Box, scale: float) -> tuple[np.ndarray, list[str]]:
        """Non-ground world points near ``box`` (BEV radius of the box scaled by ``scale`` plus a margin)."""
        c = self.config
        flags: list[str] = []
        self._ground_points = np.zeros((0, 3))
        pts = np.asarray(frame.points_ego)
        if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0:
            return np.zeros((0, 3)), flags
        ego_from_world = invert_transform(np.asarray(frame.world_from_ego, dtype=np.float64))
        centre_ego = transform_points(ego_from_world, box.center[None])[0]
        radius = 0.5 * float(np.hypot(box.length, box.width)) * (scale + 0.5) + c.gpf_margin
        deskew = (c.deskew and frame.point_time_offset_ns is not None and self._previous_pose is not None
                  and len(frame.point_time_offset_ns) == len(pts))
        if deskew:
            radius += float(np.linalg.norm(frame.world_from_ego[:3, 3] - self._previous_pose[1][:3, 3])) + 0.5
        # cheap BEV radius test in the ego frame on the whole sweep (contiguous ops only)
        diff = pts - centre_ego.astype(pts.dtype)
        near = (diff * diff) @ np.array([1.0, 1.0, 0.0], dtype=pts.dtype) <= radius * radius
        if not np.isfinite(pts).all():
            flags.append("nan_points")
            near &= np.isfinite(pts).all(axis=1)
        idx = np.flatnonzero(near)
        local = pts[idx].astype(np.float64)
        if deskew:
            prev_t, prev_pose = self._previous_pose
            world = deskew_points(local, np.asarray(frame.point_time_offset_ns)[idx], frame.timestamp_ns,
                                  frame.world_from_ego, prev_t, prev_pose)
        else:
            world = transform_points(frame.world_from_ego, local)
        # ground removal on the region the search can reach: the box scaled by ``scale``, grown by a margin
        ca, sa = np.cos(box.heading), np.sin(box.heading)
        d = world[:, :2] - box.center[:2]
        u = np.abs(d @ np.array([ca, sa]))
        v = np.abs(d @ np.array([-sa, ca]))
        gscale = scale + 0.5
        world = world[(u <= 0.5 * box.length * gscale + c.gpf_margin) & (v <= 0.5 * box.width * gscale + c.gpf_margin)]
        if c.ground_removal and len(world) >= 3:
            is_ground = ground_mask(world, self.ground_params)
            self._ground_points = world[is_ground]
            world = world[~is_ground]
        # keep only what a search box can contain (the box moves a little during the outer loop)
        d = world[:, :2] - box.center[:2]
        u = np.abs(d @ np.array([ca, sa]))
        v = np.abs(d @ np.array([-sa, ca]))
        slack = 1.0
        world = world[(u <= 0.5 * box.length * scale + slack) & (v <= 0.5 * box.width * scale + slack)]
        return world, flags

    # ------------------------------------------------------------------ API
    def start(self, frame: LidarFrame, box: Box, previous_pose: tuple[int, np.ndarray] | None = None) -> FrameEstimate:
        """Begin a track at ``frame`` with the (world-frame) ``box``.

        ``previous_pose``: (timestamp_ns, world_from_ego) of the frame before, used only to de-skew.
        """
        t0 = time.perf_counter()
        c = self.config
        values = box.to_array()
        if not np.isfinite(values).all() or min(box.length, box.width, box.height) <= 0:
            raise ValueError(f"init box must be finite with positive size, got {box}")
        if not frame.has_sweep:
            raise ValueError(f"cannot start a track at frame {frame.index}: it has no sweep")
        self.rng = np.random.default_rng(c.seed)
        self.first_box = box
        self.box = box
        self.prior = MotionPrior(c.alpha, c.prior_frame)
        self.shape = ShapeModel(c.voxel_size)
        self.subshape = SubShape(c.subshape_frames if c.use_subshape else 0, c.voxel_size)
        self.steps = 0
        self._coasting = 0
        self._shape_nn: NearestNeighbors | None = None
        self._shape_nn_size = -1
        self._previous_pose = previous_pose
        self._last_timestamp_ns = int(frame.timestamp_ns)
        self._nominal_dt_ns: int | None = None  # the frame interval the motion prior is expressed per
        local, flags = self._local_points(frame, box, max(c.first_search_scale, c.search_scale))
        height = _ground_height(self._ground_points, box.center[:2], box)
        self._ground_offset = None if height is None else box.z - height
        self._finish_frame(frame, box, local, keyframe=True)
        self._started = True
        obj = local[points_in_box(local, box, 1.0)]
        if len(obj) == 0:
            flags.append("no_points")
        est = FrameEstimate(frame.index, box.state, box, len(obj), 1.0, tuple(["init"] + flags),
                            (time.perf_counter() - t0) * 1e3, obj)
        return est

    def shape_points(self) -> np.ndarray:
        """The aggregated shape (object frame)."""
        return self.shape.points.copy()

    def _finish_frame(self, frame: LidarFrame, box: Box, local: np.ndarray, keyframe: bool) -> np.ndarray:
        c = self.config
        self.prev_points = local[points_in_box(local, box, c.crop_scale)]
        obj_world = local[points_in_box(local, box, c.shape_crop_scale)]
        obj = to_object_frame(obj_world, box)
        self.subshape.add(obj)
        if keyframe:
            self.shape.add(obj)
        self._previous_pose = (int(frame.timestamp_ns), np.asarray(frame.world_from_ego, dtype=np.float64))
        return obj_world

    def _normals(self, target: _Target, idx: np.ndarray) -> np.ndarray:
        """Unit normals (zeros where undefined) of local points ``idx``, computed on demand and cached."""
        c = self.config
        missing = np.unique(idx[~target.has_normal[idx]])
        if len(missing):
            k = min(c.normal_neighbors, len(target.nn))
            dist, nbr = target.nn.tree.query(target.nn.target[missing], k=k, distance_upper_bound=c.normal_radius)
            dist = dist.reshape(len(missing), k)
            nbr = nbr.reshape(len(missing), k)
            valid = np.isfinite(dist)
            nbr = np.where(valid, nbr, 0)
            pts = target.nn.target[nbr]                                   # (m, k, 3)
            w = valid[..., None].astype(np.float64)
            count = w.sum(axis=1)                                         # (m, 1)
            mean = (pts * w).sum(axis=1) / np.maximum(count, 1.0)
            d = (pts - mean[:, None]) * w
            cov = np.einsum("mki,mkj->mij", d, d)
            evals, evecs = np.linalg.eigh(cov)
            normal = evecs[:, :, 0]
            # a normal needs enough neighbours and a flat neighbourhood (smallest eigenvalue well below the next)
            ok = (count[:, 0] >= 4) & (evals[:, 0] < 0.3 * evals[:, 1])
            target.normals[missing] = np.where(ok[:, None], normal, 0.0)
            target.has_normal[missing] = True
        return target.normals[idx]

    def _pairs(self, x: np.ndarray, source: np.ndarray, target: _Target, mask: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """1-NN pairs (moved source -> local points); pairs whose target is outside the crop are dropped."""
        moved = apply_motion(x, source, self.box.center)
        dist, idx = target.nn.query(moved)
        keep = mask[idx]
        return source[keep], idx[keep], dist[keep], moved[keep]

    def _estimate(self, target: _Target, x0: np.ndarray, scale: float, outer: int, icp_only: bool,
                  mp_reference: np.ndarray | None, flags: list[str]) -> tuple[np.ndarray, dict]:
        """Outer loop of Algorithm 2 from motion ``x0``; returns the motion and diagnostics."""
        c = self.config
        prev = self.box
        pivot = prev.center
        local = target.nn.target
        source = self.prev_points
        sub = self.subshape.points
        if len(sub):
            source = np.vstack([source, to_world_frame(sub, prev)])
        source = random_subset(source, c.max_points, self.rng)
        shape_src = np.zeros((0, 3))
        if not icp_only and c.use_shape and c.weight_shape > 0:
            model = self.shape.points if c.shape_update else self._first_shape
            shape_src = random_subset(to_world_frame(model, prev), c.max_points, self.rng)
        x = np.asarray(x0, dtype=np.float64).copy()
        reference = None if mp_reference is None else mp_reference.copy()
        info = {"crop": 0, "icp_pairs": 0, "shape_inliers": 0, "iterations": 0}
        plane = c.icp_metric == "plane"
        ransac_seed = int(self.rng.integers(2**62))
        accel = _Anderson(c.anderson_depth)
        for it in range(outer):
            info["iterations"] = it + 1
            mask = points_in_box(local, _box_moved(prev, x), scale)
            info["crop"] = int(mask.sum())
            if info["crop"] < c.min_target_points:  # too few points to register against: no data terms
                info["icp_pairs"] = info["shape_inliers"] = 0
                break
            fixed: list = []  # (name, source, target, normals, weight, normaliser floor)
            data_norm = c.data_norm_min  # few pairs: the data terms weigh less against the motion terms
            info["icp_pairs"] = info["shape_inliers"] = 0
            if c.weight_icp > 0 and len(source) >= c.min_points:
                src, idx, dist, _ = self._pairs(x, source, target, mask)
                if c.max_pair_distance > 0:
                    keep = dist <= c.max_pair_distance
                    src, idx = src[keep], idx[keep]
                if len(src) >= c.min_points:
                    normals = self._normals(target, idx) if plane else None
                    fixed.append(("icp", src, local[idx], normals, c.weight_icp, data_norm))
                    info["icp_pairs"] = len(src)
            if len(shape_src) >= c.min_points:
                src, idx, _, moved = self._pairs(x, shape_src, target, mask)
                if c.use_ransac:
                    keep = np.zeros(len(src), dtype=bool)
                    if len(src) >= c.ransac_min_inliers:
                        # the same hypotheses every outer iteration: the loop can settle
                        keep = ransac_rigid_2d(moved[:, :2], local[idx, :2], np.random.default_rng(ransac_seed),
                                               max_iterations=c.ransac_max_iterations, confidence=c.ransac_confidence,
                                               sample_size=c.ransac_sample_size,
                                               threshold=c.ransac_inlier_threshold,
                                               max_score_pairs=c.ransac_score_pairs).inliers
                    src, idx = (src[keep], idx[keep]) if keep.sum() >= c.ransac_min_inliers else (src[:0], idx[:0])
                if len(src) >= c.min_points:
                    normals = self._normals(target, idx) if plane else None
                    fixed.append(("shape", src, local[idx], normals, c.weight_shape, data_norm))
                    info["shape_inliers"] = len(src)
            if not fixed:
                break
            use_priors = not icp_only

            def blocks_at(xx: np.ndarray) -> list[ResidualBlock]:
                blocks = [point_pair_block(name, xx, s, t, pivot, w, n, c.plane_point_weight, norm)
                          for name, s, t, n, w, norm in fixed]
                if use_priors and c.weight_mc > 0:
                    blocks.append(motion_consistency_block(xx, prev.heading, c.weight_mc, c.symmetric_mc))
                if use_priors and c.weight_mp > 0 and reference is not None:
                    blocks.append(motion_prior_block(xx, reference, c.weight_mp))
                return blocks

            result = solve(blocks_at, x, max_iterations=c.solver_iterations, tolerance=0.1 * c.convergence_tolerance)
            residual = result.x - x
            change = float(np.max(np.abs(residual)))
            x_next = result.x
            if c.anderson_depth > 0 and not icp_only:
                x_next = accel.step(x, residual)
            x = x_next
            if c.mp_reference == "iteration" and reference is not None:
                reference = x.copy()
            if change < c.convergence_tolerance:
                break
        if not icp_only and c.use_shape and c.weight_shape > 0 and info["shape_inliers"] == 0:
            flags.append("no_shape_inliers")
        return x, info

    def step(self, frame: LidarFrame) -> FrameEstimate:
        """Estimate the object's state in ``frame`` (the frame after the previous call).

        The motion prior is scaled by the elapsed time over the nominal frame interval (the first
        step's). A frame without a sweep (``frame.has_sweep`` False) is a prediction only, flagged
        ``no_sweep``.
        """
        if not self._started:
            raise RuntimeError("Tracker.step called before Tracker.start")
        t0 = time.perf_counter()
        c = self.config
        prev = self.box
        dt_ns = int(frame.timestamp_ns) - self._last_timestamp_ns
        self._last_timestamp_ns = int(frame.timestamp_ns)
        if self._nominal_dt_ns is None and dt_ns > 0:
            self._nominal_dt_ns = dt_ns
        # the prior is a motion per nominal frame interval: scale it by the elapsed time
        dt_scale = dt_ns / self._nominal_dt_ns if self._nominal_dt_ns and dt_ns > 0 else 1.0
        if not frame.has_sweep:
            return self._predict_only(frame, prev, dt_scale, t0)
        self.steps += 1
        flags: list[str] = []
        first = self.steps == 1
        if first:
            self._first_shape = self.shape.points.copy()
        prior = self.prior.predict(prev.heading) * dt_scale
        # coasting (no data) keeps the velocity but lets the turn rate die out
        prior[3] *= c.coast_yaw_decay ** self._coasting
        search_scale = c.first_search_scale if first else c.search_scale
        reach_box = _box_moved(prev, prior)
        local, point_flags = self._local_points(frame, reach_box, max(search_scale, c.search_scale))
        flags += point_flags
        x = prior.copy()
        info: dict = {"crop": 0}
        if len(local) == 0 or not points_in_box(local, reach_box, search_scale).any():
            flags += ["no_points", "prior_only"]
        else:
            target = _Target(local)
            if first:
                x, info = self._estimate(target, x, c.first_search_scale, c.first_icp_iterations, True, None, flags)
                reference = x.copy()
            else:
                reference = prior
            x, info = self._estimate(target, x, c.search_scale, c.outer_iterations, False, reference, flags)
            if info.get("icp_pairs", 0) == 0 and info.get("shape_inliers", 0) == 0:
                flags += ["low_points", "prior_only"]
                x = np.zeros(4) if first else prior.copy()
        if not np.isfinite(x).all():
            flags.append("prior_only")
            x = prior.copy()
        if c.max_yaw_change > 0 and not first and abs(x[3] - prior[3]) > c.max_yaw_change:
            flags.append("yaw_clamped")  # a vehicle cannot turn that suddenly: keep the prior's turn rate +- the cap
            x[3] = prior[3] + np.sign(x[3] - prior[3]) * c.max_yaw_change
        if c.max_speed_change > 0 and not first and self.steps > 2:
            # a vehicle's velocity changes little in 0.1 s: cap the deviation from the prediction in the box frame
            ch, sh = np.cos(prev.heading), np.sin(prev.heading)
            dev = x[:2] - prior[:2]
            along, across = ch * dev[0] + sh * dev[1], -sh * dev[0] + ch * dev[1]
            cap_along, cap_across = c.max_speed_change, 0.5 * c.max_speed_change
            if abs(along) > cap_along or abs(across) > cap_across:
                flags.append("motion_clamped")
                along, across = np.clip(along, -cap_along, cap_along), np.clip(across, -cap_across, cap_across)
                x[:2] = prior[:2] + np.array([ch * along - sh * across, sh * along + ch * across])
        coasting = "prior_only" in flags
        if c.min_quality > 0 and not coasting and not first:
            explained, _ = self._explained(local, _box_moved(prev, self._with_z(x, prev)))
            if explained < c.min_quality:  # a poor fit (clutter, a few stray points): trust the prior instead
                flags += ["low_quality", "prior_only"]
                coasting = True
                x = prior.copy()
        x = self._with_z(x, prev)
        x[3] = wrap_angle(x[3])
        box = _box_moved(prev, x)
        quality = self._quality(local, box)
        obj_world = self._finish_frame(frame, box, local, keyframe=c.shape_update and self.steps % c.keyframe_interval == 0)
        if 0 < len(obj_world) < c.min_points:
            flags.append("low_points")
        if coasting:
            self._coasting += 1  # the prior is not updated with its own prediction
        else:
            self._coasting = 0
            self.prior.update(x / dt_scale, prev.heading)
        self.box = box
        return FrameEstimate(frame.index, box.state, box, len(obj_world), quality, tuple(dict.fromkeys(flags)),
                             (time.perf_counter() - t0) * 1e3, obj_world)

    def _predict_only(self, frame: LidarFrame, prev: Box, dt_scale: float, t0: float) -> FrameEstimate:
        """A frame without a sweep: move the box by the prior over the elapsed time, measure nothing.

        The previous object points move with the box (they seed the next frame's registration); the
        shape, sub-shape and motion prior are left as they are. Flags: ``no_sweep``, ``prior_only``.
        """
        prior = self.prior.predict(prev.heading) * dt_scale
        prior[3] *= self.config.coast_yaw_decay ** self._coasting
        box = _box_moved(prev, prior)
        self.prev_points = to_world_frame(to_object_frame(self.prev_points, prev), box)
        self._previous_pose = (int(frame.timestamp_ns), np.asarray(frame.world_from_ego, dtype=np.float64))
        self._coasting += 1
        self.box = box
        return FrameEstimate(frame.index, box.state, box, 0, 0.0, ("no_sweep", "prior_only"),
                             (time.perf_counter() - t0) * 1e3, np.zeros((0, 3)))

    def _with_z(self, x: np.ndarray, prev: Box) -> np.ndarray:
        """The motion with dz set by ``z_mode`` ("ground": keep the start height above the local road)."""
        x = x.copy()
        c = self.config
        if c.z_mode == "fixed":
            x[2] = 0.0
        elif c.z_mode == "ground" and self._ground_offset is not None:
            height = _ground_height(self._ground_points, prev.center[:2] + x[:2], prev)
            if height is not None:
                x[2] = height + self._ground_offset - prev.z
        return x

    def _explained(self, local: np.ndarray, box: Box) -> tuple[float, int]:
        """Share of the object points in ``box`` within 0.2 m of the shape placed there, and their number."""
        obj = to_object_frame(local[points_in_box(local, box, 1.0)], box)
        if len(obj) == 0 or len(self.shape) == 0:
            return 0.0, len(obj)
        if self._shape_nn is None or self._shape_nn_size != len(self.shape):
            self._shape_nn = NearestNeighbors(self.shape.points)
            self._shape_nn_size = len(self.shape)
        dist, _ = self._shape_nn.query(obj)
        return float((dist <= 0.2).mean()), len(obj)

    def _quality(self, local: np.ndarray, box: Box) -> float:
        """Share of the frame's object points within 0.2 m of the shape placed at ``box``, damped when sparse."""
        explained, count = self._explained(local, box)
        return float(np.clip(explained * min(1.0, count / 20.0), 0.0, 1.0))


def track(source: FrameSource, init_box: Box, start: int = 0, end: int | None = None,
          config: TrackerConfig | None = None, progress=None) -> TrackResult:
    """Track from ``init_box`` (world frame, at frame ``start``) through frame ``end`` (inclusive, default: last).

    ``progress``: optional callable(iterable) -> iterable (e.g. tqdm) wrapping the frame loop.
    """
    config = config or TrackerConfig()
    n = len(source)
    end = n - 1 if end is None else end
    if not 0 <= start < n or not start <= end < n:
        raise IndexError(f"frames {start}..{end} are outside 0..{n - 1}")
    tracker = Tracker(config)
    previous_pose = None
    if config.deskew and start > 0:
        prev = source.lidar_frame(start - 1)
        previous_pose = (int(prev.timestamp_ns), np.asarray(prev.world_from_ego, dtype=np.float64))
    estimates = [tracker.start(source.lidar_frame(start), init_box, previous_pose)]
    frames = range(start + 1, end + 1)
    for k in (progress(frames) if progress else frames):
        estimates.append(tracker.step(source.lidar_frame(k)))
    return TrackResult(estimates, init_box.size, tracker.shape_points(), config)
