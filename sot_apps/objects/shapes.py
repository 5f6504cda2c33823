"""Object shapes from annotated (or tracked) boxes: the LiDAR points in each box, in the object frame.

One pass over the sweeps gathers, for every (track, frame), the points near the box and their capture times.
Each box is then stamped with its CAPTURE TIME, the median capture time of the points inside it
(PandaSet's boxes, and the synthetic world's, describe the object when the beam passed it; a spinning LiDAR
sweeps for 100 ms). With ``per_point_time`` each point goes into the object frame of the box trajectory at
ITS OWN capture time, which undoes the rolling-scan smear of a moving vehicle; otherwise the box of its
frame is used. The margins (:class:`BoxMargin`) say which points are near, which stamp a box and which are kept.

Used by flow (``objects_from_annotations``), the bank (``track_points_by_frame``) and the motion export
(``aggregate_shape``). The tracker's pseudo ground truth has its own (tracker/ imports nothing from here).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable

import numpy as np

from tracker import Box, points_in_box

from ..io.object_track import ObjectTrack
from .trajectory import EndMode, Trajectory

__all__ = ["BoxMargin", "ShapeParams", "box_capture_time", "in_box", "object_points_by_frame"]


@dataclass(frozen=True)
class BoxMargin:
    """A box grown per axis: half-size * ``scale`` + ``pad`` (metres)."""

    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    pad: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def half(self, size: np.ndarray) -> np.ndarray:
        return np.asarray(size, dtype=np.float64) / 2.0 * np.asarray(self.scale) + np.asarray(self.pad)


def in_box(local: np.ndarray, size: np.ndarray, margin: BoxMargin = BoxMargin()) -> np.ndarray:
    """Mask of object-frame points inside the box of ``size`` grown by ``margin`` (:func:`tracker.points_in_box`
    on that box at the object frame's origin)."""
    return points_in_box(local, Box(0.0, 0.0, 0.0, 0.0, *(2.0 * margin.half(size))))


def box_capture_time(frame_time_ns: int, offsets_inside_ns: np.ndarray, min_points: int = 1) -> int:
    """The box's capture time: the frame time plus the median time offset of the points inside it, or the
    frame time when fewer than ``min_points`` are inside."""
    if len(offsets_inside_ns) < max(min_points, 1):
        return int(frame_time_ns)
    return int(frame_time_ns) + int(np.median(offsets_inside_ns))


@dataclass(frozen=True)
class ShapeParams:
    """How points are gathered: ``near`` (candidates), ``stamp`` (points that time the box), ``keep`` (points
    kept, tested in the object frame); points lower than ``ground_clearance`` above the box bottom are dropped."""

    near: BoxMargin = field(default_factory=lambda: BoxMargin(pad=(2.0, 2.0, 0.0)))
    stamp: BoxMargin = field(default_factory=lambda: BoxMargin(pad=(0.1, 0.1, 0.0)))
    keep: BoxMargin = field(default_factory=lambda: BoxMargin(pad=(0.1, 0.1, 0.0)))
    ground_clearance: float | None = 0.2    # None: keep points down to the box bottom (and below, by the margin)
    capture_time: bool = True          # False: every box is stamped with its frame time
    min_stamp_points: int = 3
    per_point_time: bool = True        # False: the box of the point's frame, whatever its capture time
    end: EndMode = "hold"              # how the box trajectory continues beyond its stamps
    max_extrapolation_ns: int | None = None


def object_points_by_frame(seq, tracks: dict[str, ObjectTrack], params: ShapeParams = ShapeParams(),
                           point_frames: Iterable[int] | None = None, progress: bool = False
                           ) -> tuple[dict[str, dict[int, np.ndarray]], dict[str, ObjectTrack]]:
    """Per track (an ObjectTrack: boxes at frames) and frame, the object-frame points of its box; and each track
    stamped with its boxes' capture times (:meth:`ObjectTrack.restamped`; ``params.capture_time=False``: the frame
    times). ``point_frames`` (default: all) limits the frames whose points are returned; every
    box is stamped. Each sweep is read once."""
    from tqdm import tqdm

    from tracker import transform_points

    wanted = None if point_frames is None else set(int(k) for k in point_frames)
    by_frame: dict[int, list[str]] = {}
    for tid, track in tracks.items():
        for k in track.frames:
            by_frame.setdefault(int(k), []).append(tid)
    stamps: dict[str, dict[int, int]] = {tid: {} for tid in tracks}
    near_points: dict[str, dict[int, tuple[np.ndarray, np.ndarray]]] = {tid: {} for tid in tracks}
    for k in tqdm(sorted(by_frame), desc="points in boxes", unit="frame", disable=not progress, leave=False):
        sweep = seq.sweep(k)
        world = transform_points(seq.frames[k].world_from_ego, sweep.xyz)
        frame_ns = int(seq.frames[k].timestamp_ns)
        offsets = sweep.time_offset_ns if sweep.time_offset_ns is not None else np.zeros(len(world), np.int64)
        for tid in by_frame[k]:
            box = tracks[tid].box_at(k)
            local = transform_points(box.object_from_world(), world)
            near = np.flatnonzero(in_box(local, box.size, params.near))
            stamped = near[in_box(local[near], box.size, params.stamp)]
            stamps[tid][k] = (box_capture_time(frame_ns, offsets[stamped], params.min_stamp_points)
                              if params.capture_time and sweep.time_offset_ns is not None else frame_ns)
            if near.size and (wanted is None or k in wanted):
                near_points[tid][k] = (local[near] if not params.per_point_time else world[near],
                                       frame_ns + offsets[near])
    out: dict[str, dict[int, np.ndarray]] = {tid: {} for tid in tracks}
    stamped: dict[str, ObjectTrack] = {}
    for tid, track in tracks.items():
        stamped[tid] = track.restamped([stamps[tid][int(k)] for k in track.frames])
        trajectory = Trajectory.from_track(stamped[tid], params.end, params.max_extrapolation_ns)
        for k, (pts, t) in near_points[tid].items():
            box = track.box_at(k)
            local = trajectory.object_from_world_points(pts, t) if params.per_point_time else pts
            keep = in_box(local, box.size, params.keep)
            if params.ground_clearance is not None:
                keep &= local[:, 2] > -box.height / 2 + params.ground_clearance
            if keep.any():
                out[tid][k] = local[keep]
    return out, stamped
