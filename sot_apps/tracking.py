"""Run SOTracker on a :class:`~sot_apps.io.sequence.Sequence` and write ``DIR/track.json`` + ``DIR/shape.ply``.

One object (:func:`track_sequence`, ``sot-apps track``) or many in one pass over the sweeps
(:func:`track_objects`, the pipeline's tracking stage: each sweep read and grounded once, every live object
stepped; each object's result is the one tracking it alone gives). The one writer of track files: both call
:func:`write_track_result`, and both start an annotated object at the first annotated box with enough points
(:class:`StartSearch`).
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tracker import (
    Box,
    Detections,
    FrameEstimate,
    LidarFrame,
    Tracker,
    TrackerConfig,
    TrackResult,
    cached_sweep_ground_mask,
    points_in_box,
    track,
)

from .errors import InputError
from .io.atomic import write_text
from .io.object_track import ObjectTrack
from .io.sequence import Sequence
from .io.tracks import TrackHeader, frame_is_valid, write_track

__all__ = ["ShapeGrowth", "track_with_shape_growth", "write_shape_growth", "read_shape_growth", "parse_init_box",
           "VEHICLE_SIZE_RANGE_M", "implausible_size", "check_vehicle_size", "resolve_span", "track_sequence",
           "refine_track_fixed_lag", "refine_track_offline", "track_result_to_track",
           "write_track_result", "first_box_with_points", "TrackStart", "annotated_track_start",
           "TrackingFailed", "MIN_INIT_POINTS", "StartSearch",
           "ShapeRecorder", "ObjectRequest", "TrackOutcome", "PassTimes", "track_objects", "sweep_ground_once"]

MIN_INIT_POINTS = 5   # non-ground LiDAR points the tracker needs in its initial box


# What a road vehicle can measure (metres): from a small motorbike or bicycle to a long articulated
# truck / road-train unit (EU and US limits are 16.5-25.25 m long, 2.55-2.6 m wide, about 4-4.3 m high;
# wide and high loads stay under 5 m and 6 m). Init boxes outside are refused unless allowed explicitly.
VEHICLE_SIZE_RANGE_M: dict[str, tuple[float, float]] = {"length": (0.5, 30.0), "width": (0.3, 5.0),
                                                        "height": (0.3, 6.0)}


def implausible_size(box: Box) -> str | None:
    """Why ``box``'s size cannot be a road vehicle (:data:`VEHICLE_SIZE_RANGE_M`), or None if it can."""
    bad = [f"{name} {getattr(box, name):g} m (expected {lo:g}..{hi:g})"
           for name, (lo, hi) in VEHICLE_SIZE_RANGE_M.items() if not lo <= getattr(box, name) <= hi]
    return ", ".join(bad) or None


def check_vehicle_size(box: Box, where: str | Path | None, allow: bool, flag: str = "--allow-any-size") -> str | None:
    """Refuse an init box no road vehicle can fill (InputError naming ``where``), unless ``allow``: then
    return the warning to print (None when the size is plausible)."""
    why = implausible_size(box)
    if why is None:
        return None
    if not allow:
        raise InputError(where, f"init box size is not a road vehicle's: {why}; check the box (metres, "
                                f"length/width/height order) or pass {flag} to track it anyway")
    return f"warning: init box size is not a road vehicle's ({why}); tracking it as asked ({flag})"


class TrackingFailed(RuntimeError):
    """The object could not be tracked (e.g. no LiDAR points in its initial box)."""


def parse_init_box(text: str, where: str = "--init-box") -> Box:
    """``x,y,z,heading,length,width,height`` (world frame, metres, radians) -> Box; bad text -> InputError."""
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) != 7:
        raise InputError(None, f"{where}: expected 7 comma-separated numbers x,y,z,heading,length,width,height, got {len(parts)}")
    try:
        values = [float(p) for p in parts]
    except ValueError as exc:
        raise InputError(None, f"{where}: not a number ({exc})") from exc
    if not all(math.isfinite(v) for v in values):
        raise InputError(None, f"{where}: values must be finite numbers (got {text})")
    if min(values[4:]) <= 0:
        raise InputError(None, f"{where}: length, width and height must be positive")
    return Box(*values)


