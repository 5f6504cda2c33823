"""Track files: ``DIR/track.json`` (data_schema/track.schema.json) + ``DIR/shape.ply`` (object frame).

``write_track`` validates, writes ``shape.ply`` and then ``track.json`` (both atomically), so a
``track.json`` never names a missing or half-written shape. ``read_track`` validates again.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterable

import numpy as np

from tracker.geometry import Box, State

from ..errors import InputError
from ..schemas import load_json_validated, validate
from .atomic import write_json
from .jsonable import json_safe
from .object_track import ObjectTrack
from .ply import read_ply_points, write_ply_points

if TYPE_CHECKING:
    from .sequence import Sequence

__all__ = ["DEFAULT_INVALID_FLAGS", "TRACKER_FLAGS", "frame_is_valid", "Size", "FrameRecord", "TrackFile", "read_track",
           "write_track", "check_track_belongs", "object_track", "SCHEMA_VERSION"]

SCHEMA_VERSION = 1

# Flags meaning "this state was not measured" (tracker/sotracker.py sets no_points, prior_only and, for a
# frame without a sweep, no_sweep).
DEFAULT_INVALID_FLAGS: frozenset[str] = frozenset({"no_points", "prior_only", "lost", "no_sweep"})
# Every flag the tracker (tracker/sotracker.py, tracker/offline.py) writes, plus "lost" (kept for older files).
TRACKER_FLAGS: frozenset[str] = frozenset({"init", "no_points", "prior_only", "low_points", "nan_points",
                                           "no_shape_inliers", "yaw_clamped", "motion_clamped", "offline", "lost",
                                           "no_sweep"})


def frame_is_valid(flags: Iterable[str], invalid_flags: Iterable[str] = DEFAULT_INVALID_FLAGS) -> bool:
    """A frame whose state was measured (the start frame always is); advisory flags keep it valid."""
    flags = set(flags)
    return "init" in flags or not (flags & set(invalid_flags))


@dataclass(frozen=True)
class Size:
    length: float
    width: float
    height: float

    def to_array(self) -> np.ndarray:
        return np.array([self.length, self.width, self.height], dtype=np.float64)


@dataclass
class FrameRecord:
    """The tracker's result at one frame: WORLD state, support and quality."""

    frame: int
    timestamp_ns: int
    state: State
    num_points: int
    quality: float
    flags: list[str] = field(default_factory=list)
    time_ms: float | None = None

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "frame": int(self.frame), "timestamp_ns": int(self.timestamp_ns),
            "state": {"x": float(self.state.x), "y": float(self.state.y), "z": float(self.state.z),
                      "heading": float(self.state.heading)},
            "num_points": int(self.num_points), "quality": float(self.quality), "flags": [str(f) for f in self.flags],
        }
        if self.time_ms is not None:
            out["time_ms"] = float(self.time_ms)
        return out

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> "FrameRecord":
        s = data["state"]
        return cls(frame=int(data["frame"]), timestamp_ns=int(data["timestamp_ns"]),
                   state=State(float(s["x"]), float(s["y"]), float(s["z"]), float(s["heading"])),
                   num_points=int(data["num_points"]), quality=float(data["quality"]), flags=list(data["flags"]),
                   time_ms=None if data.get("time_ms") is None else float(data["time_ms"]))


@dataclass
class TrackFile:
    """One tracked object (see docs/data-formats.md, "track")."""

    sequence: str
    object_id: str
    size: Size
    start_frame: int
    end_frame: int
    init_box: Box
    config: dict[str, Any]
    frames: list[FrameRecord]
    label: str | None = None
    shape: str = "shape.ply"

    @property
    def mode(self) -> str:
        """How the states were made: "online", "lag N" (fixed-lag refinement) or "offline" (track.json's config)."""
        mode = str(self.config.get("mode", "online"))
        return f"lag {self.config.get('lag')}" if mode == "lag" else mode

    def box_at_record(self, record: FrameRecord) -> Box:
        """The WORLD box of a frame record (state + the track's size)."""
        return Box(record.state.x, record.state.y, record.state.z, record.state.heading,
                   self.size.length, self.size.width, self.size.height)

    def record(self, frame: int) -> FrameRecord | None:
        for rec in self.frames:
            if rec.frame == frame:
                return rec
        return None

    def boxes(self) -> dict[int, Box]:
        """WORLD box per frame index."""
        return {rec.frame: self.box_at_record(rec) for rec in self.frames}

    def to_json(self) -> dict[str, Any]:
        b = self.init_box
        out: dict[str, Any] = {
            "schema_version": SCHEMA_VERSION, "sequence": self.sequence, "object_id": self.object_id,
        }
        if self.label is not None:
            out["label"] = self.label
        out.update({
            "size": {"length": float(self.size.length), "width": float(self.size.width), "height": float(self.size.height)},
            "start_frame": int(self.start_frame), "end_frame": int(self.end_frame),
            "init_box": {"x": b.x, "y": b.y, "z": b.z, "heading": b.heading, "length": b.length, "width": b.width,
                         "height": b.height},
            "config": json_safe(self.config), "shape": self.shape,
            "frames": [r.to_json() for r in self.frames],
        })
        return out

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> "TrackFile":
        s, b = data["size"], data["init_box"]
        return cls(sequence=data["sequence"], object_id=data["object_id"],
                   size=Size(float(s["length"]), float(s["width"]), float(s["height"])),
                   start_frame=int(data["start_frame"]), end_frame=int(data["end_frame"]),
                   init_box=Box(*(float(b[k]) for k in ("x", "y", "z", "heading", "length", "width", "height"))),
                   config=dict(data["config"]), frames=[FrameRecord.from_json(f) for f in data["frames"]],
                   label=data.get("label"), shape=data.get("shape", "shape.ply"))


