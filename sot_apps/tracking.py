"""Run SOTracker on a :class:`~sot_apps.io.sequence.Sequence` and write ``DIR/track.json`` + ``DIR/shape.ply``.

The one writer of track files: ``sot-apps track`` and the pipeline's tracking stage both call
:func:`write_track_result`, and both start an annotated object at :func:`first_box_with_points`.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tracker import Box, Detections, TrackResult, TrackerConfig, points_in_box, track

from .errors import InputError
from .io.sequence import Sequence
from .io.atomic import write_text
from .io.tracks import FrameRecord, Size, TrackFile, write_track

__all__ = ["ShapeGrowth", "track_with_shape_growth", "write_shape_growth", "read_shape_growth", "parse_init_box",
           "VEHICLE_SIZE_RANGE_M", "implausible_size", "check_vehicle_size", "resolve_span", "track_sequence",
           "refine_track_fixed_lag", "refine_track_offline", "track_result_to_trackfile",
           "write_track_result", "first_box_with_points", "TrackingFailed", "MIN_INIT_POINTS"]

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


def first_box_with_points(seq: Sequence, annotated: list[tuple[int, Box]] | tuple[tuple[int, Box], ...],
                          config: TrackerConfig, min_points: int = MIN_INIT_POINTS) -> tuple[int, Box]:
    """The first annotated (frame, box) whose box holds ``min_points`` non-ground points, as the tracker counts
    them at its start; the last annotated frame cannot start a track. None such: :class:`TrackingFailed`."""
    from tracker import Tracker

    best = (0, annotated[0][0])
    for k, box in annotated[:-1]:
        if not seq.frames[k].has_sweep:  # a frame without a sweep cannot start a track
            continue
        n = Tracker(config).start(seq.lidar_frame(k), box).num_points
        if n >= min_points:
            return k, box
        best = max(best, (n, k), key=lambda b: b[0])
    last = annotated[-2][0] if len(annotated) > 1 else annotated[0][0]
    raise TrackingFailed(f"fewer than {min_points} LiDAR points in every annotated box (frames {annotated[0][0]}..{last}; "
                         f"at most {best[0]} at frame {best[1]}); nothing to track")


def track_result_to_trackfile(seq: Sequence, result: TrackResult, object_id: str, init_box: Box,
                              label: str | None = None, config_extra: dict[str, Any] | None = None,
                              with_time_ms: bool = True) -> TrackFile:
    """The track file record of ``result`` (world states, per-frame diagnostics, the config used). Quality is
    clipped to [0, 1] (the schema's range). ``with_time_ms=False`` leaves out the per-frame tracker time (it
    differs run to run), so the file is reproducible byte for byte (the pipeline)."""
    records = [FrameRecord(frame=e.frame, timestamp_ns=int(seq.frames[e.frame].timestamp_ns), state=e.state,
                           num_points=int(e.num_points), quality=float(np.clip(e.quality, 0.0, 1.0)),
                           flags=list(e.flags), time_ms=float(e.time_ms) if with_time_ms else None)
               for e in result.estimates]
    config = result.config.to_dict()
    if config_extra:
        config.update(config_extra)
    length, width, height = (float(v) for v in result.size)
    return TrackFile(sequence=seq.id, object_id=object_id, size=Size(length, width, height),
                     start_frame=result.frames[0], end_frame=result.frames[-1], init_box=init_box, config=config,
                     frames=records, label=label)


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
    trackfile = track_result_to_trackfile(seq, result, object_id, init_box, label, config_extra=extra,
                                          with_time_ms=with_time_ms)
    return write_track(directory, trackfile, result.shape)


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
                              for k, p in zip(self.frames, self.points)]}

    @classmethod
    def from_json(cls, doc: dict) -> "ShapeGrowth":
        snaps = doc["snapshots"]
        return cls(str(doc["object_id"]), int(doc["start_frame"]), tuple(float(v) for v in doc["size"]),
                   tuple(int(s["frame"]) for s in snaps),
                   tuple(np.asarray(s["points"], dtype=np.float64).reshape(-1, 3) for s in snaps))


def track_with_shape_growth(seq: Sequence, init_box: Box, start: int, end: int, config: TrackerConfig,
                            object_id: str, shots: int = 4, detections: Detections | None = None
                            ) -> tuple[TrackResult, ShapeGrowth]:
    """:func:`tracker.track` (same frames, same result) that also keeps the shape after every frame that changed
    it, and returns ``shots`` of those snapshots."""
    snapshots: dict[int, np.ndarray] = {}

    def keep_changed_shape(tracker, estimate) -> None:
        if not snapshots or len(tracker.shape.points) != len(snapshots[max(snapshots)]):
            snapshots[estimate.frame] = tracker.shape_points()

    result = track(seq, init_box, start, end, config, detections=detections, on_frame=keep_changed_shape)
    keys = sorted(snapshots)
    if len(keys) > shots:
        keys = sorted({keys[int(round(i))] for i in np.linspace(0, len(keys) - 1, shots)})
    growth = ShapeGrowth(object_id, start, tuple(float(v) for v in init_box.size), tuple(keys),
                         tuple(snapshots[k] for k in keys))
    return result, growth


def write_shape_growth(directory: str | Path, growth: ShapeGrowth) -> Path:
    path = Path(directory) / SHAPE_GROWTH_FILE
    write_text(path, json.dumps(growth.to_json(), separators=(",", ":")))
    return path


def read_shape_growth(directory: str | Path) -> ShapeGrowth | None:
    """The record written by :func:`write_shape_growth`, or None when the track has none."""
    path = Path(directory) / SHAPE_GROWTH_FILE
    return ShapeGrowth.from_json(json.loads(path.read_text())) if path.is_file() else None