def resolve_span(seq: Sequence, start: int, end: int | None) -> tuple[int, int]:
    """Check the frame range against the sequence; ``end`` defaults to the last frame."""
    n = len(seq)
    if not 0 <= start < n:
        raise InputError(seq.root, f"start frame {start} is out of range: the sequence has frames 0..{n - 1}")
    end = n - 1 if end is None else end
    if not start <= end < n:
        raise InputError(seq.root, f"end frame {end} is out of range: must be in {start}..{n - 1}")
    return start, end


def track_sequence(seq: Sequence, init_box: Box, start: int = 0, end: int | None = None,
                   config: TrackerConfig | None = None, progress: bool = True,
                   detections: Detections | None = None) -> TrackResult:
    """Track ``init_box`` (world frame at ``start``) through frame ``end`` (inclusive); ``detections``
    feed the Detection term / the Det baseline.

    Frames without a sweep are passed to the tracker as such (``LidarFrame.has_sweep`` False): it
    predicts through them with the elapsed time and flags them ``no_sweep``.
    """
    config = config or TrackerConfig()
    start, end = resolve_span(seq, start, end)
    if not np.isfinite(init_box.to_array()).all() or min(init_box.length, init_box.width, init_box.height) <= 0:
        raise InputError(None, f"init box must be finite with a positive size, got {init_box}")
    if not seq.frames[start].has_sweep:
        raise InputError(seq.root, f"start frame {start} has no sweep (missing sweeps: {seq.missing_sweeps()}); start at a frame with one")
    wrap = None
    if progress:
        from tqdm import tqdm

        def wrap(frames):
            return tqdm(frames, desc="track", unit="frame", leave=False)
    return track(seq, init_box, start, end, config, progress=wrap, detections=detections)


class StartSearch:
    """Where an annotated object's track starts: the first annotated (frame, box) whose box holds ``min_points``
    non-ground points, as the tracker counts them at its start (no de-skew); the last annotated frame and frames
    without a sweep cannot start a track. :meth:`attempt` tries one frame, :meth:`failure` says why none did."""

    def __init__(self, seq: Sequence, annotated: list[tuple[int, Box]] | tuple[tuple[int, Box], ...],
                 config: TrackerConfig, min_points: int = MIN_INIT_POINTS) -> None:
        self.annotated, self.config, self.min_points = tuple(annotated), config, min_points
        self.candidates = {k: box for k, box in self.annotated[:-1] if seq.frames[k].has_sweep}
        self.best = (0, self.annotated[0][0])

    def attempt(self, frame: LidarFrame) -> tuple[Tracker, FrameEstimate] | None:
        """The tracker started at candidate ``frame`` and its start estimate when its box holds enough points,
        else None."""
        tracker = Tracker(self.config)
        estimate = tracker.start(frame, self.candidates[frame.index])
        n = estimate.num_points
        if n >= self.min_points:
            return tracker, estimate
        self.best = max(self.best, (n, frame.index), key=lambda b: b[0])
        return None

    def failure(self) -> TrackingFailed:
        annotated = self.annotated
        last = annotated[-2][0] if len(annotated) > 1 else annotated[0][0]
        return TrackingFailed(f"fewer than {self.min_points} LiDAR points in every annotated box (frames "
                              f"{annotated[0][0]}..{last}; at most {self.best[0]} at frame {self.best[1]}); "
                              f"nothing to track")


def first_box_with_points(seq: Sequence, annotated: list[tuple[int, Box]] | tuple[tuple[int, Box], ...],
                          config: TrackerConfig, min_points: int = MIN_INIT_POINTS) -> tuple[int, Box]:
    """The first annotated (frame, box) whose box holds ``min_points`` non-ground points, as the tracker counts
    them at its start; the last annotated frame cannot start a track. None such: :class:`TrackingFailed`."""
    search = StartSearch(seq, annotated, config, min_points)
    for k, box in search.candidates.items():
        if search.attempt(seq.lidar_frame(k)) is not None:
            return k, box
    raise search.failure()


