"""SOTracker: the streaming tracker (``Tracker.start`` / ``Tracker.step``) and ``track()``.

Per frame k (the paper's Algorithms 1 and 2):

1. predict S^_k = S_{k-1} + dS_prior (the motion model, tracker/motion_filter.py: the moving average, per
   frame or per second of elapsed time, or a CTRV filter);
2. take the sweep's points near the prediction (a cheap radius test in the EGO frame first, so only
   those points are moved to the world — de-skewed if asked), and remove the ground there (GPF);
3. outer loop: crop the local points with S^_k scaled gamma_in, pair the ICP source (previous-frame
   object points + sub-shape, moved by the current estimate) with the crop by 1-NN, pair the shape
   (placed likewise) with the crop and keep RANSAC's inliers, then minimise the loss over
   [dx, dy, dz, dtheta] (Levenberg–Marquardt, analytic Jacobians); stop when the update is tiny;
4. keep the object points, grow the shape at key frames and update the motion model; z by ``z_mode``.

Frame 1 has no motion prior: an ICP-only search in the start box scaled 3.0 precedes the normal step, or, with
``first_hypotheses``, several ICP-only searches from motions along the heading, the one explaining the most
points winning (tracker/first_frame.py), or the authors' Finder (``first_search="finder"``, tracker/finder.py).

With ``weight_det > 0`` (Det+SOT) and the frame's detections passed to ``step``, the detection associated
with the prediction S^_k (:func:`tracker.detection.associate_detection`) adds the Detection term to the
loss of step 3; a frame without points then takes the motion from the detection and the prior.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from .association import NearestNeighbors, random_subset, ransac_rigid_2d
from .config import TrackerConfig
from .finder import finder_icp, resample
from .detection import Detections, FrameDetections, associate_detection, detection_motion
from .frames import FrameSource, LidarFrame
from .geometry import Box, State, invert_transform, points_in_box, transform_points, wrap_angle
from .first_frame import explained_points, motion_hypotheses
from .ground import ground_mask
from .motion_filter import AverageMotion, CTRVMotion, CTRVParams, HeightFilter
from .shape import ShapeModel, SubShape, to_object_frame, to_world_frame
from .solver import solve
from .sweep_ground import cached_sweep_ground_mask
from .terms import (PairMoments, ResidualBlock, apply_motion, detection_block, motion_consistency_block,
                    motion_prior_block, point_pair_block)

__all__ = ["FrameEstimate", "LocalCrop", "TrackResult", "Tracker", "track", "deskew_points"]


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


@dataclass(frozen=True)
class LocalCrop:
    """The ground-removed world points the last step searched: every finite, non-ground point of sweep
    ``frame`` whose BEV position lies in the rectangle centred on ``box`` (its heading) with half extents
    ``half_length`` x ``half_width`` (no height limit), in the sweep's order. The fixed-lag window takes its
    region from it when the region fits inside (:func:`tracker.offline.frame_region_points`)."""

    frame: int
    points: np.ndarray = field(repr=False)
    box: Box
    half_length: float
    half_width: float
    ground: str  # "none" (nothing removed) or "sweep" (the cached whole-sweep mask); else not reusable

    def contains(self, box: Box, scale: float, tolerance: float = 1e-3) -> bool:
        """Whether ``box`` scaled ``scale`` (BEV) lies inside the rectangle, ``tolerance`` inside its edges."""
        c, s = np.cos(box.heading), np.sin(box.heading)
        hl, hw = 0.5 * box.length * scale, 0.5 * box.width * scale
        corners = np.array([[hl, hw], [hl, -hw], [-hl, hw], [-hl, -hw]]) @ np.array([[c, s], [-s, c]])
        d = corners + (box.center[:2] - self.box.center[:2])
        cc, ss = np.cos(self.box.heading), np.sin(self.box.heading)
        u = np.abs(d @ np.array([cc, ss]))
        v = np.abs(d @ np.array([-ss, cc]))
        return bool(np.all(u <= self.half_length - tolerance) and np.all(v <= self.half_width - tolerance))


@dataclass
class TrackResult:
    """A whole track: one estimate per frame from ``start`` to ``end`` (the start frame is the init box).

    ``mode``: "online" (each state final when its frame arrives), "lag" (final ``lag`` frames later: fixed-lag
    refinement, tracker/fixed_lag.py) or "offline" (refined with the whole sequence, tracker/offline.py)."""

    estimates: list[FrameEstimate]
    size: np.ndarray          # (length, width, height)
    shape: np.ndarray         # (M, 3) object-frame points
    config: TrackerConfig
    mode: str = "online"
    lag: int = 0

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


_NOMINAL_DT = 0.1  # s: the frame interval assumed when timestamps do not advance


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
        self.last_crop: LocalCrop | None = None  # the points the last start/step searched (see LocalCrop)

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
        # cheap BEV radius test in the ego frame on the whole sweep (x and y only, the sweep's precision)
        dx = pts[:, 0] - pts.dtype.type(centre_ego[0])
        dy = pts[:, 1] - pts.dtype.type(centre_ego[1])
        dx *= dx
        dy *= dy
        dx += dy
        near = dx <= radius * radius
        if not np.isfinite(pts).all():
            flags.append("nan_points")
            near &= np.isfinite(pts).all(axis=1)
        sweep_ground = c.ground_removal and c.ground_scope == "sweep"
        idx = np.flatnonzero(near)
        local = pts[idx].astype(np.float64)
        is_ground = None
        if sweep_ground:  # upstream: one plane for the whole sweep (sensor frame), its ground removed below
            is_ground = cached_sweep_ground_mask(pts, *c.sweep_ground_args())[idx]
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
        region = (u <= 0.5 * box.length * gscale + c.gpf_margin) & (v <= 0.5 * box.width * gscale + c.gpf_margin)
        world = world[region]
        if is_ground is not None:
            is_ground = is_ground[region]
        elif c.ground_removal and not sweep_ground and len(world) >= 3:
            is_ground = ground_mask(world, self.ground_params)
        if is_ground is not None:
            road = is_ground
            if c.height_road == "none":
                road = np.zeros(len(world), dtype=bool)
            elif sweep_ground and c.height_road == "local" and c.z_mode in ("filter", "ground") and len(world) >= 3:
                # the road under the box for the height from the local planes: one plane per sweep serves the
                # removal, but can miss a far road's grade and camber by more than the height's 5 cm
                road = ground_mask(world, self.ground_params)
            self._ground_points = world[road]
            world = world[~is_ground]
        # keep only what a search box can contain (the box moves a little during the outer loop)
        d = world[:, :2] - box.center[:2]
        u = np.abs(d @ np.array([ca, sa]))
        v = np.abs(d @ np.array([-sa, ca]))
        slack = 1.0
        half_length, half_width = 0.5 * box.length * scale + slack, 0.5 * box.width * scale + slack
        world = world[(u <= half_length) & (v <= half_width)]
        ground = "none" if not c.ground_removal else "sweep" if sweep_ground else "local"
        self.last_crop = LocalCrop(frame.index, world, box, half_length, half_width, ground)
        return world, flags

    # ------------------------------------------------------------------ API
    def start(self, frame: LidarFrame, box: Box, previous_pose: tuple[int, np.ndarray] | None = None,
              initial_motion: np.ndarray | None = None) -> FrameEstimate:
        """Begin a track at ``frame`` with the (world-frame) ``box``.

        ``previous_pose``: (timestamp_ns, world_from_ego) of the frame before, used only to de-skew.
        ``initial_motion``: a known per-frame motion [dx, dy, dz, dtheta] (world frame), e.g. from associated
        detections: the motion prior starts from it instead of zero (frame 1's search starts there).
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
        self.motion = self._motion_model(box)
        if initial_motion is not None:  # a known per-frame motion seeds the motion model
            self.motion.update(box, np.asarray(initial_motion, dtype=np.float64), None, None, _NOMINAL_DT)
        self._timestamp_ns = int(frame.timestamp_ns)
        self.shape = ShapeModel(c.voxel_size)
        self.subshape = SubShape(c.subshape_frames if c.use_subshape else 0, c.voxel_size)
        self.steps = 0
        self._coasting = 0
        self._shape_nn: NearestNeighbors | None = None
        self._shape_nn_size = -1
        self._previous_pose = previous_pose
        local, flags = self._local_points(frame, box, max(c.first_search_scale, c.search_scale))
        height = _ground_height(self._ground_points, box.center[:2], box)
        self._ground_offset = None if height is None else box.z - height
        self._height = HeightFilter(box.z, height, c.height_drift_sigma, c.height_fit_sigma, c.height_road_sigma,
                                    c.height_offset_gain)
        self._finish_frame(frame, box, local, keyframe=True)
        self._started = True
        obj = local[points_in_box(local, box, 1.0)]
        self._start_points = obj  # the Finder's source (first_search="finder")
        self._waiting = c.reacquire and len(obj) < c.min_target_points  # an empty start (see _reacquire)
        self._start_ns = int(frame.timestamp_ns)
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

    def _pairs(self, x: np.ndarray, source: np.ndarray, target: _Target, mask: np.ndarray,
               crop: NearestNeighbors | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """1-NN pairs of the moved source: (source, local-point index or -1, distance, moved, target point).

        Without ``crop`` the target is every local point and pairs whose target is outside the crop are
        dropped; with ``crop`` (association="crop") each source point pairs with its nearest crop point."""
        moved = apply_motion(x, source, self.box.center)
        if crop is not None:
            dist, idx = crop.query(moved)
            return source, np.full(len(source), -1), dist, moved, crop.target[idx]
        dist, idx = target.nn.query(moved)
        keep = mask[idx]
        idx = idx[keep]
        return source[keep], idx, dist[keep], moved[keep], target.nn.target[idx]

    def _ransac_inliers(self, src: np.ndarray, idx: np.ndarray, tgt: np.ndarray, moved: np.ndarray,
                        seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The shape pairs RANSAC keeps. ``ransac_mode="fixed"``: the same hypotheses (``seed``) every outer
        iteration so the loop can settle; too few inliers: no pairs. ``"upstream"``: new draws each call,
        the current estimate (identity on ``moved``) is the first hypothesis; too few inliers: all pairs."""
        c = self.config
        upstream = c.ransac_mode == "upstream"
        keep = np.zeros(len(src), dtype=bool)
        if len(src) >= c.ransac_min_inliers:
            rng = self.rng if upstream else np.random.default_rng(seed)
            keep = ransac_rigid_2d(moved[:, :2], tgt[:, :2], rng, max_iterations=c.ransac_max_iterations,
                                   confidence=c.ransac_confidence, sample_size=c.ransac_sample_size,
                                   threshold=c.ransac_inlier_threshold, max_score_pairs=c.ransac_score_pairs,
                                   identity_first=upstream).inliers
        if keep.sum() >= c.ransac_min_inliers:
            return src[keep], idx[keep], tgt[keep]
        if upstream:
            return src, idx, tgt
        return src[:0], idx[:0], tgt[:0]

    def _estimate(self, target: _Target, x0: np.ndarray, scale: float, outer: int, icp_only: bool,
                  mp_reference: np.ndarray | None, flags: list[str],
                  det_target: np.ndarray | None = None) -> tuple[np.ndarray, dict]:
        """Outer loop of Algorithm 2 from motion ``x0``; returns the motion and diagnostics."""
        c = self.config
        prev = self.box
        pivot = prev.center
        local = target.nn.target
        source = self.prev_points
        sub = self.subshape.points
        if len(sub):
            source = np.vstack([source, to_world_frame(sub, prev)])
        per_iteration = c.association == "crop"  # upstream: fresh subsets (with replacement) every outer iteration
        if not per_iteration:
            source = random_subset(source, c.max_points, self.rng)
        shape_src = np.zeros((0, 3))
        if not icp_only and c.use_shape and c.weight_shape > 0:
            model = self.shape.points if c.shape_update else self._first_shape
            shape_src = to_world_frame(model, prev)
            if not per_iteration:
                shape_src = random_subset(shape_src, c.max_points, self.rng)
        x = np.asarray(x0, dtype=np.float64).copy()
        reference = None if mp_reference is None else mp_reference.copy()
        info = {"crop": 0, "icp_pairs": 0, "shape_inliers": 0, "iterations": 0}
        plane = c.icp_metric == "plane"
        ransac_seed = int(self.rng.integers(2**62))
        accel = _Anderson(c.anderson_depth)
        # upstream: without data terms the frame still minimises the motion prior + motion consistency
        motion_terms_only = c.data_free_frames == "motion_terms" and not icp_only
        for it in range(outer):
            info["iterations"] = it + 1
            mask = points_in_box(local, _box_moved(prev, x), scale)
            info["crop"] = int(mask.sum())
            enough = info["crop"] >= c.min_target_points  # too few points to register against: no data terms
            if not enough and not motion_terms_only:
                info["icp_pairs"] = info["shape_inliers"] = 0
                break
            fixed: list = []  # (name, source, target, normals, weight, normaliser floor)
            data_norm = c.data_norm_min  # few pairs: the data terms weigh less against the motion terms
            info["icp_pairs"] = info["shape_inliers"] = 0
            crop = None
            if per_iteration and enough:
                crop = NearestNeighbors(resample(local[mask], c.max_points, self.rng))
            if enough and c.weight_icp > 0 and len(source) >= c.min_points:
                icp_src = resample(source, c.max_points, self.rng) if per_iteration else source
                src, idx, dist, _, tgt = self._pairs(x, icp_src, target, mask, crop)
                if c.max_pair_distance > 0:
                    keep = dist <= c.max_pair_distance
                    src, idx, tgt = src[keep], idx[keep], tgt[keep]
                if len(src) >= c.min_points:
                    normals = self._normals(target, idx) if plane else None
                    fixed.append(("icp", src, tgt, normals, c.weight_icp, data_norm))
                    info["icp_pairs"] = len(src)
            if enough and len(shape_src) >= c.min_points:
                sh_src = resample(shape_src, c.max_points, self.rng) if per_iteration else shape_src
                src, idx, _, moved, tgt = self._pairs(x, sh_src, target, mask, crop)
                if c.use_ransac:
                    src, idx, tgt = self._ransac_inliers(src, idx, tgt, moved, ransac_seed)
                if len(src) >= c.min_points:
                    normals = self._normals(target, idx) if plane else None
                    fixed.append(("shape", src, tgt, normals, c.weight_shape, data_norm))
                    info["shape_inliers"] = len(src)
            if not fixed and not motion_terms_only:
                break
            use_priors = not icp_only

            # point-to-point pairs as sums, so each LM trial costs O(1) in the pairs (PairMoments)
            moments = [(name, PairMoments.of(s, t, pivot), w, norm) for name, s, t, n, w, norm in fixed if n is None]
            planes = [entry for entry in fixed if entry[3] is not None]

            def blocks_at(xx: np.ndarray) -> list[ResidualBlock]:
                blocks = [m.block(name, xx, w, norm) for name, m, w, norm in moments]
                blocks += [point_pair_block(name, xx, s, t, pivot, w, n, c.plane_point_weight, norm)
                           for name, s, t, n, w, norm in planes]
                if use_priors and c.weight_mc > 0:
                    blocks.append(motion_consistency_block(xx, prev.heading, c.weight_mc, c.symmetric_mc))
                if use_priors and c.weight_mp > 0 and reference is not None:
                    blocks.append(motion_prior_block(xx, reference, c.weight_mp))
                if use_priors and det_target is not None:
                    blocks.append(detection_block(xx, det_target, c.weight_det))
                return blocks

            # the LM stops on a step below a tenth of the outer tolerance (at least 1e-8: never a fixed 50 steps)
            result = solve(blocks_at, x, max_iterations=c.solver_iterations,
                           tolerance=max(0.1 * c.convergence_tolerance, 1e-8))
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

    def detection_target(self, prediction: Box, detections: FrameDetections | None) -> np.ndarray | None:
        """The Detection term's target motion S_D - S_{k-1} for this frame, or None (term off): the
        detection associated with ``prediction`` (the motion model's predicted box S^_k)."""
        c = self.config
        if c.weight_det <= 0 or detections is None:
            return None
        det = associate_detection(prediction, detections, c.det_min_score, c.det_min_iou, c.det_max_distance)
        return None if det is None else detection_motion(self.box, det, prediction.heading)

    def _motion_model(self, box: Box) -> AverageMotion | CTRVMotion:
        c = self.config
        if c.motion_model == "ctrv":
            params = CTRVParams(accel_sigma=c.ctrv_accel_sigma, yaw_accel_sigma=c.ctrv_yaw_accel_sigma)
            return CTRVMotion(box, params, c.ctrv_position_sigma, c.ctrv_heading_sigma, c.travel_heading_sigma,
                              c.travel_min_distance)
        return AverageMotion(c.alpha, c.prior_frame, c.coast_yaw_decay, c.prior_per_second,
                             c.first_motion_along_heading)

    def _elapsed(self, frame: LidarFrame) -> float:
        """Seconds since the previous frame (0.1 s when the timestamps do not advance)."""
        dt = (int(frame.timestamp_ns) - self._timestamp_ns) * 1e-9
        self._timestamp_ns = int(frame.timestamp_ns)
        return dt if dt > 0 else _NOMINAL_DT

    def _search_scale(self, first: bool) -> float:
        """gamma_in, grown by ``search_growth`` sigmas of the predicted centre (capped)."""
        c = self.config
        if first:
            return c.search_scale if c.first_hypotheses > 0 else c.first_search_scale
        scale = c.search_scale
        if c.search_growth > 0:
            margin = c.search_growth * self.motion.search_sigma()
            scale = max(scale, min(c.max_search_scale, c.search_scale + 2.0 * margin / self.box.length))
        return scale

    def _first_frame_search(self, target: _Target, local: np.ndarray, prior: np.ndarray,
                            det_target: np.ndarray | None, flags: list[str]) -> np.ndarray:
        """Frame 1 (no prior yet): the motion the normal step starts from (see tracker/first_frame.py). With an
        associated detection the search starts from the detection's motion instead of the hypotheses."""
        c = self.config
        prev = self.box
        if c.first_search == "finder":  # the authors' Finder: ICP in a fixed wide crop (tracker/finder.py)
            return finder_icp(self._start_points, local, prev, self.rng, scale=c.first_search_scale,
                              iterations=c.first_icp_iterations, max_points=c.max_points, min_points=c.min_points,
                              solver_iterations=c.solver_iterations)
        if c.first_hypotheses <= 0:  # one ICP-only search from the prediction
            x, _ = self._estimate(target, prior, c.first_search_scale, c.first_icp_iterations, True, None, flags)
            return x
        dt = self._last_dt
        best, best_score = np.zeros(4), -1
        source = self.prev_points
        starts = list(motion_hypotheses(prev.heading, c.first_hypotheses, c.first_max_speed * dt,
                                        c.first_max_speed * dt / 3.0))
        if det_target is not None:  # the associated detection's motion is one more hypothesis (first: wins ties)
            starts.insert(0, det_target)
        for x0 in starts:
            x, _ = self._estimate(target, x0, c.search_scale, c.first_icp_iterations, True, None, flags)
            if c.first_max_yaw > 0:
                x[3] = np.clip(x[3], -c.first_max_yaw, c.first_max_yaw)
            score = explained_points(local, _box_moved(prev, x), apply_motion(x, source, prev.center), 0.2)
            if score > best_score:
                best, best_score = x, score
        return best

    def _register(self, frame_local: np.ndarray, prior: np.ndarray, search_scale: float, first: bool,
                  det_target: np.ndarray | None, flags: list[str]) -> np.ndarray:
        """The frame's motion from the data (Algorithm 2), or the prior when there are no data (with a
        detection: the weighted mean of the prior and the detection's motion, flagged ``det_only``)."""
        c = self.config
        reach_box = _box_moved(self.box, prior)
        if len(frame_local) == 0 or not points_in_box(frame_local, reach_box, search_scale).any():
            flags += ["no_points", "prior_only"]
            return self._data_free_motion(prior, det_target, flags)
        target = _Target(frame_local)
        if first:
            x = self._first_frame_search(target, frame_local, prior, det_target, flags)
            reference = x.copy()
        else:
            x, reference = prior.copy(), prior
        x, info = self._estimate(target, x, search_scale, c.outer_iterations, False, reference, flags, det_target)
        if info.get("icp_pairs", 0) == 0 and info.get("shape_inliers", 0) == 0:
            flags.append("low_points")
            if c.data_free_frames == "prior":  # else (upstream) the motion terms alone decided x
                flags.append("prior_only")
                return self._data_free_motion(np.zeros(4) if first else prior, det_target, flags)
        return x

    def _data_free_motion(self, prior: np.ndarray, det_target: np.ndarray | None, flags: list[str]) -> np.ndarray:
        """No points to register: the prior, or with a detection the minimiser of the prior and Detection terms."""
        if det_target is None:
            return prior.copy()
        c = self.config
        flags[:] = [f for f in flags if f != "prior_only"] + ["det_only"]
        return (c.weight_mp * prior + c.weight_det * det_target) / (c.weight_mp + c.weight_det)

    def _limit_motion(self, x: np.ndarray, prior: np.ndarray, first: bool, flags: list[str]) -> np.ndarray:
        """Caps on the change of turn rate and velocity relative to the prediction (physical limits)."""
        c = self.config
        prev = self.box
        if not np.isfinite(x).all():
            flags.append("prior_only")
            return prior.copy()
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
        return x

    def _fuse_motion(self, x: np.ndarray, local: np.ndarray) -> np.ndarray:
        """The motion model's update with the registered motion (CTRV: heading about the visible points)."""
        prev = self.box
        before = self.prev_points[points_in_box(self.prev_points, prev, 1.0)]
        now = local[points_in_box(local, _box_moved(prev, x), 1.0)]
        return self.motion.update(prev, x, before.mean(axis=0) if len(before) else None,
                                  now.mean(axis=0) if len(now) else None, self._last_dt)

    def step(self, frame: LidarFrame, detections: FrameDetections | None = None) -> FrameEstimate:
        """Estimate the object's state in ``frame`` (the frame after the previous call), as named steps.

        The motion model predicts over the elapsed time. A frame without a sweep (``frame.has_sweep`` False)
        is a prediction only, flagged ``no_sweep``. ``detections``: the frame's detections (world boxes), used
        by the Detection term when ``config.weight_det > 0``."""
        if not self._started:
            raise RuntimeError("Tracker.step called before Tracker.start")
        t0 = time.perf_counter()
        c = self.config
        prev = self.box
        self._last_dt = self._elapsed(frame)
        if not frame.has_sweep:
            return self._predict_only(frame, prev, t0)
        if self._waiting:
            return self._reacquire(frame, t0)
        self.steps += 1
        flags: list[str] = []
        first = self.steps == 1
        if first:
            self._first_shape = self.shape.points.copy()
        prior = self.motion.predict(prev, self._last_dt, self._coasting)
        prediction = _box_moved(prev, prior)  # the motion model's prediction S^_k
        det_target = self.detection_target(prediction, detections)
        if det_target is not None:
            flags.append("det")
        search_scale = self._search_scale(first)
        local, point_flags = self._local_points(frame, prediction, max(search_scale, c.search_scale))
        flags += point_flags
        x = self._register(local, prior, search_scale, first, det_target, flags)
        x = self._limit_motion(x, prior, first, flags)
        coasting = "prior_only" in flags
        if c.min_quality > 0 and not coasting and not first:
            explained, _ = self._explained(local, _box_moved(prev, x))
            if explained < c.min_quality:  # a poor fit (clutter, a few stray points): trust the prior instead
                flags += ["low_quality", "prior_only"]
                coasting = True
                x = prior.copy()
        x = self._with_z(x, prev, fit=not coasting)
        if coasting:
            self._coasting += 1  # the motion model is not updated with its own prediction
        else:
            self._coasting = 0
            x = self._fuse_motion(x, local)
        x[3] = wrap_angle(x[3])
        box = _box_moved(prev, x)
        quality = self._quality(local, box)
        obj_world = self._finish_frame(frame, box, local, keyframe=c.shape_update and self.steps % c.keyframe_interval == 0)
        if 0 < len(obj_world) < c.min_points:
            flags.append("low_points")
        self.box = box
        return FrameEstimate(frame.index, box.state, box, len(obj_world), quality, tuple(dict.fromkeys(flags)),
                             (time.perf_counter() - t0) * 1e3, obj_world)

    def _reacquire(self, frame: LidarFrame, t0: float) -> FrameEstimate:
        """An empty start (``reacquire``): the start box had fewer than ``min_target_points`` points, so there
        is neither a shape nor a motion to follow. The box is held, and a region along its heading is searched
        that grows with the time since the start: ``first_max_speed`` x elapsed ahead, a third of that behind,
        the box's width + 0.5 m each side across. Once one box length of it holds ``min_target_points``
        non-ground points, the box slides along its heading to where it holds the most of them (among equals,
        where its face toward the sensor meets the points: that face is the visible one) and the track starts
        again there, with the travelled distance over the elapsed time as the motion prior's start.
        Flags: ``waiting`` (held), ``reacquired``."""
        c = self.config
        prev = self.box
        elapsed = max((int(frame.timestamp_ns) - self._start_ns) * 1e-9, _NOMINAL_DT)
        ahead, behind = c.first_max_speed * elapsed, c.first_max_speed * elapsed / 3.0
        reach = Box(prev.x + 0.5 * (ahead - behind) * np.cos(prev.heading),
                    prev.y + 0.5 * (ahead - behind) * np.sin(prev.heading), prev.z, prev.heading,
                    prev.length + ahead + behind, prev.width + 1.0, prev.height)
        local, _ = self._local_points(frame, reach, 1.0)
        obj = to_object_frame(local[points_in_box(local, reach, 1.0)], reach)
        u = np.sort(obj[:, 0] + 0.5 * (ahead - behind))      # along the heading, from the start box's centre
        shifts = np.arange(-behind, ahead + 0.05, 0.1)
        half = 0.5 * prev.length                             # points within a box length of each shift
        counts = np.searchsorted(u, shifts + half, side="right") - np.searchsorted(u, shifts - half, side="left")
        if counts.max(initial=0) < c.min_target_points:
            self._coasting += 1
            self._previous_pose = (int(frame.timestamp_ns), np.asarray(frame.world_from_ego, dtype=np.float64))
            return FrameEstimate(frame.index, prev.state, prev, 0, 0.0, ("no_points", "prior_only", "waiting"),
                                 (time.perf_counter() - t0) * 1e3, np.zeros((0, 3)))
        best = shifts[counts == counts.max()]
        sensor = transform_points(np.asarray(frame.world_from_ego, dtype=np.float64), np.zeros((1, 3)))[0]
        sensor_u = float(np.dot(sensor[:2] - prev.center[:2], [np.cos(prev.heading), np.sin(prev.heading)]))
        shift = float(best.min() if sensor_u > best.mean() else best.max())  # the visible face meets the points
        motion = np.array([shift * np.cos(prev.heading), shift * np.sin(prev.heading), 0.0, 0.0])
        first_box, previous = self.first_box, self._previous_pose
        estimate = self.start(frame, _box_moved(prev, motion), previous, motion * (_NOMINAL_DT / elapsed))
        self.first_box = first_box
        return replace(estimate, flags=tuple(f for f in estimate.flags if f != "init") + ("reacquired",),
                       time_ms=(time.perf_counter() - t0) * 1e3)

    def _predict_only(self, frame: LidarFrame, prev: Box, t0: float) -> FrameEstimate:
        """A frame without a sweep: move the box by the motion model over the elapsed time, measure nothing.

        The previous object points move with the box (they seed the next frame's registration); the
        shape, sub-shape and motion model are left as they are. Flags: ``no_sweep``, ``prior_only``.
        """
        prior = self.motion.predict(prev, self._last_dt, self._coasting)
        box = _box_moved(prev, prior)
        self.prev_points = to_world_frame(to_object_frame(self.prev_points, prev), box)
        self._previous_pose = (int(frame.timestamp_ns), np.asarray(frame.world_from_ego, dtype=np.float64))
        self._coasting += 1
        self.box = box
        return FrameEstimate(frame.index, box.state, box, 0, 0.0, ("no_sweep", "prior_only"),
                             (time.perf_counter() - t0) * 1e3, np.zeros((0, 3)))

    def _with_z(self, x: np.ndarray, prev: Box, fit: bool = True) -> np.ndarray:
        """The motion with dz set by ``z_mode`` ("ground": keep the start height above the local road;
        "filter": the height filter, fed with the fit's z when ``fit``)."""
        x = x.copy()
        c = self.config
        if c.z_mode == "fixed":
            x[2] = 0.0
        elif c.z_mode == "filter":
            road = _ground_height(self._ground_points, prev.center[:2] + x[:2], prev)
            x[2] = self._height.update(prev.z + x[2] if fit else None, road) - prev.z
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
          config: TrackerConfig | None = None, progress=None, detections: Detections | None = None,
          initial_motion: np.ndarray | None = None, on_frame=None) -> TrackResult:
    """Track from ``init_box`` (world frame, at frame ``start``) through frame ``end`` (inclusive, default: last).

    ``progress``: optional callable(iterable) -> iterable (e.g. tqdm) wrapping the frame loop.
    ``detections``: per-frame detections for the Detection term (``weight_det > 0``) or the ``det`` baseline
    (``method="det"``, :mod:`tracker.det_baseline`). ``initial_motion``: see :meth:`Tracker.start`.
    ``on_frame``: optional callable(tracker, estimate) after every frame (e.g. to record the shape growing).
    """
    config = config or TrackerConfig()
    n = len(source)
    end = n - 1 if end is None else end
    if not 0 <= start < n or not start <= end < n:
        raise IndexError(f"frames {start}..{end} are outside 0..{n - 1}")
    if config.method == "det":
        from .det_baseline import track_detections

        return track_detections(source, init_box, start, end, config, detections or {}, progress)
    tracker = Tracker(config)
    previous_pose = None
    if config.deskew and start > 0:
        prev = source.lidar_frame(start - 1)
        previous_pose = (int(prev.timestamp_ns), np.asarray(prev.world_from_ego, dtype=np.float64))
    estimates = [tracker.start(source.lidar_frame(start), init_box, previous_pose, initial_motion)]
    if on_frame is not None:
        on_frame(tracker, estimates[-1])
    frames = range(start + 1, end + 1)
    for k in (progress(frames) if progress else frames):
        estimates.append(tracker.step(source.lidar_frame(k), None if detections is None else detections.get(k)))
        if on_frame is not None:
            on_frame(tracker, estimates[-1])
    return TrackResult(estimates, init_box.size, tracker.shape_points(), config)
