"""Run SOTracker on a :class:`~sot_apps.io.sequence.Sequence` and write ``DIR/track.json`` + ``DIR/shape.ply``.

The one writer of track files: ``sot-apps track`` and the pipeline's tracking stage both call
:func:`write_track_result`, and both start an annotated object at :func:`first_box_with_points`.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from tracker import Box, TrackResult, TrackerConfig, points_in_box, track

from .errors import InputError
from .io.sequence import Sequence
from .io.tracks import FrameRecord, Size, TrackFile, write_track

__all__ = ["parse_init_box", "resolve_span", "track_sequence", "refine_track_offline", "track_result_to_trackfile",
           "write_track_result", "first_box_with_points", "TrackingFailed", "MIN_INIT_POINTS"]

MIN_INIT_POINTS = 5   # non-ground LiDAR points the tracker needs in its initial box


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
                   config: TrackerConfig | None = None, progress: bool = True) -> TrackResult:
    """Track ``init_box`` (world frame at ``start``) through frame ``end`` (inclusive).

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
    return track(seq, init_box, start, end, config, progress=wrap)


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


def refine_track_offline(seq: Sequence, result: TrackResult) -> TrackResult:
    """Offline refinement of an online result: all states jointly against the final shape (tracker.offline)."""
    from tracker import refine_offline

    return refine_offline(seq, result, result.config)


def write_track_result(directory: str | Path, seq: Sequence, result: TrackResult, object_id: str, init_box: Box,
                       label: str | None = None, offline: bool = False, with_time_ms: bool = True) -> Path:
    """Write ``directory/track.json`` and ``directory/shape.ply``; returns the json path.

    ``offline`` records in the config block that ``result`` was refined offline (``mode: offline``).
    """
    extra = {"mode": "offline", "refined": True} if offline else None
    trackfile = track_result_to_trackfile(seq, result, object_id, init_box, label, config_extra=extra,
                                          with_time_ms=with_time_ms)
    return write_track(directory, trackfile, result.shape)


def init_points(seq: Sequence, frame: int, box: Box) -> int:
    """Number of sweep points inside ``box`` at ``frame`` (for a warning when the init box is empty)."""
    return int(points_in_box(seq.points_world(frame), box).sum())