@dataclass(frozen=True)
class TrackStart:
    """Where tracking an annotated object starts: its id, label, start box and frame span (inclusive)."""

    object_id: str
    label: str
    init_box: Box
    start: int
    end: int


def annotated_track_start(seq: Sequence, track_id: str, config: TrackerConfig, start: int | None = None,
                          end: int | None = None) -> TrackStart:
    """The start of tracking the annotated object ``track_id`` (a unique prefix is enough). ``start`` /
    ``end`` default to its first / last annotated frame; without ``start``, the first annotated box the tracker
    can start on (:func:`first_box_with_points`, the pipeline's rule), or the first annotated box when none can.
    A frame out of range, or a ``start`` without an annotated box, is an InputError."""
    object_id = seq.resolve_track_id(track_id)
    annotated = seq.tracks()[object_id]
    first = int(annotated.frames[0]) if start is None else start
    last = int(annotated.frames[-1]) if end is None else end
    resolve_span(seq, first, last)   # both frames in range, first <= last
    if start is None:
        try:
            first, _ = first_box_with_points(seq, [(int(k), annotated.box_at(k)) for k in annotated.frames if k <= last],
                                             config)
        except TrackingFailed:
            pass   # none: start at the first annotated box anyway (it is flagged on the prior only)
    init_box = annotated.box_at(first)
    if init_box is None:
        raise InputError(seq.root, f"track {object_id} has no box at frame {first} "
                                   f"(annotated frames {annotated.frames[0]}..{annotated.frames[-1]})")
    return TrackStart(object_id, annotated.label, init_box, first, last)


def track_result_to_track(seq: Sequence, result: TrackResult, object_id: str, init_box: Box,
                          label: str | None = None, config_extra: dict[str, Any] | None = None,
                          with_time_ms: bool = True) -> tuple[TrackHeader, ObjectTrack]:
    """The track file of ``result``: its header and its rows (world states at the frames' timestamps, per-frame
    diagnostics, the shape, the config used). Quality (``scores``) is clipped to [0, 1] (the schema's range).
    ``with_time_ms=False`` leaves out the per-frame tracker time (it differs run to run), so the file is
    reproducible byte for byte (the pipeline)."""
    estimates = result.estimates
    config = result.config.to_dict()
    if config_extra:
        config.update(config_extra)
    frames = [e.frame for e in estimates]
    flags = [tuple(e.flags) for e in estimates]
    track = ObjectTrack.from_states(
        object_id, label or "", tuple(float(v) for v in result.size), frames,
        [int(seq.frames[k].timestamp_ns) for k in frames],
        np.array([e.state.to_array() for e in estimates], dtype=np.float64).reshape(-1, 4),
        [frame_is_valid(f) for f in flags], flags, scores=np.clip([float(e.quality) for e in estimates], 0.0, 1.0),
        num_points=[int(e.num_points) for e in estimates],
        time_ms=[float(e.time_ms) for e in estimates] if with_time_ms else None,
        shape_points=result.shape, config={"tracker": config})
    header = TrackHeader(sequence=seq.id, start_frame=result.frames[0], end_frame=result.frames[-1],
                         init_box=init_box, config=config)
    return header, track


def refine_track_fixed_lag(seq: Sequence, result: TrackResult, lag: int) -> TrackResult:
    """Fixed-lag refinement of an online result (tracker.fixed_lag; the same states as streaming with lag)."""
    from tracker import refine_fixed_lag

    return refine_fixed_lag(seq, result, lag, result.config)


def refine_track_offline(seq: Sequence, result: TrackResult) -> TrackResult:
    """Offline refinement of an online result: all states jointly against the final shape (tracker.offline)."""
    from tracker import refine_offline

    return refine_offline(seq, result, result.config)


