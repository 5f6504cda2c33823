"""Inputs of the motion export: tracker outputs (track directories) or ground-truth annotations.

Both become :class:`~sot_apps.io.object_track.ObjectTrack` (per-frame WORLD states with a
validity mask). A tracker frame whose ``flags`` contain one of ``invalid_flags`` (default
"no_points", "prior_only", "lost": the state was predicted, not measured) is invalid: it is not used
as a measurement and is exported with ``valid = False``. Advisory flags ("init", "low_points",
"no_shape_inliers", "nan_points") keep the frame valid; the start frame ("init") is the given box and
always valid.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable
from typing import Sequence as Seq

import numpy as np

from tracker import voxel_downsample_centres

from ..errors import InputError
from ..io.object_track import ObjectTrack
from ..io.sequence import Sequence
from ..io.tracks import DEFAULT_INVALID_FLAGS, frame_is_valid
from ..objects.shapes import BoxMargin, ShapeParams, object_points_by_frame

__all__ = ["DEFAULT_INVALID_FLAGS", "frame_is_valid", "track_from_dir", "tracks_from_dirs", "tracks_from_annotations",
           "aggregate_shape"]

def track_from_dir(directory: str | Path, sequence: Sequence | None = None,
                   invalid_flags: Iterable[str] = DEFAULT_INVALID_FLAGS) -> ObjectTrack:
    """Read ``directory/track.json`` + ``shape.ply`` into an ObjectTrack."""
    from ..io.tracks import check_track_belongs, read_track

    directory = Path(directory)
    header, track = read_track(directory, invalid_flags)
    json_path = directory if directory.suffix == ".json" else directory / "track.json"
    if sequence is not None:
        check_track_belongs(header, track, sequence, json_path)
    if not len(track):
        raise InputError(json_path, "frames: the track has no frames")
    return track


def tracks_from_dirs(directories: Seq[str | Path], sequence: Sequence | None = None,
                     invalid_flags: Iterable[str] = DEFAULT_INVALID_FLAGS) -> list[ObjectTrack]:
    tracks = [track_from_dir(d, sequence, invalid_flags) for d in directories]
    seen: dict[str, str] = {}
    for t in tracks:
        if t.object_id in seen:
            raise InputError(t.source, f"object {t.object_id!r} is also exported from {seen[t.object_id]}")
        seen[t.object_id] = t.source
    return tracks


def tracks_from_annotations(sequence: Sequence, track_ids: Seq[str] | None = None) -> list[ObjectTrack]:
    """Ground-truth tracks of ``sequence`` (all, or those whose ids start with ``track_ids``).

    Frames inside an annotated span where the box is missing are kept as invalid frames (flag
    "not_annotated"). The size is the per-dimension median over the annotated boxes. Boxes that are not level
    in the world (AV2, Waymo, nuScenes) keep their roll and pitch (``ObjectTrack.tilts``).
    """
    annotated = sequence.tracks()
    if not annotated:
        raise InputError(sequence.root, "the sequence has no annotations (needed by --from-annotations)")
    ids = sorted(annotated) if not track_ids else [sequence.resolve_track_id(p) for p in track_ids]
    out: list[ObjectTrack] = []
    for tid in dict.fromkeys(ids):
        ann = annotated[tid]
        first, last = int(ann.frames[0]), int(ann.frames[-1])
        frames = np.arange(first, last + 1)
        rows = ann.frames - first
        states = np.full((len(frames), 4), np.nan)
        states[rows] = ann.states
        tilts = np.zeros((len(frames), 2))
        if ann.tilts is not None:
            tilts[rows] = ann.tilts
        valid = np.zeros(len(frames), dtype=bool)
        valid[rows] = True
        flags = [[] if v else ["not_annotated"] for v in valid]
        size = ann.size
        out.append(ObjectTrack.from_states(object_id=tid, label=ann.label, size=size, frames=frames,
                               timestamps_ns=sequence.timestamps_ns[frames], states=states, valid=valid,
                               flags=flags, source=f"annotations of {sequence.id}",
                               config={"source": "annotations"}, tilts=tilts if tilts.any() else None))
    return out


def aggregate_shape(sequence: Sequence, track: ObjectTrack, max_frames: int = 20, voxel: float = 0.05,
                    scale: float = 1.0) -> np.ndarray:
    """Object-frame points of ``track``: points inside its valid boxes (up to ``max_frames`` frames,
    evenly spaced) moved into the object frame and voxel-downsampled. Frames without a sweep are skipped."""
    has_sweep = np.array([sequence.frames[int(k)].has_sweep for k in track.frames], dtype=bool)
    idx = np.flatnonzero(np.asarray(track.valid, dtype=bool) & has_sweep)
    if len(idx) == 0:
        return np.zeros((0, 3))
    pick = idx[np.unique(np.linspace(0, len(idx) - 1, min(max_frames, len(idx))).round().astype(int))]
    boxes = ObjectTrack.from_states(track.object_id, track.label, track.size, track.frames[pick], None,
                                    track.states[pick], None)
    margin = BoxMargin(scale=(scale, scale, scale))
    params = ShapeParams(near=margin, stamp=margin, keep=margin, ground_clearance=None, capture_time=False,
                         per_point_time=False)
    points, _ = object_points_by_frame(sequence, {track.object_id: boxes}, params)
    chunks = [points[track.object_id][k] for k in sorted(points[track.object_id])]
    return voxel_downsample_centres(np.concatenate(chunks) if chunks else np.zeros((0, 3)), voxel)
