"""One object over time: :class:`ObjectTrack`, the per-object time series of sot_apps.

The tracker's output is :class:`tracker.TrackResult` (tracker/ imports nothing from sot_apps); what sot_apps
keeps of one object over frames is an ObjectTrack: the smoother's input (a track file's states, or the
annotations), the boxes a shape is gathered from, the label tracks the KITTI/AV2 writers take, the detections
associated over time. Its columns, one row per frame:

- ``frames`` (N,) int64 sequence frame indices, strictly increasing;
- ``boxes`` (N, 7) WORLD ``[x, y, z, heading, length, width, height]``, or (N, 9) with ``[roll, pitch]`` for
  boxes that are not level in the world; a row of an invalid frame may hold NaN;
- optional: ``timestamps_ns`` (N,) int64 strictly increasing, ``valid`` (N,) bool (default: every frame whose box
  is finite; ``flags[i]`` says why a frame is not), ``scores`` (N,) float (a detector's or label's confidence),
  ``num_points`` (N,) int64 (the source's own count of points in the box, -1 where unknown), ``time_ms`` (N,)
  float (the tracker's computing time for the frame, ms; NaN where not recorded);
- optional kinematics (the motion smoother's output, :func:`sot_apps.objects.smoother.smooth_track`): ``velocity``
  (N, 2) WORLD ``[vx, vy]`` m/s, ``speed`` (N,) m/s, ``acceleration`` (N,) m/s^2 along the heading, ``yaw_rate``
  (N,) rad/s, and their 1-sigma ``position_std`` (m), ``heading_std`` (rad), ``speed_std`` (m/s), ``yaw_rate_std``
  (rad/s), each (N,) float (NaN where invalid or unknown).

Per object: ``object_id``, ``label``, ``size`` (length, width, height; default the per-dimension median of the
boxes), ``source`` (where it came from), ``shape_points`` (M, 3) object frame and ``config`` (how it was made).
:func:`sot_apps.io.tracks.read_track` reads a track file as one (the tracker's per-frame quality as ``scores``) and
:func:`sot_apps.io.tracks.write_track` writes one.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Iterable, Mapping

import numpy as np

from tracker.geometry import Box

__all__ = ["ObjectTrack", "KINEMATICS"]

# The optional float columns of the smoother's kinematics (``velocity`` is (N, 2), the others (N,)).
KINEMATICS: tuple[str, ...] = ("velocity", "speed", "acceleration", "yaw_rate", "position_std", "heading_std",
                               "speed_std", "yaw_rate_std")
# Every per-frame column besides ``frames``/``boxes``/``flags`` (``select`` cuts them all).
_COLUMNS: tuple[str, ...] = ("timestamps_ns", "valid", "scores", "num_points", "time_ms") + KINEMATICS


def _column(values: Any, n: int, dtype: Any, name: str, object_id: str, width: int = 0) -> np.ndarray | None:
    if values is None:
        return None
    out = np.asarray(values, dtype=dtype).reshape((-1, width) if width else -1)
    if len(out) != n:
        raise ValueError(f"{object_id}: {name} has {len(out)} entries for {n} frames")
    return out


@dataclass(frozen=True, eq=False)
class ObjectTrack:
    """One object's boxes at sequence frames with optional per-frame columns (see the module docstring)."""

    object_id: str
    label: str
    frames: np.ndarray
    boxes: np.ndarray
    timestamps_ns: np.ndarray | None = None
    valid: np.ndarray | None = None
    flags: tuple[tuple[str, ...], ...] = ()
    scores: np.ndarray | None = None
    num_points: np.ndarray | None = None
    time_ms: np.ndarray | None = None
    velocity: np.ndarray | None = None
    speed: np.ndarray | None = None
    acceleration: np.ndarray | None = None
    yaw_rate: np.ndarray | None = None
    position_std: np.ndarray | None = None
    heading_std: np.ndarray | None = None
    speed_std: np.ndarray | None = None
    yaw_rate_std: np.ndarray | None = None
    size: tuple[float, float, float] | None = None
    source: str = ""
    shape_points: np.ndarray | None = None
    config: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        oid = self.object_id
        frames = np.asarray(self.frames, dtype=np.int64).reshape(-1)
        n = len(frames)
        boxes = np.array(self.boxes, dtype=np.float64).reshape(n, -1) if n else np.zeros((0, 7))
        if boxes.shape[1] not in (7, 9):
            raise ValueError(f"{oid}: boxes must have 7 or 9 columns, not {boxes.shape[1]}")
        stamps = _column(self.timestamps_ns, n, np.int64, "timestamps_ns", oid)
        valid = _column(self.valid, n, bool, "valid", oid)
        valid = (np.ones(n, dtype=bool) if valid is None else valid) & np.isfinite(boxes).all(axis=1)
        flags = tuple(tuple(str(f) for f in fl) for fl in self.flags) if len(self.flags) else ((),) * n
        if len(flags) != n:
            raise ValueError(f"{oid}: flags has {len(flags)} entries for {n} frames")
        if n > 1 and (np.any(np.diff(frames) <= 0) or (stamps is not None and np.any(np.diff(stamps) <= 0))):
            raise ValueError(f"{oid}: frames and timestamps must be strictly increasing")
        size = self.size
        if size is None:
            size = tuple(float(v) for v in np.median(boxes[:, 4:7], axis=0)) if n else (0.0, 0.0, 0.0)
        for name, value in (("frames", frames), ("boxes", boxes), ("timestamps_ns", stamps), ("valid", valid),
                            ("flags", flags), ("scores", _column(self.scores, n, np.float64, "scores", oid)),
                            ("num_points", _column(self.num_points, n, np.int64, "num_points", oid)),
                            ("time_ms", _column(self.time_ms, n, np.float64, "time_ms", oid)),
                            ("size", tuple(float(v) for v in size))):
            object.__setattr__(self, name, value)
        for name in KINEMATICS:
            object.__setattr__(self, name, _column(getattr(self, name), n, np.float64, name, oid,
                                                   2 if name == "velocity" else 0))

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_boxes(cls, object_id: str, label: str, boxes: Mapping[int, Box], *,
                   scores: Mapping[int, float] | None = None, num_points: Mapping[int, int] | None = None,
                   timestamps_ns: np.ndarray | None = None, **rest: Any) -> "ObjectTrack":
        """A track of ``Box`` objects by frame (any order; rows sorted by frame). ``scores`` / ``num_points`` by
        frame (a frame missing from ``num_points`` is unknown: -1); ``timestamps_ns`` the SEQUENCE's timestamps
        (indexed by frame)."""
        frames = sorted(int(k) for k in boxes)
        tilted = any(not boxes[k].is_level for k in frames)
        rows = np.array([_box_row(boxes[k], tilted) for k in frames], dtype=np.float64) if frames else np.zeros((0, 7))
        return cls(object_id, label, np.array(frames, dtype=np.int64), rows,
                   timestamps_ns=None if timestamps_ns is None else np.asarray(timestamps_ns)[frames],
                   scores=None if scores is None else [scores[k] for k in frames],
                   num_points=None if num_points is None else [num_points.get(k, -1) for k in frames], **rest)

    @classmethod
    def from_states(cls, object_id: str, label: str, size: Iterable[float], frames: Any, timestamps_ns: Any,
                    states: Any, valid: Any, flags: Iterable[Iterable[str]] = (), tilts: Any = None,
                    **rest: Any) -> "ObjectTrack":
        """A track of per-frame WORLD states ``[x, y, z, heading]`` (N, 4) of one box ``size``; ``tilts`` (N, 2)
        ``[roll, pitch]`` (None: level)."""
        states = np.asarray(states, dtype=np.float64).reshape(-1, 4)
        size = tuple(float(v) for v in size)
        columns = [states, np.broadcast_to(np.asarray(size), (len(states), 3))]
        if tilts is not None:
            columns.append(np.asarray(tilts, dtype=np.float64).reshape(-1, 2))
        if tilts is not None and len(columns[2]) != len(states):
            raise ValueError(f"{object_id}: tilts has {len(columns[2])} rows for {len(states)} frames")
        return cls(object_id, label, frames, np.concatenate(columns, axis=1), timestamps_ns=timestamps_ns,
                   valid=valid, flags=tuple(tuple(f) for f in flags), size=size, **rest)  # type: ignore[arg-type]

    # ------------------------------------------------------------------ views
    def __len__(self) -> int:
        return len(self.frames)

    @property
    def states(self) -> np.ndarray:
        """(N, 4) WORLD ``[x, y, z, heading]``."""
        return self.boxes[:, :4]

    @property
    def tilts(self) -> np.ndarray | None:
        """(N, 2) ``[roll, pitch]``, or None for a level track."""
        return self.boxes[:, 7:9] if self.boxes.shape[1] == 9 else None

    def box(self, i: int) -> Box:
        """Row ``i`` as a :class:`tracker.Box`."""
        return Box(*(float(v) for v in self.boxes[i]))

    def box_at(self, frame: int) -> Box | None:
        """The box at sequence frame ``frame``, or None where the track has none."""
        i = int(np.searchsorted(self.frames, frame))
        return self.box(i) if i < len(self.frames) and self.frames[i] == frame else None

    def boxes_by_frame(self) -> dict[int, Box]:
        """``{frame: Box}`` of every row, in frame order."""
        return {int(k): self.box(i) for i, k in enumerate(self.frames)}

    def select(self, rows: np.ndarray) -> "ObjectTrack":
        """The track at the rows a boolean mask (or index array) picks, every column with them."""
        pick = np.arange(len(self.frames))[rows]
        columns = {name: None if getattr(self, name) is None else getattr(self, name)[pick] for name in _COLUMNS}
        return replace(self, frames=self.frames[pick], boxes=self.boxes[pick], flags=tuple(self.flags[i] for i in pick),
                       **columns)

    def between(self, first: int, last: int) -> "ObjectTrack":
        """The rows at frames ``first``..``last`` (inclusive), every column with them."""
        return self.select((self.frames >= first) & (self.frames <= last))

    def restamped(self, times_ns: Any) -> "ObjectTrack":
        """The track with ``times_ns`` (one per row, e.g. the capture time of each box's points) as its
        ``timestamps_ns``; a row whose time is not after the previous kept row's is dropped (times must increase)."""
        times = np.asarray(times_ns, dtype=np.int64).reshape(-1)
        if len(times) != len(self.frames):
            raise ValueError(f"{self.object_id}: {len(times)} times for {len(self.frames)} rows")
        keep = np.zeros(len(times), dtype=bool)
        if len(times):
            keep[0] = True
            keep[1:] = times[1:] > np.maximum.accumulate(times)[:-1]
        return replace(self.select(keep), timestamps_ns=times[keep])

    @property
    def mean_score(self) -> float:
        """The mean of the ``scores`` column (NaN without one)."""
        return float(np.mean(self.scores)) if self.scores is not None and len(self.scores) else float("nan")


def _box_row(box: Box, tilted: bool) -> list[float]:
    row = [box.x, box.y, box.z, box.heading, box.length, box.width, box.height]
    return row + [box.roll, box.pitch] if tilted else row