def write_track_result(directory: str | Path, seq: Sequence, result: TrackResult, object_id: str, init_box: Box,
                       label: str | None = None, offline: bool = False, with_time_ms: bool = True) -> Path:
    """Write ``directory/track.json`` and ``directory/shape.ply``; returns the json path.

    The config block records the mode: ``mode: online``, ``mode: lag`` with ``lag: N`` (fixed-lag refinement,
    each state final N frames later) or ``mode: offline`` (``result.mode``; ``offline=True`` forces offline);
    refined modes also say ``refined: true``.
    """
    mode = "offline" if offline else result.mode
    extra: dict[str, Any] = {"mode": mode}
    if mode != "online":
        extra["refined"] = True
    if mode == "lag":
        extra["lag"] = int(result.lag)
    header, track = track_result_to_track(seq, result, object_id, init_box, label, config_extra=extra,
                                          with_time_ms=with_time_ms)
    return write_track(directory, header, track)


def init_points(seq: Sequence, frame: int, box: Box) -> int:
    """Number of sweep points inside ``box`` at ``frame`` (for a warning when the init box is empty)."""
    return int(points_in_box(seq.points_world(frame), box).sum())


# ------------------------------------------------------------------------------------- shape growth

SHAPE_GROWTH_FILE = "shape_growth.json"


@dataclass(frozen=True)
class ShapeGrowth:
    """The tracker's aggregated shape (object frame) at a few frames: the start, the last change and evenly
    spaced changes between (a change is a key frame that added points). What the report's shape-growth
    figure draws."""

    object_id: str
    start_frame: int
    size: tuple[float, float, float]
    frames: tuple[int, ...]
    points: tuple[np.ndarray, ...]     # (M_i, 3) per frame

    def to_json(self) -> dict:
        return {"object_id": self.object_id, "start_frame": self.start_frame, "size": list(self.size),
                "snapshots": [{"frame": int(k), "points": np.round(p, 3).tolist()}
                              for k, p in zip(self.frames, self.points, strict=True)]}

    @classmethod
    def from_json(cls, doc: dict) -> "ShapeGrowth":
        snaps = doc["snapshots"]
        return cls(str(doc["object_id"]), int(doc["start_frame"]), tuple(float(v) for v in doc["size"]),
                   tuple(int(s["frame"]) for s in snaps),
                   tuple(np.asarray(s["points"], dtype=np.float64).reshape(-1, 3) for s in snaps))


class ShapeRecorder:
    """Keeps the tracker's shape after every frame that changed it (``on_frame`` of :func:`tracker.track` or of
    the multi-object pass); :meth:`growth` picks ``shots`` of those snapshots."""

    def __init__(self) -> None:
        self.snapshots: dict[int, np.ndarray] = {}

    def __call__(self, tracker, estimate) -> None:
        snapshots = self.snapshots
        if not snapshots or len(tracker.shape.points) != len(snapshots[max(snapshots)]):
            snapshots[estimate.frame] = tracker.shape_points()

    def growth(self, object_id: str, start: int, init_box: Box, shots: int = 4) -> ShapeGrowth:
        keys = sorted(self.snapshots)
        if len(keys) > shots:
            keys = sorted({keys[int(round(i))] for i in np.linspace(0, len(keys) - 1, shots)})
        return ShapeGrowth(object_id, start, tuple(float(v) for v in init_box.size), tuple(keys),
                           tuple(self.snapshots[k] for k in keys))


def track_with_shape_growth(seq: Sequence, init_box: Box, start: int, end: int, config: TrackerConfig,
                            object_id: str, shots: int = 4, detections: Detections | None = None
                            ) -> tuple[TrackResult, ShapeGrowth]:
    """:func:`tracker.track` (same frames, same result) that also keeps the shape after every frame that changed
    it, and returns ``shots`` of those snapshots."""
    recorder = ShapeRecorder()
    result = track(seq, init_box, start, end, config, detections=detections, on_frame=recorder)
    return result, recorder.growth(object_id, start, init_box, shots)


def write_shape_growth(directory: str | Path, growth: ShapeGrowth) -> Path:
    path = Path(directory) / SHAPE_GROWTH_FILE
    write_text(path, json.dumps(growth.to_json(), separators=(",", ":")))
    return path


def read_shape_growth(directory: str | Path) -> ShapeGrowth | None:
    """The record written by :func:`write_shape_growth`, or None when the track has none."""
    path = Path(directory) / SHAPE_GROWTH_FILE
    return ShapeGrowth.from_json(json.loads(path.read_text())) if path.is_file() else None


