"""What ``sot-apps info`` reports about a sequence: frames, timing, points, cameras, annotated tracks.

Vehicle and motion rules: :mod:`sot_apps.objects.selection` (the same rule as planning, ``bank build
--all`` and ``eval --all-moving``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from tqdm import tqdm

from tracker import points_in_box

from .io.object_track import ObjectTrack
from .io.sequence import Sequence
from .objects.selection import DEFAULT_SELECTION, Selection

__all__ = ["TrackSummary", "CameraSummary", "SequenceSummary", "summarize_sequence", "summarize_tracks"]

@dataclass(frozen=True)
class TrackSummary:
    track_id: str
    label: str
    vehicle: bool
    num_frames: int
    first_frame: int
    last_frame: int
    mean_points_first10: float
    displacement_m: float
    max_displacement_m: float
    moving: bool
    motion: str
    stationary_flag: bool | None


@dataclass(frozen=True)
class CameraSummary:
    name: str
    width: int
    height: int
    num_frames: int
    mean_offset_to_lidar_ms: float


@dataclass(frozen=True)
class SequenceSummary:
    id: str
    format: str
    root: str
    num_frames: int
    time_span_s: float
    rate_hz: float
    points_min: int | None
    points_median: float | None
    points_max: int | None
    missing_sweeps: list[int]
    empty_sweeps: list[int] | None
    cameras: list[CameraSummary]
    tracks: list[TrackSummary]

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def _mean_points_first_frames(seq: Sequence, tracks: dict[str, ObjectTrack], first_n: int,
                              progress: bool) -> dict[str, float]:
    """Mean number of points inside each track's GT box over its first ``first_n`` annotated frames.

    Reads only the frames needed (the union of those first frames), each once; frames without a
    sweep do not count.
    """
    needed: dict[int, list[str]] = {}
    for tid, track in tracks.items():
        for k in [k for k in track.frames if seq.frames[k].has_sweep][:first_n]:
            needed.setdefault(k, []).append(tid)
    counts: dict[str, list[int]] = {tid: [] for tid in tracks}
    for k in tqdm(sorted(needed), desc="points in boxes", unit="frame", disable=not progress, leave=False):
        points = seq.points_world(k)
        order = np.argsort(points[:, 0], kind="stable")
        xs = points[order, 0]
        for tid in needed[k]:
            box = tracks[tid].box_at(k)
            radius = 0.5 * float(np.hypot(box.length, box.width)) + 1e-6
            lo, hi = np.searchsorted(xs, [box.x - radius, box.x + radius])
            counts[tid].append(int(points_in_box(points[order[lo:hi]], box).sum()))
    return {tid: float(np.mean(c)) if c else 0.0 for tid, c in counts.items()}


def summarize_tracks(seq: Sequence, first_n: int = 10, vehicles_only: bool = False,
                     progress: bool = True, selection: Selection = DEFAULT_SELECTION) -> list[TrackSummary]:
    """Annotated tracks, vehicles first, then moving first, then by mean points (descending).

    Reads only the sweeps of each track's first ``first_n`` frames.
    """
    tracks = seq.tracks()
    if vehicles_only:
        tracks = {tid: t for tid, t in tracks.items() if selection.is_vehicle(t.label)}
    stationary: dict[str, list[bool]] = {}
    for frame_annotations in seq.annotations or []:
        for ann in frame_annotations:
            if ann.track_id in tracks and ann.stationary is not None:
                stationary.setdefault(ann.track_id, []).append(bool(ann.stationary))
    points = _mean_points_first_frames(seq, tracks, first_n, progress)
    stamps = seq.timestamps_ns
    out = []
    for tid, track in tracks.items():
        moving, displacement, max_displacement = dataclasses.astuple(selection.track_motion(track, stamps))
        vehicle = selection.is_vehicle(track.label)
        flags = stationary.get(tid)
        out.append(TrackSummary(
            track_id=tid, label=track.label, vehicle=vehicle, num_frames=len(track.frames),
            first_frame=int(track.frames[0]), last_frame=int(track.frames[-1]), mean_points_first10=points[tid],
            displacement_m=displacement, max_displacement_m=max_displacement, moving=moving,
            motion="moving" if moving else ("parked" if vehicle else "static"),
            stationary_flag=None if not flags else sum(flags) * 2 > len(flags)))
    out.sort(key=lambda t: (not t.vehicle, not t.moving, -t.mean_points_first10, t.track_id))
    return out


def summarize_sequence(seq: Sequence, point_stats: bool = True, vehicles_only: bool = False,
                       progress: bool = True) -> SequenceSummary:
    """Everything ``sot-apps info`` prints. ``point_stats`` reads every sweep (with a progress bar).

    ``missing_sweeps``: frames without a sweep (from the reader, no sweep read); ``empty_sweeps``:
    frames whose sweep has zero points (None without ``point_stats``).
    """
    stamps = seq.timestamps_ns
    span = (int(stamps[-1]) - int(stamps[0])) * 1e-9 if len(stamps) else 0.0
    rate = (len(stamps) - 1) / span if span > 0 else 0.0
    pmin = pmed = pmax = None
    missing = seq.missing_sweeps()
    empty = None
    if point_stats:
        with_sweep = [k for k in range(len(seq)) if seq.frames[k].has_sweep]
        counts = np.array([len(seq.sweep(k)) for k in tqdm(with_sweep, desc="reading sweeps", unit="frame",
                                                            disable=not progress, leave=False)], dtype=np.int64)
        empty = [k for k, n in zip(with_sweep, counts, strict=True) if n == 0]
        if len(counts):
            pmin, pmed, pmax = int(counts.min()), float(np.median(counts)), int(counts.max())
    cameras = []
    for name, cam in seq.cameras.items():
        offsets = [(cf.timestamp_ns - seq.frames[k].timestamp_ns) * 1e-6 for k, cf in enumerate(cam.frames)]
        cameras.append(CameraSummary(name=name, width=cam.width, height=cam.height, num_frames=len(cam.frames),
                                     mean_offset_to_lidar_ms=float(np.mean(offsets)) if offsets else 0.0))
    tracks = summarize_tracks(seq, vehicles_only=vehicles_only, progress=progress)
    return SequenceSummary(id=seq.id, format=seq.format, root=str(seq.root), num_frames=len(seq), time_span_s=span,
                           rate_hz=rate, points_min=pmin, points_median=pmed, points_max=pmax,
                           missing_sweeps=missing, empty_sweeps=empty, cameras=cameras,
                           tracks=tracks)
