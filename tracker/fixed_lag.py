"""Fixed-lag refinement: an online mode whose states are final ``lag`` frames after their frame arrives.

At every frame the online tracker (the front end, :class:`~tracker.sotracker.Tracker`) gives a state; then the
last ``lag + 1`` states are re-optimised jointly with the shape, as a sliding-window smoother (as SLAM
systems do): the same joint problem as the offline refinement (tracker/offline.py: data term against the
shape of the other frames, second-difference smoothness, a weak pull to the online states) over a window of
``context`` already-final frames (held fixed: they tie the window to the past and add points to the shape)
followed by the ``lag + 1`` free frames. Each free state starts from its previous refinement, so every state
is refined ``lag + 1`` times with a few Gauss–Newton steps before it leaves the window and becomes final.
Until the first state after the start box becomes final (the first ``lag + 1`` frames) the window is solved
as the offline problem is (all states free, re-gauged to the start box), so with ``lag`` covering the whole
sequence the result approaches the offline refinement's (warm-started solves with fewer iterations each).

The front end is not changed by the smoother (its predictions come from its own states), so the result is
a function of the online result and the points: :func:`refine_fixed_lag` computes it from a finished online
TrackResult, :class:`FixedLagTracker` streams it, and both give the same states. With
``refinement.relock_bridge="both"`` a re-locked frame bridges the stretch before it that is still free
(tracker/relock_bridge.py).
"""

from __future__ import annotations

import dataclasses
import time
from typing import Callable

import numpy as np

from .config import LAG_PARAMS, OfflineParams, TrackerConfig
from .frames import FrameSource, LidarFrame
from .geometry import Box, State, points_in_box
from .offline import _box, _rebuild_shape, frame_region_points_timed, refine_states
from .own_motion import RegionTimes, compensate_track
from .relock_bridge import bridge_start, bridged_estimates
from .sotracker import FrameEstimate, LocalCrop, Tracker, TrackResult

__all__ = ["LAG_PARAMS", "FixedLagSmoother", "FixedLagTracker", "refine_fixed_lag", "track_fixed_lag", "window_states"]