# ------------------------------------------------------------------------------------- multi-object pass

@dataclass(frozen=True)
class ObjectRequest:
    """One object of :func:`track_objects`: ``init_box`` (world frame) at frame ``start``, tracked through ``end``.

    ``annotated``: the object's annotated (frame, box) pairs; when given, the track starts at the first of them
    whose box holds ``min_points`` points (:class:`StartSearch`) and ``start``/``init_box`` are not used.
    ``max_frames``: track at most this many frames after the start. ``detections``: this object's own detections
    for the Detection term, instead of the pass's (e.g. an auto-label track's); ``initial_motion``: the per-frame
    motion [dx, dy, dz, dtheta] the motion prior starts from (:meth:`tracker.Tracker.start`)."""

    object_id: str
    init_box: Box
    start: int
    end: int
    annotated: tuple[tuple[int, Box], ...] = ()
    max_frames: int | None = None
    detections: Detections | None = None
    initial_motion: np.ndarray | None = None


@dataclass
class TrackOutcome:
    """One object's outcome of the pass: its result (in the pass's mode) or the reason it failed (``error``;
    ``lacks_points``: a :class:`TrackingFailed`, the object had too few LiDAR points to start or follow)."""

    object_id: str
    start: int = -1
    init_box: Box | None = None
    result: TrackResult | None = None
    growth: ShapeGrowth | None = None
    error: str | None = None
    lacks_points: bool = False
    seconds: float = 0.0          # this object's own CPU seconds (its steps and refinement; the shared reads not)


@dataclass
class PassTimes:
    """Where a pass spent its time (seconds): reading sweeps, their whole-sweep ground (once per sweep), the
    objects' online steps, and the refinement (fixed-lag windows, offline gathering and solves)."""

    read: float = 0.0
    ground: float = 0.0
    step: float = 0.0
    refine: float = 0.0
    sweeps: int = 0
    object_frames: int = 0

    def to_json(self) -> dict:
        return {"read_s": round(self.read, 4), "ground_s": round(self.ground, 4), "step_s": round(self.step, 4),
                "refine_s": round(self.refine, 4), "sweeps": self.sweeps, "object_frames": self.object_frames}


MODES = ("online", "lag", "offline")


class _Live:
    """An object during the pass: its start search, then its tracker, recorder and refinement state."""

    def __init__(self, request: ObjectRequest, seq: Sequence, config: TrackerConfig, min_points: int | None) -> None:
        self.request = request
        self.out = TrackOutcome(request.object_id)
        self.search = (StartSearch(seq, request.annotated, config, min_points or 0) if request.annotated
                       else None)
        self.first = min(self.search.candidates, default=None) if self.search else request.start
        self.tracker: Tracker | None = None
        self.end = -1
        self.estimates: list = []
        self.recorder: ShapeRecorder | None = None
        self.smoother = None              # mode "lag": tracker.fixed_lag.FixedLagSmoother
        self.final: list = []             # mode "lag": the estimates that became final
        self.regions: list[np.ndarray] = []   # mode "offline": each frame's region points (its local crops)
        self.region_times: list = []          # ... and their capture times (with refinement.offline.own_motion_spread)
        self.previous: tuple[int, np.ndarray] | None = None

    @property
    def waiting(self) -> bool:
        return self.out.start < 0 and self.out.error is None


def _pose(seq: Sequence, k: int) -> tuple[int, np.ndarray]:
    info = seq.frames[k]
    return int(info.timestamp_ns), np.asarray(info.world_from_ego, dtype=np.float64)


