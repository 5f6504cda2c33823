"""Track files: ``DIR/track.json`` (data_schema/track.schema.json) + ``DIR/shape.ply`` (object frame).

In memory a track file is a :class:`TrackHeader` (sequence, span, initial box, tracker config, shape file) and an
:class:`~sot_apps.io.object_track.ObjectTrack` (its frames' rows and shape points). ``write_track`` validates,
writes ``shape.ply`` and then ``track.json`` (both atomically), so a ``track.json`` never names a missing or
half-written shape. ``read_track`` validates again.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterable, Mapping

import numpy as np

from tracker.geometry import Box

from ..errors import InputError
from ..schemas import load_json_validated, validate
from .atomic import write_json
from .jsonable import json_safe
from .object_track import ObjectTrack
from .ply import read_ply_points, write_ply_points

if TYPE_CHECKING:
    from .sequence import Sequence

__all__ = ["DEFAULT_INVALID_FLAGS", "TRACKER_FLAGS", "frame_is_valid", "TrackHeader", "track_json", "read_track",
           "write_track", "check_track_belongs", "SCHEMA_VERSION"]

SCHEMA_VERSION = 1

# Flags meaning "this state was not measured" (tracker/sotracker.py sets no_points, prior_only and, for a
# frame without a sweep, no_sweep; the refinements bridged, for a frame put on the line to a re-lock).
DEFAULT_INVALID_FLAGS: frozenset[str] = frozenset({"no_points", "prior_only", "lost", "no_sweep", "bridged"})
# Every flag the tracker (tracker/sotracker.py, the refinements, keyframes, the Det baseline) writes, plus "lost"
# (kept for older files).
TRACKER_FLAGS: frozenset[str] = frozenset({"init", "no_points", "prior_only", "low_points", "nan_points",
                                           "no_shape_inliers", "yaw_clamped", "motion_clamped", "offline", "lost",
                                           "no_sweep", "footprint", "coasting", "searching", "waiting", "reacquired",
                                           "backward", "bridged",
                                           "det", "det_only", "keyframe", "keyframes", "low_quality", "contained"})


def frame_is_valid(flags: Iterable[str], invalid_flags: Iterable[str] = DEFAULT_INVALID_FLAGS) -> bool:
    """A frame whose state was measured (the start frame always is); advisory flags keep it valid."""
    flags = set(flags)
    return "init" in flags or not (flags & set(invalid_flags))


@dataclass(frozen=True)
class TrackHeader:
    """What ``track.json`` says about a track besides its rows (those are the :class:`ObjectTrack`): the sequence
    it was made from, the span (``start_frame`` = the initial box's frame), the initial WORLD box, the tracker's
    configuration (``config``, with ``preset`` and ``mode``) and the shape file's name next to ``track.json``."""

    sequence: str
    start_frame: int
    end_frame: int
    init_box: Box
    config: Mapping[str, Any]
    shape: str = "shape.ply"

    @property
    def mode(self) -> str:
        """How the states were made: "online", "lag N" (fixed-lag refinement) or "offline" (track.json's config)."""
        mode = str(self.config.get("mode", "online"))
        return f"lag {self.config.get('lag')}" if mode == "lag" else mode


def _header_from_json(data: dict[str, Any]) -> TrackHeader:
    b = data["init_box"]
    return TrackHeader(sequence=data["sequence"], start_frame=int(data["start_frame"]),
                       end_frame=int(data["end_frame"]),
                       init_box=Box(*(float(b[k]) for k in ("x", "y", "z", "heading", "length", "width", "height"))),
                       config=dict(data["config"]), shape=data.get("shape", "shape.ply"))


def _track_from_json(data: dict[str, Any], header: TrackHeader, shape_points: np.ndarray, source: str,
                     invalid_flags: Iterable[str]) -> ObjectTrack:
    """The rows of a track.json document in frame order (ValueError on frames or timestamps that do not increase)."""
    rows = sorted(data["frames"], key=lambda r: r["frame"])
    times = [r.get("time_ms") for r in rows]
    flags = [list(r["flags"]) for r in rows]
    invalid_flags = set(invalid_flags)
    s = data["size"]
    return ObjectTrack.from_states(
        data["object_id"], data.get("label", ""), (float(s["length"]), float(s["width"]), float(s["height"])),
        [r["frame"] for r in rows], [r["timestamp_ns"] for r in rows],
        np.array([[r["state"][k] for k in ("x", "y", "z", "heading")] for r in rows], dtype=np.float64).reshape(-1, 4),
        [frame_is_valid(f, invalid_flags) for f in flags], flags, scores=[r["quality"] for r in rows],
        num_points=[r["num_points"] for r in rows],
        time_ms=None if all(t is None for t in times) else [np.nan if t is None else t for t in times],
        source=source, shape_points=shape_points, config={"tracker": header.config})


def track_json(header: TrackHeader, track: ObjectTrack) -> dict[str, Any]:
    """The ``track.json`` document of ``header`` and ``track`` (level boxes of one size, ``track.size``; needs
    ``timestamps_ns``, ``scores`` (the quality) and ``num_points``; ``time_ms`` where finite; a ``label`` when not
    empty). The frames' validity is in their ``flags``."""
    oid = track.object_id
    if track.timestamps_ns is None or track.scores is None or track.num_points is None:
        raise ValueError(f"{oid}: a track file needs timestamps_ns, scores (the quality) and num_points")
    if track.tilts is not None or not np.array_equal(track.boxes[:, 4:7], np.broadcast_to(track.size, (len(track), 3))):
        raise ValueError(f"{oid}: a track file holds level boxes of one size (the track's size)")
    b = header.init_box
    out: dict[str, Any] = {"schema_version": SCHEMA_VERSION, "sequence": header.sequence, "object_id": oid}
    if track.label:
        out["label"] = track.label
    times = track.time_ms.tolist() if track.time_ms is not None else [math.nan] * len(track)
    frames = []
    for frame, stamp, (x, y, z, heading), points, quality, flags, time_ms in zip(
            track.frames.tolist(), track.timestamps_ns.tolist(), track.states.tolist(), track.num_points.tolist(),
            track.scores.tolist(), track.flags, times, strict=True):
        row: dict[str, Any] = {"frame": frame, "timestamp_ns": stamp,
                               "state": {"x": x, "y": y, "z": z, "heading": heading},
                               "num_points": points, "quality": quality, "flags": list(flags)}
        if not math.isnan(time_ms):
            row["time_ms"] = time_ms
        frames.append(row)
    length, width, height = track.size
    out.update({
        "size": {"length": float(length), "width": float(width), "height": float(height)},
        "start_frame": int(header.start_frame), "end_frame": int(header.end_frame),
        "init_box": {"x": b.x, "y": b.y, "z": b.z, "heading": b.heading, "length": b.length, "width": b.width,
                     "height": b.height},
        "config": json_safe(dict(header.config)), "shape": header.shape, "frames": frames,
    })
    return out


def _check_frames(doc: dict[str, Any], path: Path) -> None:
    frames = [f["frame"] for f in doc["frames"]]
    if len(set(frames)) != len(frames):
        dup = next(f for f in frames if frames.count(f) > 1)
        raise InputError(path, f"frames: frame {dup} appears more than once")


def _json_path(path: str | Path) -> Path:
    path = Path(path)
    return path if path.suffix == ".json" else path / "track.json"


def write_track(directory: str | Path, header: TrackHeader, track: ObjectTrack) -> Path:
    """Write ``directory/<header.shape>`` (``track.shape_points``, object frame) then ``directory/track.json``
    (:func:`track_json`, validated); returns the json path."""
    directory = Path(directory)
    json_path = directory / "track.json"
    doc = track_json(header, track)
    validate("track", doc, json_path)
    _check_frames(doc, json_path)
    if track.shape_points is None:
        raise ValueError(f"{track.object_id}: a track file needs shape_points")
    shape_points = np.asarray(track.shape_points, dtype=np.float64).reshape(-1, 3)
    if not np.isfinite(shape_points).all():
        raise InputError(directory / header.shape, "shape points contain non-finite coordinates")
    write_ply_points(directory / header.shape, shape_points)
    write_json(json_path, doc)
    return json_path


def read_track(path: str | Path, invalid_flags: Iterable[str] = DEFAULT_INVALID_FLAGS
               ) -> tuple[TrackHeader, ObjectTrack]:
    """Read a track directory (or its track.json): its header and its rows as an :class:`ObjectTrack` in frame order
    (``source`` the json path; the tracker's quality as ``scores``; ``valid`` where :func:`frame_is_valid` with
    ``invalid_flags``; the per-frame ``time_ms`` where the file has it; ``shape_points`` (N, 3) float64 object frame;
    ``config["tracker"]`` the header's config). InputError naming the file on frames or timestamps that do not
    increase."""
    json_path = _json_path(path)
    doc = load_json_validated(json_path, "track")
    _check_frames(doc, json_path)
    header = _header_from_json(doc)
    shape = read_ply_points(json_path.parent / header.shape)
    try:
        return header, _track_from_json(doc, header, shape, str(json_path), invalid_flags)
    except ValueError as exc:
        raise InputError(json_path, str(exc)) from exc


def check_track_belongs(header: TrackHeader, track: ObjectTrack, sequence: "Sequence", path: str | Path) -> None:
    """Refuse (InputError naming ``path``) a track that was not made from ``sequence``.

    The one belongs-to-this-sequence check of every command that takes track directories with a
    sequence (flow, motion-export, bench motion, pipeline): the recorded sequence name must be the
    sequence's id or directory name, every frame index must exist and every frame's ``timestamp_ns``
    must equal the sequence's (a renamed or re-converted sequence with other timestamps is refused too).
    """
    if header.sequence not in (sequence.id, Path(sequence.root).name):
        raise InputError(path, f"track of sequence {header.sequence!r}, not of {sequence.id!r}")
    n = len(sequence.frames)
    bad = [int(k) for k in track.frames if not 0 <= k < n]
    if bad:
        raise InputError(path, f"frame {bad[0]} is outside the sequence {sequence.id!r} (frames 0..{n - 1})")
    stamps = track.timestamps_ns if track.timestamps_ns is not None else np.zeros(len(track), dtype=np.int64)
    for frame, stamp in zip(track.frames.tolist(), stamps.tolist(), strict=True):
        expected = int(sequence.frames[frame].timestamp_ns)
        if stamp != expected:
            raise InputError(path, f"frame {frame}: timestamp_ns {stamp} differs from the sequence "
                                   f"{sequence.id!r}'s {expected}: the track was made from another sequence")