class FixedLagSmoother:
    """Sliding-window refinement of online estimates; ``add`` returns the estimates that became final."""

    def __init__(self, config: TrackerConfig, lag: int, size: np.ndarray, params: OfflineParams | None = None,
                 context: int | None = None) -> None:
        if lag < 1:
            raise ValueError(f"lag must be at least 1, not {lag}")
        params = params or config.refinement.lag
        context = config.refinement.lag_context if context is None else context
        self.config, self.lag, self.params, self.context = config, int(lag), params, int(context)
        self.size = np.asarray(size, dtype=np.float64)
        self.online: list[FrameEstimate] = []
        self.points: list[np.ndarray] = []  # each frame's region points (own motion taken out, see _own_motion_out)
        self.captured: list[np.ndarray] = []  # ... as captured
        self.times: list[RegionTimes | None] = []  # ... and their capture times (with params.own_motion_spread)
        self.states = np.zeros((0, 4))      # current (refined) state of every frame so far
        self.extra_ms: list[float] = []     # smoother time spent when each frame arrived
        self.emitted = 0
        self.shape = np.zeros((0, 3))
        self._previous: tuple[int, np.ndarray] | None = None
        self._previous_of: list[tuple[int, np.ndarray] | None] = []  # each frame's previous pose (de-skew)
        self.floor = 0  # windows start no earlier (set by a backward pass: the frames before it are lost, and the
                        # window must not smooth the revised frames toward them)

    def add(self, frame: LidarFrame | None, estimate: FrameEstimate, world: np.ndarray | None = None,
            crop: LocalCrop | None = None, points: np.ndarray | None = None) -> list[FrameEstimate]:
        """Add frame k's online estimate; returns the estimates that are now final (frame k - lag, or none).
        ``world``, ``crop``: see :func:`~tracker.offline.frame_region_points`; ``points``: the frame's region
        points when the caller has them (then ``frame`` is not read and may be None; no :meth:`revise` after)."""
        t0 = time.perf_counter()
        when = None
        if points is None:
            assert frame is not None
            points, when = frame_region_points_timed(frame, estimate.box, self.config, self.params, self._previous,
                                                     world, crop, with_times=self.params.own_motion_spread > 0)
        if self.config.refinement.relock_bridge == "both" and "reacquired" in estimate.flags:
            self._bridge(estimate)
        self.points.append(points)
        self.captured.append(points)
        self.times.append(when)
        self._previous_of.append(self._previous)
        if frame is not None:
            self._previous = (int(frame.timestamp_ns), np.asarray(frame.world_from_ego, dtype=np.float64))
        self.online.append(estimate)
        self.states = np.vstack([self.states, estimate.state.to_array()[None]])
        k = len(self.online)
        first_free = max(0, k - self.lag - 1)
        begin = max(0, first_free - self.context, self.floor)
        first_free = max(first_free, begin)
        if k - begin >= 2:  # frames before first_free are final (held); with none, the first is re-gauged as offline
            self._own_motion_out(begin)
            online = np.array([e.state.to_array() for e in self.online[begin:]])
            refined, _ = refine_states(self.points[begin:], online, self.size, self.params,
                                       seed=self.config.seed + k, initial=self.states[begin:],
                                       fixed=first_free - begin, with_shape=False)
            self.states[first_free:] = refined[first_free - begin:]
        self.extra_ms.append((time.perf_counter() - t0) * 1e3)
        return self._emit(max(1, k - self.lag))  # the start box is final at once

    def revise(self, j: int, estimate: FrameEstimate, frame: LidarFrame) -> None:
        """Replace estimate j, not yet final, before the next :meth:`add`: its state (also the window's anchor
        for it) and its points (gathered around the new box)."""
        if j < self.emitted:
            raise ValueError(f"estimate {j} is final already")
        self.online[j] = estimate
        self.states[j] = estimate.state.to_array()
        self.points[j], self.times[j] = frame_region_points_timed(
            frame, estimate.box, self.config, self.params, self._previous_of[j],
            with_times=self.params.own_motion_spread > 0)
        self.captured[j] = self.points[j]

    def _bridge(self, estimate: FrameEstimate) -> None:
        """A re-locked ``estimate`` about to be added: the frames of its bridged stretch (tracker/relock_bridge.py)
        not yet final become the line from the frame before them to it, without points (also as the window's
        anchors for them)."""
        k = len(self.online)
        a = bridge_start(self.online + [estimate], k, self.config.refinement.backward_lost_points)
        lo = max(a or k, self.emitted, 1)
        if lo >= k:
            return
        self.online[lo:k] = bridged_estimates(self.online[lo:k], _box(self.states[lo - 1], self.size), estimate.box)
        for j in range(lo, k):
            self.states[j] = self.online[j].state.to_array()
            self.points[j] = self.captured[j] = np.zeros((0, 3))
            self.times[j] = None

    def _own_motion_out(self, begin: int) -> None:
        """The window's points (frames ``begin`` on) with the object's own motion during each sweep taken out
        (``params.own_motion_spread``, tracker/own_motion.py), at the velocities of the window's current states."""
        spread = self.params.own_motion_spread
        if spread <= 0 or all(t is None for t in self.times[begin:]):
            return
        boxes = [_box(s, self.size) for s in self.states[begin:]]
        self.points[begin:] = compensate_track(self.captured[begin:], self.times[begin:], boxes, spread)

    def finish(self) -> list[FrameEstimate]:
        """The estimates not yet final (the last ``lag`` frames), as they stand; builds the shape (all frames)."""
        self._own_motion_out(0)
        self.shape = _rebuild_shape(self.points, self.states, self.size, self.config.refinement.offline.voxel)
        return self._emit(len(self.online))

    def _emit(self, upto: int) -> list[FrameEstimate]:
        out = []
        for j in range(self.emitted, upto):
            est = self.online[j]
            if j == 0:
                out.append(dataclasses.replace(est, time_ms=est.time_ms + self.extra_ms[j]))
                continue
            box = _box(self.states[j], self.size)
            obj = self.points[j][points_in_box(self.points[j], box, 1.0)]
            flags = tuple(dict.fromkeys(list(est.flags) + [f"lag{self.lag}"]))
            out.append(dataclasses.replace(est, state=State.from_array(box.to_array()[:4]), box=box,
                                           num_points=len(obj), points=obj, flags=flags,
                                           time_ms=est.time_ms + self.extra_ms[j]))
        self.emitted = max(self.emitted, upto)
        return out