def track_objects(seq: Sequence, requests: list[ObjectRequest], config: TrackerConfig, mode: str = "online",
                  lag: int = 10, detections: Detections | None = None, min_points: int | None = MIN_INIT_POINTS,
                  shape_growth: bool = False, on_done=None, progress=None) -> tuple[list[TrackOutcome], PassTimes]:
    """Track many objects of ``seq`` in ONE pass over its sweeps: each sweep is read once and its whole-sweep
    ground computed once (the tracker's per-sweep cache, shared by every tracker on the sweep), every live
    object is stepped (objects start and end at different frames). The result of each object is the one
    tracking it alone gives (:func:`tracker.track`, then :func:`refine_track_fixed_lag` with ``mode="lag"`` or
    :func:`refine_track_offline` with ``mode="offline"``), bit for bit: the refinements are fed from the sweeps
    as the pass reads them (the fixed-lag window as it slides; offline, each object keeps only its region points
    per frame until its solve; with backward passes, ``refinement.backward``, the frames of a lost run are read
    again). Refinement applies to ``config.method == "sot"``; other methods track alone.

    An object whose start box (or every annotated box, see :class:`ObjectRequest`) holds fewer than
    ``min_points`` points, that is lost after its start (no points in any later frame), or whose tracking raises,
    fails alone (``TrackOutcome.error``). ``min_points=None`` drops the two point checks (evaluation scores every
    track as :func:`tracker.track` returns it; annotated objects then start at their first annotated box). ``shape_growth``: also record :class:`ShapeGrowth`. ``on_done``:
    callable(TrackOutcome) as each object finishes (then its result is not kept in the returned list, so a long
    pass holds only live objects). ``progress``: callable(iterable) -> iterable over the frames.
    Returns the objects' outcomes in request order and where the time went."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, not {mode!r}")
    times = PassTimes()
    refine = mode if config.method == "sot" else "online"
    if config.method == "det":
        return _track_alone(seq, requests, config, detections, min_points, shape_growth, on_done, times)
    live = [_Live(r, seq, config, min_points) for r in requests]
    for o in live:
        if o.first is None:
            o.out.error, o.out.lacks_points = str(o.search.failure()), True
    sweep_ground = config.ground.remover == "sweep"
    ground_args = config.ground.sweep_args() if sweep_ground else ()
    last = max([o.request.end for o in live if o.first is not None], default=-1)
    first = min([o.first for o in live if o.first is not None], default=last + 1)
    results: list[TrackOutcome] = [o.out for o in live]
    frames = range(first, last + 1)
    for k in (progress(frames) if progress else frames):
        starting = [o for o in live if o.waiting and (k in o.search.candidates if o.search else k == o.first)]
        stepping = [o for o in live if o.tracker is not None and o.out.start < k <= o.end]
        if not starting and not stepping:
            continue
        t0 = time.thread_time()
        frame = seq.lidar_frame(k)
        t1 = time.thread_time()
        if sweep_ground and frame.has_sweep and len(frame.points_ego):
            sweep_ground_once(seq, frame, ground_args)   # every tracker on the sweep reuses it
        t2 = time.thread_time()
        times.read += t1 - t0
        times.ground += t2 - t1
        times.sweeps += 1
        for o in starting:
            _start(o, seq, k, frame, config, refine, lag, shape_growth, times)
            if o.tracker is not None:
                _refine_frame(o, seq, frame, config, refine, times)
        for o in stepping:
            try:
                t = time.thread_time()
                own = detections if o.request.detections is None else o.request.detections
                estimate = o.tracker.step(frame, None if own is None else own.get(k))
                o.estimates.append(estimate)
                if o.recorder is not None:
                    o.recorder(o.tracker, estimate)
                dt = time.thread_time() - t
                times.step += dt
                times.object_frames += 1
                o.out.seconds += dt
                _refine_frame(o, seq, frame, config, refine, times)
            except Exception as exc:  # noqa: BLE001 - one object's failure does not stop the others
                _fail(o, f"{type(exc).__name__}: {' '.join(str(exc).split())}")
        for o in starting + stepping:
            if o.tracker is not None and o.out.error is None and k == o.end:
                _finish(o, seq, config, refine, lag, min_points, times, on_done)
    for o in live:
        if o.waiting and o.search is not None:   # no candidate frame held enough points
            o.out.error, o.out.lacks_points = str(o.search.failure()), True
    return results, times


def sweep_ground_once(seq: Sequence, frame: LidarFrame, ground_args: tuple) -> np.ndarray:
    """The whole-sweep ground mask of ``frame`` (:func:`tracker.cached_sweep_ground_mask` with ``ground_args``),
    made the tracker's cached mask for the sweep: taken from the sweep cache when ``seq`` reads through one and
    it holds the mask, else computed once and stored there (every process and later run reuses it)."""
    from tracker import remember_sweep_ground_mask, sweep_ground_mask

    from .io.sweep_cache import SweepCache, code_digest

    cache = SweepCache.of(seq)
    if cache is None:
        return cached_sweep_ground_mask(frame.points_ego, *ground_args)
    # the mask's name: its parameters and the ground code (a changed algorithm never reads an old mask)
    digest = hashlib.sha256(repr(tuple(ground_args)).encode() + code_digest(sweep_ground_mask))
    name = "ground-" + digest.hexdigest()[:16]
    mask = cache.load_mask(frame.index, name)
    if mask is not None and len(mask) == len(frame.points_ego):
        return remember_sweep_ground_mask(frame.points_ego, mask, *ground_args)
    mask = cached_sweep_ground_mask(frame.points_ego, *ground_args)
    cache.store_mask(frame.index, name, mask)
    return mask


def _fail(o: _Live, error: str, lacks_points: bool = False) -> None:
    o.out.error, o.out.lacks_points = error, lacks_points
    o.tracker, o.estimates, o.smoother, o.regions, o.region_times = None, [], None, [], []


def _start(o: _Live, seq: Sequence, k: int, frame: LidarFrame, config: TrackerConfig, refine: str, lag: int,
           shape_growth: bool, times: PassTimes) -> None:
    """Start ``o`` at ``frame``, position ``k`` of ``seq`` (an annotated candidate or its given start), as
    :func:`tracker.track` would (the pass counts positions, not ``frame.index``: a source may serve its frames in
    another order, e.g. reversed in time)."""
    from tracker import FixedLagSmoother

    t = time.thread_time()
    try:
        started = None
        if o.search is not None:
            started = o.search.attempt(frame)
            if started is None:
                return
            box = o.search.candidates[k]
        else:
            if not frame.has_sweep:
                _fail(o, f"the start frame {k} has no sweep; nothing to track", lacks_points=True)
                return
            box = o.request.init_box
        previous = _pose(seq, k - 1) if config.deskew and k > 0 else None
        if started is None or previous is not None:   # the search's start had no previous pose (no de-skew)
            tracker = Tracker(config)
            estimate = tracker.start(frame, box, previous, o.request.initial_motion)
        else:
            tracker, estimate = started
    except Exception as exc:  # noqa: BLE001
        _fail(o, f"{type(exc).__name__}: {' '.join(str(exc).split())}")
        return
    dt = time.thread_time() - t
    times.step += dt
    o.out.seconds += dt
    o.tracker, o.out.start, o.out.init_box = tracker, k, box
    end = o.request.end
    o.end = end if o.request.max_frames is None else min(end, k + o.request.max_frames)
    o.estimates = [estimate]
    if shape_growth:
        o.recorder = ShapeRecorder()
        o.recorder(tracker, estimate)
    if refine == "lag":
        o.smoother = FixedLagSmoother(config, lag, np.asarray(box.size))
        if config.deskew and k > 0:   # as tracker.refine_fixed_lag: the pose before the start de-skews it
            o.smoother._previous = _pose(seq, k - 1)


def _refine_frame(o: _Live, seq: Sequence, frame: LidarFrame, config: TrackerConfig, refine: str,
                  times: PassTimes) -> None:
    """Feed the object's newest estimate to its refinement with the sweep in hand."""
    from tracker import frame_region_points_timed

    if refine == "online":
        return
    t = time.thread_time()
    # the region comes from the step's own crop when it holds the region, else from the part of the sweep that
    # can reach it: the same points in the same order as from the whole sweep in the world frame, which the
    # per-object refinements use (transform_points is element-wise: a row's result does not depend on the others);
    # de-skewed sweeps take the per-object refinements' own path (no crop)
    crop = None if config.deskew else o.tracker.last_crop
    estimate = o.estimates[-1]
    if refine == "lag":
        o.final += o.smoother.add(frame, estimate, crop=crop)
    else:
        params = config.refinement.offline
        points, when = frame_region_points_timed(frame, estimate.box, config, params, o.previous, crop=crop,
                                                 with_times=params.own_motion_spread > 0)
        o.regions.append(points)
        o.region_times.append(when)
        o.previous = _pose(seq, frame.index)
    dt = time.thread_time() - t
    times.refine += dt
    o.out.seconds += dt


