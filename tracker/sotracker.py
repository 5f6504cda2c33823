"""SOTracker: the streaming tracker (``Tracker.start`` / ``Tracker.step``) and ``track()``.

Per frame k (the paper's Algorithms 1 and 2), each step a strategy chosen once from the config
(tracker/strategies/, :func:`~tracker.strategies.choose.choose_strategies`):

1. predict S^_k = S_{k-1} + dS_prior (the motion model, ``motion.model``: the moving average, per frame or per
   second of elapsed time, or a CTRV filter);
2. take the sweep's points near the prediction and remove the ground there (``ground.remover``,
   tracker/local_region.py);
3. register: on frame 1 first the frame-1 search (``first_frame.search``), then the outer loop of
   tracker/registration.py (association ``search.association``, shape inliers ``shape.ransac.mode``, metric
   ``registration.metric``, motion terms ``motion.prior_reference`` / ``motion.consistency``);
4. limit the motion, set dz (``height.model``), keep the object points, grow the shape at key frames and update
   the motion model.

With ``detection.weight > 0`` (Det+SOT) and the frame's detections passed to ``step``, the detection associated
with the prediction S^_k (:func:`tracker.detection.associate_detection`) adds the Detection term to the
loss of step 3; a frame without points then takes the motion from the detection and the prior.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from .config import ContainmentConfig, ShapeConfig, TrackerConfig
from .containment import containment_shift
from .deskew import deskew_points
from .detection import Detections, FrameDetections, associate_detection, detection_motion
from .footprint import FootprintCheck
from .frames import FrameSource, LidarFrame
from .geometry import Box, State, points_in_box, transform_points, wrap_angle
from .local_region import LocalCrop, local_region, road_within
from .motion_limits import limit_motion
from .own_motion import own_motion_compensated
from .reacquire import EarlierSweep, box_holds_against, cluster_candidates, filled_start, search_region, start_shift
from .registration import box_moved
from .shape import ShapeModel, SubShape, to_object_frame, to_world_frame
from .strategies.choose import Strategies, choose_strategies
from .strategies.first_frame import FrameOne
from .strategies.metric import FrameTarget
from .strategies.motion import choose_motion_model
from .strategies.reacquire import Relock

__all__ = ["FrameEstimate", "LocalCrop", "TrackResult", "Tracker", "track", "deskew_points"]


@dataclass(frozen=True)
class FrameEstimate:
    """The tracker's output for one frame (world frame).

    ``num_points``: object points (ground removed) in the estimated box; ``points``: those points (N, 3);
    ``quality``: 0..1 (share of those points that the registration explains, scaled down when sparse);
    ``flags``: e.g. "init", "no_points", "prior_only", "low_points", "nan_points", "no_shape_inliers",
    "no_sweep" (the frame has no sweep: a prediction only, see :meth:`Tracker.step`). ``turn``: how far the
    footprint check turned this frame's box (rad, flag ``footprint``; 0 elsewhere): the offline solve carries it back.
    """

    frame: int
    state: State
    box: Box
    num_points: int
    quality: float
    flags: tuple[str, ...]
    time_ms: float
    points: np.ndarray = field(repr=False)
    turn: float = 0.0


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


_NOMINAL_DT = 0.1  # s: the frame interval assumed when timestamps do not advance


class Tracker:
    """Online SOTracker. ``start(frame, box)`` once, then ``step(frame)`` for each following frame."""

    def __init__(self, config: TrackerConfig | None = None) -> None:
        self.config = config or TrackerConfig()
        self.strategies = choose_strategies(self.config)
        self._started = False
        self.last_crop: LocalCrop | None = None  # the points the last start/step searched (see LocalCrop)

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
        if not np.isfinite(box.to_array()).all() or min(box.length, box.width, box.height) <= 0:
            raise ValueError(f"init box must be finite with positive size, got {box}")
        if not frame.has_sweep:
            raise ValueError(f"cannot start a track at frame {frame.index}: it has no sweep")
        self.rng = np.random.default_rng(c.seed)
        self.first_box = self.box = box
        self.motion = choose_motion_model(c.motion, box)
        if initial_motion is not None:  # a known per-frame motion seeds the motion model
            self.motion.update(box, np.asarray(initial_motion, dtype=np.float64), None, None, _NOMINAL_DT)
        self._timestamp_ns = self._start_ns = int(frame.timestamp_ns)
        self.shape = ShapeModel(c.shape.voxel_size)
        self.subshape = SubShape(c.shape.subshape_frames if c.shape.subshape else 0, c.shape.voxel_size)
        self.steps = self._coasting = self._settle = 0
        self._previous_pose = previous_pose
        local, flags = self._local_points(frame, box, max(c.first_frame.scale, c.search.scale))
        self.strategies.height.start(box, self._ground_points)
        self._finish_frame(frame, box, local, keyframe=True)
        self._started = True
        obj = local[points_in_box(local, box, 1.0)]
        self._start_points = obj  # the Finder's source (first_frame.search="finder")
        self._waiting = c.first_frame.reacquire and len(obj) < c.search.min_target_points  # see _reacquire
        time_s = int(frame.timestamp_ns) * 1e-9
        self.strategies.reacquire.reset(time_s, box.center)
        self._lost_start = self.strategies.reacquire.lost_start(len(obj))  # see _search
        self.strategies.travel.reset()
        self.strategies.travel.record(box, time_s)
        self._footprint = FootprintCheck(c.footprint)
        if len(obj) == 0:
            flags.append("no_points")
        return FrameEstimate(frame.index, box.state, box, len(obj), 1.0, tuple(["init"] + flags),
                             (time.perf_counter() - t0) * 1e3, obj)

    def step(self, frame: LidarFrame, detections: FrameDetections | None = None) -> FrameEstimate:
        """Estimate the object's state in ``frame`` (the frame after the previous call), as named steps.

        The motion model predicts over the elapsed time. A frame without a sweep (``frame.has_sweep`` False)
        is a prediction only, flagged ``no_sweep``. ``detections``: the frame's detections (world boxes), used
        by the Detection term when ``config.detection.weight > 0``."""
        if not self._started:
            raise RuntimeError("Tracker.step called before Tracker.start")
        t0 = time.perf_counter()
        self._last_dt = self._elapsed(frame)
        if not frame.has_sweep:
            return self._predict_only(frame, t0)
        if self._waiting:
            return self._reacquire(frame, t0)
        if self._lost_start:
            return self._search(frame, self._held(frame), np.zeros(2), self.first_box, t0)
        self.steps += 1
        first, flags = self.steps == 1, list[str]()
        prior = self.motion.predict(self.box, self._last_dt, self._coasting)
        prediction = box_moved(self.box, prior)  # the motion model's prediction S^_k
        det_target = self._detection_for(prediction, detections, flags)
        search_scale = self._search_scale(first)
        local, point_flags = self._local_points(frame, prediction, max(search_scale, self.config.search.scale), prior)
        flags += point_flags
        x = self._register(local, prior, search_scale, first, det_target, flags)
        x = limit_motion(x, prior, self.box.heading, first, self.steps, self.config.motion, flags, self._last_dt,
                         len(self.prev_points))
        x = self._check_fit(x, local, prior, first, flags)
        coasting = "prior_only" in flags
        x = self.strategies.height.motion(x, self.box, self._ground_points, fit=not coasting)
        x = self._update_motion(x, local, coasting)
        estimate = self._finish_step(frame, x, local, flags, t0)
        if self.strategies.reacquire.holds(estimate.num_points, coasting, int(frame.timestamp_ns) * 1e-9,
                                           estimate.box.center):
            return estimate
        return self._search(frame, estimate, prior[:2] / self._last_dt, None, t0)

    def shape_points(self) -> np.ndarray:
        """The aggregated shape (object frame)."""
        return self.shape.points.copy()

    def detection_target(self, prediction: Box, detections: FrameDetections | None) -> np.ndarray | None:
        """The Detection term's target motion S_D - S_{k-1} for this frame, or None (term off): the
        detection associated with ``prediction`` (the motion model's predicted box S^_k)."""
        d = self.config.detection
        if d.weight <= 0 or detections is None:
            return None
        det = associate_detection(prediction, detections, d.min_score, d.min_iou, d.max_distance)
        return None if det is None else detection_motion(self.box, det, prediction.heading)

    # ------------------------------------------------------------------ steps
    def _local_points(self, frame: LidarFrame, box: Box, scale: float, prior: np.ndarray | None = None
                      ) -> tuple[np.ndarray, list[str]]:
        """Non-ground world points near ``box`` (tracker/local_region.py); keeps the road points and the crop. With
        the step's ``prior``, the object's own motion during the sweep taken out (:func:`_own_motion_out`)."""
        s, c = self.strategies, self.config
        region = local_region(frame, box, scale, s.ground, s.road, c.ground.margin, c.deskew, self._previous_pose)
        self._ground_points = road_within(region.road, box, frame, c.height.road_max_range)
        if region.crop is not None:
            self.last_crop = region.crop
        velocity = None if prior is None else prior[:2] / self._last_dt
        return _own_motion_out(region.points, region.crop, box, velocity, c.search.own_motion_spread), list(region.flags)

    def _detection_for(self, prediction: Box, detections: FrameDetections | None, flags: list[str]
                       ) -> np.ndarray | None:
        det_target = self.detection_target(prediction, detections)
        if det_target is not None:
            flags.append("det")
        return det_target

    def _search_scale(self, first: bool) -> float:
        """gamma_in (frame 1: the frame-1 search's), grown by ``search.growth`` sigmas of the predicted centre."""
        s = self.config.search
        if first:
            return self.strategies.first_frame.scale
        scale = s.scale
        if s.growth > 0:
            margin = s.growth * self.motion.search_sigma()
            scale = max(scale, min(s.max_scale, s.scale + 2.0 * margin / self.box.length))
        return scale

    def _source(self) -> np.ndarray:
        """The ICP source: the previous frame's object points and the sub-shape placed at the box."""
        sub = self.subshape.points
        return np.vstack([self.prev_points, to_world_frame(sub, self.box)]) if len(sub) else self.prev_points

    def _register(self, local: np.ndarray, prior: np.ndarray, search_scale: float, first: bool,
                  det_target: np.ndarray | None, flags: list[str]) -> np.ndarray:
        """The frame's motion from the data (Algorithm 2), or the prior when there are no data (with a
        detection: the weighted mean of the prior and the detection's motion, flagged ``det_only``)."""
        c, prev, reg = self.config, self.box, self.strategies.registration
        if len(local) == 0 or not points_in_box(local, box_moved(prev, prior), search_scale).any():
            flags += ["no_points", "prior_only"]
            return self._data_free_motion(prior, det_target, flags)
        target = FrameTarget(local)
        x, reference = prior.copy(), prior
        if first:
            def icp(x0: np.ndarray, scale: float, outer: int) -> np.ndarray:
                return reg.estimate(prev, self._source(), self.shape.points, target, x0, scale, outer, True, None,
                                    flags, self.rng)[0]

            x = self.strategies.first_frame.motion(FrameOne(prev, local, prior, det_target, self._last_dt,
                                                            self.prev_points, self._start_points, self.rng, icp))
            reference = x.copy()
        travel = self.strategies.travel.target(prev.heading, len(self.prev_points))
        x, info = reg.estimate(prev, self._source(), self.shape.points, target, x, search_scale,
                               c.registration.outer_iterations, False, reference, flags, self.rng, det_target, travel)
        if info.get("icp_pairs", 0) == 0 and info.get("shape_inliers", 0) == 0:
            flags.append("low_points")
            if reg.data_free.keeps_prior():  # else (upstream) the motion terms alone decided x
                flags.append("prior_only")
                return self._data_free_motion(np.zeros(4) if first else prior, det_target, flags)
        return x

    def _data_free_motion(self, prior: np.ndarray, det_target: np.ndarray | None, flags: list[str]) -> np.ndarray:
        """No points to register: the prior, or with a detection the minimiser of the prior and Detection terms."""
        if det_target is None:
            return prior.copy()
        mp, det = self.config.motion.prior_weight, self.config.detection.weight
        flags[:] = [f for f in flags if f != "prior_only"] + ["det_only"]
        return (mp * prior + det * det_target) / (mp + det)

    def _check_fit(self, x: np.ndarray, local: np.ndarray, prior: np.ndarray, first: bool,
                   flags: list[str]) -> np.ndarray:
        """A poor fit (clutter; below ``registration.min_quality``): the prior instead; else :func:`_slid`."""
        min_quality = self.config.registration.min_quality
        if min_quality > 0 and "prior_only" not in flags and not first:
            explained, _ = _explained(self.shape, local, box_moved(self.box, x))
            if explained < min_quality:
                flags += ["low_quality", "prior_only"]
                return prior.copy()
        return _slid(x, self.box, local, self.config.footprint.containment, self._last_dt,
                     (self.shape, self.subshape), flags, self.steps <= self._settle)

    def _update_motion(self, x: np.ndarray, local: np.ndarray, coasting: bool) -> np.ndarray:
        """The motion model's update with the registered motion (CTRV: heading about the visible points); a
        coasting frame does not update it with its own prediction."""
        if coasting:
            self._coasting += 1
            self.subshape.hold(_hold_frames(self.config.shape, self.shape), self.config.shape.subshape_hold_dense)
        else:
            self._coasting = 0
            prev = self.box
            before = self.prev_points[points_in_box(self.prev_points, prev, 1.0)]
            now = local[points_in_box(local, box_moved(prev, x), 1.0)]
            x = self.motion.update(prev, x, before.mean(axis=0) if len(before) else None,
                                   now.mean(axis=0) if len(now) else None, self._last_dt, len(now))
        x[3] = wrap_angle(x[3])
        return x

    def _check_footprint(self, x: np.ndarray, local: np.ndarray, flags: list[str]) -> tuple[np.ndarray, float]:
        """The footprint check (tracker/footprint.py) of a measured frame: the box turns about its centre, the
        shape and sub-shape turn back in the object frame (they stay where they lie in the world). Flag:
        ``footprint``."""
        turn = None if "prior_only" in flags else self._footprint.turn(local, box_moved(self.box, x), self.shape.points)
        if turn is None:
            return x, 0.0
        flags.append("footprint")
        self.shape.turn(-turn)
        self.subshape.turn(-turn)
        return x + np.array([0.0, 0.0, 0.0, turn]), turn

    def _finish_step(self, frame: LidarFrame, x: np.ndarray, local: np.ndarray, flags: list[str],
                     t0: float) -> FrameEstimate:
        c = self.config
        x, turn = self._check_footprint(x, local, flags)
        box = box_moved(self.box, x)
        inside = local[points_in_box(local, box, 1.0)]   # the points the quality and (crop 1.0) the shape take
        obj = to_object_frame(inside, box)
        quality = _quality(*self.shape.explained(obj))
        keyframe = c.shape.aggregate and self.steps % c.shape.keyframe_interval == 0
        shared = (inside, obj) if c.shape.crop_scale == 1.0 else None
        obj_world = self._finish_frame(frame, box, local, keyframe, shared)
        if 0 < len(obj_world) < c.registration.min_points:
            flags.append("low_points")
        self.box = box
        self.strategies.travel.record(box, int(frame.timestamp_ns) * 1e-9)
        return FrameEstimate(frame.index, box.state, box, len(obj_world), quality, tuple(dict.fromkeys(flags)),
                             (time.perf_counter() - t0) * 1e3, obj_world, turn)

    def _finish_frame(self, frame: LidarFrame, box: Box, local: np.ndarray, keyframe: bool,
                      object_points: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """``object_points``: (world, object frame) of the points in ``box`` scaled ``shape.crop_scale`` when the
        caller has them."""
        c = self.config
        self.prev_points = local[points_in_box(local, box, c.search.crop_scale)]
        if object_points is None:
            obj_world = local[points_in_box(local, box, c.shape.crop_scale)]
            obj = to_object_frame(obj_world, box)
        else:
            obj_world, obj = object_points
        self.subshape.add(obj)
        if keyframe:
            self.shape.add(obj)
        self._previous_pose = (int(frame.timestamp_ns), np.asarray(frame.world_from_ego, dtype=np.float64))
        return obj_world

    def _reacquire(self, frame: LidarFrame, t0: float) -> FrameEstimate:
        """An empty start (``first_frame.reacquire``): the start box had fewer than ``search.min_target_points``
        points. The box is held while tracker/reacquire.py searches along its heading; once it finds points the
        track starts again there, with the travelled distance over the elapsed time as the motion prior's
        start. Flags: ``waiting`` (held), ``reacquired``."""
        c, prev = self.config, self.box
        elapsed = max((int(frame.timestamp_ns) - self._start_ns) * 1e-9, _NOMINAL_DT)
        ahead, behind = c.first_frame.max_speed * elapsed, c.first_frame.max_speed * elapsed / 3.0
        local, _ = self._local_points(frame, search_region(prev, ahead, behind), 1.0)
        sensor = transform_points(np.asarray(frame.world_from_ego, dtype=np.float64), np.zeros((1, 3)))[0]
        shift = start_shift(local, prev, ahead, behind, c.search.min_target_points, sensor)
        if shift is None:
            self._coasting += 1
            self._previous_pose = (int(frame.timestamp_ns), np.asarray(frame.world_from_ego, dtype=np.float64))
            return FrameEstimate(frame.index, prev.state, prev, 0, 0.0, ("no_points", "prior_only", "waiting"),
                                 (time.perf_counter() - t0) * 1e3, np.zeros((0, 3)))
        motion = np.array([shift * np.cos(prev.heading), shift * np.sin(prev.heading), 0.0, 0.0])
        first_box, previous = self.first_box, self._previous_pose
        estimate = self.start(frame, box_moved(prev, motion), previous, motion * (_NOMINAL_DT / elapsed))
        self.first_box = first_box
        return replace(estimate, flags=tuple(f for f in estimate.flags if f != "init") + ("reacquired",),
                       time_ms=(time.perf_counter() - t0) * 1e3)

    def _held(self, frame: LidarFrame) -> FrameEstimate:
        """A lost start's frame: the start box held (the time is set by :meth:`_search`)."""
        self._coasting += 1
        self._previous_pose = (int(frame.timestamp_ns), np.asarray(frame.world_from_ego, dtype=np.float64))
        return FrameEstimate(frame.index, self.box.state, self.box, 0, 0.0, ("no_points", "prior_only"), 0.0,
                             np.zeros((0, 3)))

    def _search(self, frame: LidarFrame, estimate: FrameEstimate, velocity: np.ndarray, start: Box | None,
                t0: float) -> FrameEstimate:
        """Re-acquisition (``reacquire.mode``, tracker/strategies/reacquire.py): the frame's estimate (the motion
        model's prediction where the points did not hold it) is flagged ``coasting`` while the box-sized non-ground
        clusters of the strategy's region are searched; a candidate consistent with the previous frame's restarts
        the track there (``reacquired``). ``velocity``: predicted (m/s, xy); ``start``: a lost start's box, else None."""
        c, s = self.config, self.strategies
        time_s = int(frame.timestamp_ns) * 1e-9
        region = s.reacquire.region(self.box, time_s, start)
        points = _non_ground_points_in(frame, region, c, s, self._previous_pose)
        sensor = transform_points(np.asarray(frame.world_from_ego, dtype=np.float64), np.zeros((1, 3)))[0]
        r = c.reacquire
        if r.static_share > 0 and start is None and s.reacquire.earlier is None:   # the sweep where the track became lost
            s.reacquire.earlier = _earlier_sweep(frame, self.box, c, s, self._previous_pose)
        if start is not None and r.start_fill_frames > 0 and s.reacquire.start_filled(
                int(points_in_box(points, start, 1.0).sum())):
            filled = Relock(filled_start(points, start, r.start_points, sensor), np.zeros(2))   # starts at rest
            return self._relock(frame, filled, False, t0)
        candidates = cluster_candidates(points, self.box, sensor, r.grid(start is not None), r.cluster_points,
                                        r.size_margin, time_s, centred=start is None, hold_scale=c.search.crop_scale,
                                        region=region if r.whole_candidates or r.drift_gate else None,
                                        earlier=s.reacquire.earlier if start is None else None, radius=r.static_radius)
        supported = estimate.num_points >= r.min_points and "prior_only" not in estimate.flags
        held = start is None and s.reacquire.holds_object(candidates, self.box, supported)
        relock = s.reacquire.confirm(candidates, self.box, velocity, start)
        confirms = held or (relock is not None and start is None
                            and float(np.linalg.norm(relock.centre - self.box.center[:2])) < r.hold_distance)
        if relock is None or confirms or (start is None and box_holds_against(
                self.box, relock.centre, points, r.supported_holds_ties and supported, self.config.search.crop_scale)):
            if confirms:  # the candidate is where the track is: it holds, the search ends
                s.reacquire.reset(time_s, self.box.center)
            flags = _search_flags(estimate.flags, relock is None, confirms or start is not None)
            return replace(estimate, flags=flags, time_ms=(time.perf_counter() - t0) * 1e3)
        return self._relock(frame, relock, start is None, t0)

    def _relock(self, frame: LidarFrame, relock: Relock, keep_motion: bool, t0: float) -> FrameEstimate:
        """Restart the track at a confirmed candidate, its velocity seeding the motion model; with ``keep_motion`` (a
        lost track: its prediction found the candidate) the motion model goes on as it was (a turn keeps turning)."""
        prev, motion_model = self.box, self.motion
        box = Box(float(relock.centre[0]), float(relock.centre[1]), prev.z, prev.heading, prev.length, prev.width,
                  prev.height)
        motion = np.array([relock.velocity[0] * _NOMINAL_DT, relock.velocity[1] * _NOMINAL_DT, 0.0, 0.0])
        first_box, previous = self.first_box, self._previous_pose
        estimate = self.start(frame, box, previous, motion)
        self.first_box, self._lost_start, self._footprint = first_box, False, FootprintCheck(self.config.footprint, True)
        self._settle = self.config.footprint.containment.settle_frames   # its placement is a guess: see _slid
        if keep_motion:
            self.motion = motion_model
        return replace(estimate, flags=tuple(f for f in estimate.flags if f != "init") + ("reacquired",),
                       time_ms=(time.perf_counter() - t0) * 1e3)

    def _predict_only(self, frame: LidarFrame, t0: float) -> FrameEstimate:
        """A frame without a sweep: move the box by the motion model over the elapsed time, measure nothing.

        The previous object points move with the box (they seed the next frame's registration); the
        shape, sub-shape and motion model are left as they are. Flags: ``no_sweep``, ``prior_only``.
        """
        prev = self.box
        box = box_moved(prev, self.motion.predict(prev, self._last_dt, self._coasting))
        self.prev_points = to_world_frame(to_object_frame(self.prev_points, prev), box)
        self._previous_pose = (int(frame.timestamp_ns), np.asarray(frame.world_from_ego, dtype=np.float64))
        self._coasting, self.box = self._coasting + 1, box
        return FrameEstimate(frame.index, box.state, box, 0, 0.0, ("no_sweep", "prior_only"),
                             (time.perf_counter() - t0) * 1e3, np.zeros((0, 3)))

    def _elapsed(self, frame: LidarFrame) -> float:
        """Seconds since the previous frame (0.1 s when the timestamps do not advance)."""
        dt = (int(frame.timestamp_ns) - self._timestamp_ns) * 1e-9
        self._timestamp_ns = int(frame.timestamp_ns)
        return dt if dt > 0 else _NOMINAL_DT


def _search_flags(flags: tuple[str, ...], no_candidate: bool, held: bool) -> tuple[str, ...]:
    """A searching frame's flags: ``coasting`` on the motion model's prediction with no candidate, ``searching`` on
    points while lost (the box may follow something that is not the object; a re-lock elsewhere later says it
    did), not where the track holds its object (``held``) or for a lost start."""
    if "prior_only" in flags:
        return tuple(dict.fromkeys(flags + ("coasting",))) if no_candidate else flags
    return flags if held else tuple(dict.fromkeys(flags + ("searching",)))


def _slid(x: np.ndarray, box: Box, local: np.ndarray, config: ContainmentConfig, dt: float,
          shapes: tuple[ShapeModel, SubShape], flags: list[str], either_way: bool = False) -> np.ndarray:
    """The containment check (tracker/containment.py) of a measured frame's motion ``x`` from ``box`` over ``dt``
    seconds: the box moves along its length to hold its object's points; with ``config.shape`` "world" the shape
    and sub-shape move back by as much in the object frame (they stay where they lie in the world). ``either_way``:
    a re-locked track settling (``config.settle_frames``), its box slides against the motion too. Flag
    ``contained``."""
    if "prior_only" in flags:
        return x
    moved = box_moved(box, x)
    direction = np.array([np.cos(moved.heading), np.sin(moved.heading)])
    shift = containment_shift(local, moved, config, float(x[:2] @ direction) / dt, either_way)
    if shift == 0.0:
        return x
    flags.append("contained")
    if config.shape == "world":
        for shape in shapes:
            shape.slide(-shift)
    return x + np.array([*(shift * direction), 0.0, 0.0])


def _hold_frames(config: ShapeConfig, shape: ShapeModel) -> int:
    """For how many frames from a coasting frame the sub-shape takes no points (``shape.subshape_hold``): a box
    placed by the coast places the re-appearing object's points in the sub-shape where the coast put them, and the
    registration then holds the box there; a shape of ``subshape_hold_shape`` points or more places the box instead.
    A sparser object's shape cannot: its sub-shape is kept. A frame of ``subshape_hold_dense`` points or more
    registers well on its own and is taken."""
    return config.subshape_hold if config.subshape_hold > 0 and len(shape.points) >= config.subshape_hold_shape else 0


def _explained(shape: ShapeModel, local: np.ndarray, box: Box) -> tuple[float, int]:
    """Share of the object points in ``box`` within 0.2 m of ``shape`` placed there, and their number."""
    return shape.explained(to_object_frame(local[points_in_box(local, box, 1.0)], box))


def _own_motion_out(local: np.ndarray, crop: LocalCrop | None, prediction: Box, velocity: np.ndarray | None,
                    spread: float) -> np.ndarray:
    """``local`` (the step's region points: ``crop``'s, in its order) with the object's own motion during the sweep
    taken out (``search.own_motion_spread``) at the motion model's predicted ``velocity`` (none: as they are); the
    crop, which the refinements reuse, keeps the points as captured."""
    times = None if crop is None else crop.time_offsets_ns
    if spread <= 0 or velocity is None or times is None or len(times) != len(local):
        return local
    return own_motion_compensated(local, times, prediction, velocity, spread)


def _quality(explained: float, count: int) -> float:
    """A frame's quality: the share of its ``count`` object points within 0.2 m of the shape, damped when sparse."""
    return float(np.clip(explained * min(1.0, count / 20.0), 0.0, 1.0))


def _non_ground_points_in(frame: LidarFrame, region: Box, config: TrackerConfig, strategies: Strategies,
                          previous_pose: tuple[int, np.ndarray] | None) -> np.ndarray:
    """The frame's non-ground points (world) inside ``region``."""
    points = local_region(frame, region, 1.0, strategies.ground, strategies.road, config.ground.margin, config.deskew,
                          previous_pose).points
    return points[points_in_box(points, region, 1.0)]


def _earlier_sweep(frame: LidarFrame, box: Box, config: TrackerConfig, strategies: Strategies,
                   previous_pose: tuple[int, np.ndarray] | None) -> EarlierSweep:
    """The frame's non-ground points (world) as far around ``box`` as the search ever reaches
    (``reacquire.max_reach``), less those in the box grown by ``reacquire.reach`` (the object's own place): the sweep
    where the track became lost, against which ``reacquire.static_share`` compares candidates."""
    r = config.reacquire
    points = _non_ground_points_in(frame, search_region(box, r.max_reach, r.max_reach, r.max_reach, r.rise), config,
                                   strategies, previous_pose)
    return EarlierSweep(points[~points_in_box(points, search_region(box, r.reach, r.reach, r.reach, r.rise), 1.0)])


def track(source: FrameSource, init_box: Box, start: int = 0, end: int | None = None,
          config: TrackerConfig | None = None, progress=None, detections: Detections | None = None,
          initial_motion: np.ndarray | None = None, on_frame=None) -> TrackResult:
    """Track from ``init_box`` (world frame, at frame ``start``) through frame ``end`` (inclusive, default: last).

    ``progress``: optional callable(iterable) -> iterable (e.g. tqdm) wrapping the frame loop.
    ``detections``: per-frame detections for the Detection term (``detection.weight > 0``) or the ``det`` baseline
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