class FixedLagTracker:
    """Streaming fixed-lag tracking: ``start`` / ``step`` return the estimates that became final
    (state k is final after frame k + lag); ``finish`` returns the rest; ``result`` the whole TrackResult."""

    def __init__(self, config: TrackerConfig, lag: int, params: OfflineParams | None = None,
                 context: int | None = None) -> None:
        self.config, self.lag, self.params, self.context = config, lag, params, context
        self.front = Tracker(config)
        self.final: list[FrameEstimate] = []
        self.frames: list[LidarFrame] = []  # with refinement.backward: the frames not yet final (and the one before)

    def start(self, frame: LidarFrame, box: Box, previous_pose: tuple[int, np.ndarray] | None = None) -> list[FrameEstimate]:
        estimate = self.front.start(frame, box, previous_pose)
        self.smoother = FixedLagSmoother(self.config, self.lag, box.size, self.params, self.context)
        self.smoother._previous = previous_pose
        self.backward = BackwardWindow(self.smoother) if self.config.refinement.backward == "both" else None
        return self._add(frame, estimate)

    def step(self, frame: LidarFrame) -> list[FrameEstimate]:
        return self._add(frame, self.front.step(frame))

    def _add(self, frame: LidarFrame, estimate: FrameEstimate) -> list[FrameEstimate]:
        if self.backward is not None:
            self.frames = (self.frames + [frame])[-(self.lag + 2):]
            self.backward.add(estimate, lambda j: self.frames[j - len(self.smoother.online) - 1])
        return self._keep(self.smoother.add(frame, estimate, crop=self.front.last_crop))

    def finish(self) -> list[FrameEstimate]:
        return self._keep(self.smoother.finish())

    def _keep(self, estimates: list[FrameEstimate]) -> list[FrameEstimate]:
        self.final += estimates
        return estimates

    def result(self) -> TrackResult:
        return TrackResult(list(self.final), self.smoother.size, self.smoother.shape, self.config, mode="lag",
                           lag=self.lag)


class BackwardWindow:
    """Bidirectional refinement in the window (``refinement.backward="both"``, tracker/bidirectional.py): once the
    forward pass has held the object ``backward_lag_lead`` frames from an anchor on (so the pass starts with an
    established motion), a backward pass from the newest frame revises the lost frames of the anchor's weak run
    that are not final yet (fused as in tracker/bidirectional.py, down to the run's start or the last final
    frame)."""

    def __init__(self, smoother: FixedLagSmoother) -> None:
        from .bidirectional import AnchorDetector

        self.smoother = smoother
        self.detector = AnchorDetector(smoother.config)
        self.previous: FrameEstimate | None = None  # the online estimate before (the backward motion's seed)
        self.pending: tuple[int, int] | None = None  # (s, k) of an anchor waiting for its lead

    def add(self, estimate: FrameEstimate, frame_at: Callable[[int], LidarFrame]) -> None:
        """``estimate``: the online estimate about to be added (index c = the smoother's count);
        ``frame_at(j)``: the LidarFrame of index j (c and the frames still free, and the one before them)."""
        from .bidirectional import backward_run, is_lost, reversed_motion

        sm, r = self.smoother, self.smoother.config.refinement
        c = len(sm.online)
        pair = self.detector.add(estimate)
        previous, self.previous = self.previous, estimate
        self.pending = pair or self.pending
        if self.pending is None or c - self.pending[1] < r.backward_lag_lead:
            return
        s, k = self.pending
        self.pending = None
        end = max(s, sm.emitted - 1, 0)
        if k - end < 2 or is_lost(estimate, r.backward_lost_points):
            return
        current = [dataclasses.replace(sm.online[j], state=State.from_array(sm.states[j]),
                                       box=_box(sm.states[j], sm.size)) for j in range(end, k + 1)]
        frames = [frame_at(j) for j in range(c, end - 1, -1)]
        fused = backward_run(frames, estimate, reversed_motion(previous, estimate), current, sm.config, sm.size,
                             end > s)
        for j, est in zip(range(end + 1, k), fused, strict=True):
            if "backward" in est.flags:
                sm.revise(j, est, frame_at(j))
        if end > s:  # the final frames before the revised ones are lost: no window reaches back to them
            sm.floor = end + 1


