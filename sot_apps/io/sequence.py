"""The in-memory sequence every reader produces: frames (lazy sweeps), cameras, annotations.

Past a reader, everything follows docs/conventions.md: world/ego frames, ``target_from_source``
4x4 transforms, integer nanoseconds, boxes with heading of the length axis, OpenCV camera axes.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from tracker.frames import LidarFrame
from tracker.geometry import Box, transform_points

from ..errors import InputError
from .object_track import ObjectTrack

__all__ = [
    "Sweep",
    "FrameInfo",
    "CameraFrame",
    "Camera",
    "BoxAnnotation",
    "Sequence",
]


@dataclass(frozen=True)
class Sweep:
    """One LiDAR sweep in the EGO frame.

    ``xyz``: (N, 3) float32; ``intensity``: optional (N,) float32; ``time_offset_ns``: optional (N,)
    int64 capture time of each point relative to the frame's ``timestamp_ns``.
    """

    xyz: np.ndarray
    intensity: np.ndarray | None = None
    time_offset_ns: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.xyz.shape[0])


@dataclass(frozen=True)
class FrameInfo:
    """Per-frame metadata (cheap: no points).

    ``has_sweep`` is False for a frame whose sweep is missing (real logs drop sweeps while poses,
    boxes and images continue); such a frame has no ``points_path`` and reads as an empty sweep.
    An *empty* sweep (a file with zero points) is a different event: ``has_sweep`` stays True.
    """

    index: int
    timestamp_ns: int
    world_from_ego: np.ndarray
    points_path: Path | None
    has_sweep: bool = True


@dataclass(frozen=True)
class CameraFrame:
    """One image of a camera: its file, capture time and pose (camera axes are OpenCV's)."""

    timestamp_ns: int
    image_path: Path
    world_from_camera: np.ndarray


@dataclass(frozen=True)
class Camera:
    """A pinhole camera with OpenCV distortion (k1, k2, p1, p2[, k3, ...]).

    ``frames[k]`` is the image taken with lidar frame k. ``ego_from_camera`` is set when the camera
    is rigidly mounted and its per-frame pose follows from the ego pose.
    """

    name: str
    K: np.ndarray
    distortion: np.ndarray
    width: int
    height: int
    frames: list[CameraFrame]
    ego_from_camera: np.ndarray | None = None


@dataclass(frozen=True)
class BoxAnnotation:
    """A ground-truth box of one object at one frame (world frame).

    ``num_points``: the dataset's own count of lidar points in the box, when it has one.
    """

    track_id: str
    label: str
    box: Box
    stationary: bool | None = None
    num_points: int | None = None


SweepLoader = Callable[[int], Sweep]


@dataclass
class Sequence:
    """A LiDAR sequence with lazy sweeps.

    Readers fill the metadata eagerly (it is small) and pass ``load_sweep``, which reads one frame's
    points on demand; the last few sweeps are cached.
    """

    id: str
    root: Path
    format: str
    frames: list[FrameInfo]
    load_sweep: SweepLoader
    ego_from_lidar: np.ndarray = field(default_factory=lambda: np.eye(4))
    cameras: dict[str, Camera] = field(default_factory=dict)
    annotations: list[list[BoxAnnotation]] | None = None
    cache_size: int = 4
    _cache: "OrderedDict[int, Sweep]" = field(default_factory=OrderedDict, repr=False)
    # tracks() of the annotations (the list object itself and its box count: a list replaced or grown is re-read)
    _tracks: tuple[list, int, dict[str, ObjectTrack]] | None = field(default=None, init=False, repr=False,
                                                                     compare=False)

    def __len__(self) -> int:
        return len(self.frames)

    def check_index(self, index: int) -> int:
        if not 0 <= index < len(self.frames):
            raise InputError(self.root, f"frame {index} is out of range: the sequence has frames 0..{len(self.frames) - 1}")
        return index

    def missing_sweeps(self) -> list[int]:
        """Indices of the frames that have no sweep (see :attr:`FrameInfo.has_sweep`)."""
        return [f.index for f in self.frames if not f.has_sweep]

    def sweep(self, index: int) -> Sweep:
        """The frame's points in the ego frame (read on first use); a frame without a sweep gives 0 points."""
        self.check_index(index)
        if not self.frames[index].has_sweep:
            return Sweep(xyz=np.zeros((0, 3), dtype=np.float32))
        if index in self._cache:
            self._cache.move_to_end(index)
            return self._cache[index]
        sweep = self.load_sweep(index)
        self._cache[index] = sweep
        while len(self._cache) > self.cache_size:
            self._cache.popitem(last=False)
        return sweep

    def points_world(self, index: int) -> np.ndarray:
        """(N, 3) float64 points of frame ``index`` in the world frame."""
        return transform_points(self.frames[index].world_from_ego, self.sweep(index).xyz)

    def lidar_frame(self, index: int) -> LidarFrame:
        """The frame as the tracker consumes it."""
        sweep = self.sweep(index)
        info = self.frames[index]
        return LidarFrame(index=index, timestamp_ns=info.timestamp_ns, points_ego=sweep.xyz,
                          world_from_ego=info.world_from_ego, point_time_offset_ns=sweep.time_offset_ns,
                          has_sweep=info.has_sweep)

    @property
    def timestamps_ns(self) -> np.ndarray:
        return np.array([f.timestamp_ns for f in self.frames], dtype=np.int64)

    def tracks(self) -> dict[str, ObjectTrack]:
        """The annotations as one :class:`ObjectTrack` per object id, in order of first appearance (empty without
        annotations; reads no sweep): the boxes by frame (a frame's first box of an id), the frames'
        ``timestamps_ns``, the source's point counts as ``num_points`` (-1 where it has none), ``source`` =
        "annotations"."""
        if not self.annotations:
            return {}
        count = sum(len(a) for a in self.annotations)
        if self._tracks is None or self._tracks[0] is not self.annotations or self._tracks[1] != count:
            self._tracks = (self.annotations, count, self._annotation_tracks())
        return dict(self._tracks[2])

    def _annotation_tracks(self) -> dict[str, ObjectTrack]:
        assert self.annotations is not None
        boxes: dict[str, dict[int, Box]] = {}
        counts: dict[str, dict[int, int]] = {}
        labels: dict[str, str] = {}
        for k, frame_annotations in enumerate(self.annotations):
            for ann in frame_annotations:
                by_frame = boxes.setdefault(ann.track_id, {})
                if k in by_frame:
                    continue
                by_frame[k] = ann.box
                labels.setdefault(ann.track_id, ann.label)
                if ann.num_points is not None:
                    counts.setdefault(ann.track_id, {})[k] = int(ann.num_points)
        stamps = self.timestamps_ns
        return {tid: ObjectTrack.from_boxes(tid, labels[tid], by_frame, num_points=counts.get(tid, {}),
                                            timestamps_ns=stamps, source="annotations")
                for tid, by_frame in boxes.items()}

    def resolve_track_id(self, prefix: str) -> str:
        """The unique annotated track id starting with ``prefix``."""
        ids = [tid for tid in self.tracks() if tid.startswith(prefix)]
        if not ids:
            raise InputError(self.root, f"no annotated track id starts with {prefix!r}")
        if len(ids) > 1 and prefix not in ids:
            raise InputError(self.root, f"track id prefix {prefix!r} is ambiguous: {', '.join(sorted(ids)[:5])}")
        return prefix if prefix in ids else ids[0]