def _finish(o: _Live, seq: Sequence, config: TrackerConfig, refine: str, lag: int, min_points: int | None,
            times: PassTimes, on_done) -> None:
    """The object's last frame: the pipeline's checks, the offline solve, its result; then release it."""
    from tracker import refine_offline

    online = TrackResult(o.estimates, o.out.init_box.size, o.tracker.shape_points(), config)
    why = None if min_points is None else lacking_points(online, min_points)
    if why is not None:
        _fail(o, why, lacks_points=True)
    else:
        t = time.thread_time()
        try:
            if refine == "lag":
                o.final += o.smoother.finish()
                result = TrackResult(o.final, np.asarray(online.size), o.smoother.shape, config, mode="lag", lag=lag)
            elif refine == "offline":
                # backward passes re-read the frames of a lost run (and gather points around the fused boxes)
                source = seq if config.refinement.backward != "none" else None
                result = refine_offline(source, online, config, points=o.regions, point_times=o.region_times)
            else:
                result = online
        except Exception as exc:  # noqa: BLE001 - one object's failure does not stop the others
            _fail(o, f"{type(exc).__name__}: {' '.join(str(exc).split())}")
            result = None
        dt = time.thread_time() - t
        times.refine += dt
        o.out.seconds += dt
        if result is not None:
            o.out.result = result
            if o.recorder is not None:
                o.out.growth = o.recorder.growth(o.request.object_id, o.out.start, o.out.init_box)
            o.tracker, o.estimates, o.smoother, o.regions, o.final, o.recorder = None, [], None, [], [], None
            o.region_times = []
    if on_done is not None:
        on_done(o.out)
        o.out.result = None