def refine_fixed_lag(source: FrameSource, result: TrackResult, lag: int, config: TrackerConfig | None = None,
                     params: OfflineParams | None = None, context: int | None = None,
                     backward: bool | None = None) -> TrackResult:
    """The fixed-lag result of a finished online ``result`` (the same states as streaming with
    :class:`FixedLagTracker`). ``params``, ``context``: default ``config.refinement.lag``, ``.lag_context``;
    ``backward``: bidirectional refinement (:class:`BackwardWindow`), default ``config.refinement.backward == "both"``."""
    config = config or result.config
    smoother = FixedLagSmoother(config, lag, np.asarray(result.size), params, context)
    on = config.refinement.backward == "both" if backward is None else backward
    window = BackwardWindow(smoother) if on else None
    getter = getattr(source, "points_world", None)
    if config.deskew and result.estimates and result.estimates[0].frame > 0:
        before = source.lidar_frame(result.estimates[0].frame - 1)
        smoother._previous = (int(before.timestamp_ns), np.asarray(before.world_from_ego, dtype=np.float64))
    final: list[FrameEstimate] = []
    frames = [e.frame for e in result.estimates]
    for est in result.estimates:
        world = getter(est.frame) if callable(getter) and not config.deskew else None
        frame = source.lidar_frame(est.frame)
        if window is not None:
            def frame_at(j: int, now: LidarFrame = frame) -> LidarFrame:
                return now if j == len(smoother.online) else source.lidar_frame(frames[j])

            window.add(est, frame_at)
        final += smoother.add(frame, est, world)
    final += smoother.finish()
    return TrackResult(final, np.asarray(result.size), smoother.shape, config, mode="lag", lag=lag)


def track_fixed_lag(source: FrameSource, init_box: Box, start: int, end: int, config: TrackerConfig, lag: int,
                    progress=None) -> TrackResult:
    """Track with fixed-lag refinement from ``init_box`` at frame ``start`` through ``end`` (inclusive)."""
    tracker = FixedLagTracker(config, lag)
    previous = None
    if config.deskew and start > 0:
        before = source.lidar_frame(start - 1)
        previous = (int(before.timestamp_ns), np.asarray(before.world_from_ego, dtype=np.float64))
    tracker.start(source.lidar_frame(start), init_box, previous)
    frames = range(start + 1, end + 1)
    for k in (progress(frames) if progress else frames):
        tracker.step(source.lidar_frame(k))
    tracker.finish()
    return tracker.result()


def window_states(points: list[np.ndarray], result: TrackResult, lag: int, config: TrackerConfig | None = None,
                  params: OfflineParams | None = None) -> np.ndarray:
    """States (K, 4) of the fixed-lag window pass over a finished online ``result``, given each frame's region
    points (as :func:`~tracker.offline.gather_frame_points` gathers them; no frames read, no backward passes):
    the states :func:`refine_fixed_lag` gives when its window gathers the same points."""
    config = config or result.config
    smoother = FixedLagSmoother(config, lag, np.asarray(result.size), params)
    for estimate, region in zip(result.estimates, points, strict=True):
        smoother.add(None, estimate, points=region)
    return smoother.states.copy()