def object_track(track: TrackFile, shape_points: np.ndarray | None = None, source: str = "",
                 invalid_flags: Iterable[str] = DEFAULT_INVALID_FLAGS) -> ObjectTrack:
    """A track file as an :class:`ObjectTrack` (the one conversion): its records in frame order, the track's size,
    ``valid`` where :func:`frame_is_valid` (``invalid_flags``), the tracker's quality as ``scores``, its
    ``num_points``, and the tracker's config as ``config["tracker"]``. ValueError on frames or timestamps that do
    not increase."""
    records = sorted(track.frames, key=lambda r: r.frame)
    flags = [list(r.flags) for r in records]
    invalid_flags = set(invalid_flags)
    return ObjectTrack.from_states(
        track.object_id, track.label or "", (track.size.length, track.size.width, track.size.height),
        [r.frame for r in records], [r.timestamp_ns for r in records],
        np.array([r.state.to_array() for r in records], dtype=np.float64).reshape(-1, 4),
        [frame_is_valid(f, invalid_flags) for f in flags], flags, scores=[r.quality for r in records],
        num_points=[r.num_points for r in records], source=source, shape_points=shape_points,
        config={"tracker": track.config})


def _check_frames(doc: dict[str, Any], path: Path) -> None:
    frames = [f["frame"] for f in doc["frames"]]
    if len(set(frames)) != len(frames):
        dup = next(f for f in frames if frames.count(f) > 1)
        raise InputError(path, f"frames: frame {dup} appears more than once")


def _json_path(path: str | Path) -> Path:
    path = Path(path)
    return path if path.suffix == ".json" else path / "track.json"


def write_track(directory: str | Path, track: TrackFile, shape_points: np.ndarray) -> Path:
    """Write ``directory/shape.ply`` then ``directory/track.json`` (validated); returns the json path."""
    directory = Path(directory)
    json_path = directory / "track.json"
    doc = track.to_json()
    validate("track", doc, json_path)
    _check_frames(doc, json_path)
    shape_points = np.asarray(shape_points, dtype=np.float64).reshape(-1, 3)
    if not np.isfinite(shape_points).all():
        raise InputError(directory / track.shape, "shape points contain non-finite coordinates")
    write_ply_points(directory / track.shape, shape_points)
    write_json(json_path, doc)
    return json_path


def read_track(path: str | Path) -> tuple[TrackFile, np.ndarray]:
    """Read a track directory (or its track.json): (TrackFile, shape points (N,3) float64 object frame)."""
    json_path = _json_path(path)
    doc = load_json_validated(json_path, "track")
    _check_frames(doc, json_path)
    track = TrackFile.from_json(doc)
    return track, read_ply_points(json_path.parent / track.shape)


def check_track_belongs(track: TrackFile, sequence: "Sequence", path: str | Path) -> None:
    """Refuse (InputError naming ``path``) a track that was not made from ``sequence``.

    The one belongs-to-this-sequence check of every command that takes track directories with a
    sequence (flow, motion-export, bench motion, pipeline): the recorded sequence name must be the
    sequence's id or directory name, every frame index must exist and every frame's ``timestamp_ns``
    must equal the sequence's (a renamed or re-converted sequence with other timestamps is refused too).
    """
    if track.sequence not in (sequence.id, Path(sequence.root).name):
        raise InputError(path, f"track of sequence {track.sequence!r}, not of {sequence.id!r}")
    n = len(sequence.frames)
    bad = [r.frame for r in track.frames if not 0 <= r.frame < n]
    if bad:
        raise InputError(path, f"frame {bad[0]} is outside the sequence {sequence.id!r} (frames 0..{n - 1})")
    for r in track.frames:
        expected = int(sequence.frames[r.frame].timestamp_ns)
        if r.timestamp_ns != expected:
            raise InputError(path, f"frame {r.frame}: timestamp_ns {r.timestamp_ns} differs from the sequence "
                                   f"{sequence.id!r}'s {expected}: the track was made from another sequence")