def lacking_points(result: TrackResult, min_points: int) -> str | None:
    """Why an online ``result`` is no track (fewer than ``min_points`` points in the start box, or no points in
    any later frame), or None."""
    first, later = result.estimates[0], result.estimates[1:]
    if first.num_points < min_points:
        return (f"{first.num_points} LiDAR points in the initial box at frame {first.frame} (need at least "
                f"{min_points}); nothing to track")
    if later and all("no_points" in e.flags for e in later):
        return "lost after the start frame (no points in any later frame)"
    return None


def _track_alone(seq: Sequence, requests: list[ObjectRequest], config: TrackerConfig, detections, min_points: int | None,
                 shape_growth: bool, on_done, times: PassTimes) -> tuple[list[TrackOutcome], PassTimes]:
    """Methods other than SOTracker's (the Det baseline): each object tracked alone through :func:`tracker.track`."""
    outs = []
    for r in requests:
        out = TrackOutcome(r.object_id)
        t = time.thread_time()
        try:
            start, box = (first_box_with_points(seq, r.annotated, config, min_points or 0) if r.annotated
                          else (r.start, r.init_box))
            end = r.end if r.max_frames is None else min(r.end, start + r.max_frames)
            recorder = ShapeRecorder() if shape_growth else None
            own = detections if r.detections is None else r.detections
            result = track(seq, box, start, end, config, detections=own, initial_motion=r.initial_motion,
                           on_frame=recorder)
            why = None if min_points is None else lacking_points(result, min_points)
            if why is not None:
                raise TrackingFailed(why)
            out.result, out.start, out.init_box = result, start, box
            if recorder is not None:
                out.growth = recorder.growth(r.object_id, start, box)
            times.object_frames += end - start
        except TrackingFailed as exc:
            out.error, out.lacks_points = str(exc), True
        except Exception as exc:  # noqa: BLE001
            out.error = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
        out.seconds = time.thread_time() - t
        times.step += out.seconds
        outs.append(out)
        if on_done is not None:
            on_done(out)
            out.result = None
    return outs, times
