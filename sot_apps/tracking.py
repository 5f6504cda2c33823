"""Run SOTracker on a :class:`~sot_apps.io.sequence.Sequence` and write ``DIR/track.json`` + ``DIR/shape.ply``."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from tracker.config import TrackerConfig
from tracker.geometry import Box, points_in_box
from tracker.sotracker import TrackResult, track

from .errors import InputError
from .io.sequence import Sequence
from .io.tracks import FrameRecord, Size, TrackFile, write_track

__all__ = ["parse_init_box", "resolve_span", "track_sequence", "refine_track_fixed_lag", "refine_track_offline",
           "track_result_to_trackfile", "write_track_result"]


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
    """Track ``init_box`` (world frame at ``start``) through frame ``end`` (inclusive)."""
    config = config or TrackerConfig()
    start, end = resolve_span(seq, start, end)
    if not np.isfinite(init_box.to_array()).all() or min(init_box.length, init_box.width, init_box.height) <= 0:
        raise InputError(None, f"init box must be finite with a positive size, got {init_box}")
    wrap = None
    if progress:
        from tqdm import tqdm

        def wrap(frames):
            return tqdm(frames, desc="track", unit="frame", leave=False)
    return track(seq, init_box, start, end, config, progress=wrap)


def track_result_to_trackfile(seq: Sequence, result: TrackResult, object_id: str, init_box: Box,
                              label: str | None = None, config_extra: dict[str, Any] | None = None) -> TrackFile:
    """The track file record of ``result`` (world states, per-frame diagnostics, the config used)."""
    records = [FrameRecord(frame=e.frame, timestamp_ns=int(seq.frames[e.frame].timestamp_ns), state=e.state,
                           num_points=int(e.num_points), quality=float(e.quality), flags=list(e.flags),
                           time_ms=float(e.time_ms)) for e in result.estimates]
    config = result.config.to_dict()
    if config_extra:
        config.update(config_extra)
    length, width, height = (float(v) for v in result.size)
    return TrackFile(sequence=seq.id, object_id=object_id, size=Size(length, width, height),
                     start_frame=result.frames[0], end_frame=result.frames[-1], init_box=init_box, config=config,
                     frames=records, label=label)


def refine_track_fixed_lag(seq: Sequence, result: TrackResult, lag: int) -> TrackResult:
    """Fixed-lag refinement of an online result (tracker.fixed_lag; the same states as streaming with lag)."""
    from tracker.fixed_lag import refine_fixed_lag

    return refine_fixed_lag(seq, result, lag, result.config)


def refine_track_offline(seq: Sequence, result: TrackResult) -> TrackResult:
    """Offline refinement of an online result: all states jointly against the final shape (tracker.offline)."""
    from tracker.offline import refine_offline

    return refine_offline(seq, result, result.config)


def write_track_result(directory: str | Path, seq: Sequence, result: TrackResult, object_id: str, init_box: Box,
                       label: str | None = None, offline: bool = False) -> Path:
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
    trackfile = track_result_to_trackfile(seq, result, object_id, init_box, label, config_extra=extra)
    return write_track(directory, trackfile, result.shape)


def init_points(seq: Sequence, frame: int, box: Box) -> int:
    """Number of sweep points inside ``box`` at ``frame`` (for a warning when the init box is empty)."""
    return int(points_in_box(seq.points_world(frame), box).sum())
