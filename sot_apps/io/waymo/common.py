"""Conversions shared by the Waymo v1 and v2 readers: boxes, cameras, image cache."""

from __future__ import annotations

import hashlib
import math
import os
from collections.abc import Sequence as SequenceABC
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Callable

import numpy as np

from tracker.geometry import Box

from ...errors import InputError
from ..atomic import write_bytes
from ..sequence import BoxAnnotation, CameraFrame, Sweep
from .messages import LABEL_TYPES, LASER_NAMES

__all__ = ["micros_to_ns", "seconds_to_ns", "transform_4x4", "box_annotation", "camera_intrinsics",
           "WAYMO_CAMERA_FROM_OPENCV", "ImageRecord", "LazyCameraFrames", "image_cache_dir", "sweep_from_parts",
           "PointSelection"]

# Waymo's camera frame is x forward, y left, z up; OpenCV's is x right, y down, z forward.
# WAYMO_CAMERA_FROM_OPENCV: columns are the OpenCV axes expressed in Waymo's camera frame.
WAYMO_CAMERA_FROM_OPENCV = np.array([[0.0, 0.0, 1.0, 0.0],
                                   [-1.0, 0.0, 0.0, 0.0],
                                   [0.0, -1.0, 0.0, 0.0],
                                   [0.0, 0.0, 0.0, 1.0]])


def micros_to_ns(micros: int) -> int:
    return int(micros) * 1000


def seconds_to_ns(seconds: float) -> int:
    """Seconds since the epoch (a double, as Waymo stores image times) to the nearest integer ns of its exact
    value (``seconds * 1e9`` in floating point would be off by up to ~128 ns at today's epoch times)."""
    return round(Fraction(float(seconds)) * 1_000_000_000)


def transform_4x4(values, path: Path, what: str) -> np.ndarray:
    """A row-major 16-value transform as a checked 4x4 matrix.

    The rotation is snapped to the nearest proper rotation (Waymo stores some transforms as float32,
    orthonormal only to ~1e-7); one further than 1e-3 from a rotation is bad input.
    """
    matrix = np.asarray(list(values), dtype=np.float64)
    if matrix.size != 16:
        raise InputError(path, f"{what}: a transform needs 16 values, got {matrix.size}")
    matrix = matrix.reshape(4, 4)
    rotation = matrix[:3, :3]
    if (not np.isfinite(matrix).all() or not np.allclose(matrix[3], [0, 0, 0, 1], atol=1e-6)
            or not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-3) or np.linalg.det(rotation) < 0):
        raise InputError(path, f"{what}: not a rigid 4x4 transform")
    u, _, vt = np.linalg.svd(rotation)
    matrix[:3, :3] = u @ vt
    matrix[3] = [0.0, 0.0, 0.0, 1.0]
    return matrix


def box_annotation(track_id: str, type_code: int, center: tuple[float, float, float], length: float, width: float,
                   height: float, heading: float, world_from_ego: np.ndarray, path: Path, where: str,
                   num_points: int | None = None) -> BoxAnnotation:
    """A Waymo box (vehicle frame of the frame pose; length along the heading; level in the vehicle frame) as a
    WORLD-frame annotation: its roll and pitch in the world are those of the vehicle pose."""
    values = (*center, length, width, height, heading)
    if not all(math.isfinite(v) for v in values):
        raise InputError(path, f"{where}: box {track_id!r} has a non-finite value")
    if min(length, width, height) <= 0:
        raise InputError(path, f"{where}: box {track_id!r} has a non-positive size {length}x{width}x{height}")
    box = Box(float(center[0]), float(center[1]), float(center[2]), float(heading), float(length), float(width),
              float(height)).transformed(world_from_ego, keep_tilt=True)
    return BoxAnnotation(track_id=track_id, label=LABEL_TYPES.get(int(type_code), "Unknown"), box=box,
                         num_points=None if num_points is None else int(num_points))


@dataclass(frozen=True)
class PointSelection:
    """Which lidars (Waymo names: TOP, FRONT, SIDE_LEFT, SIDE_RIGHT, REAR; None = all) and returns go into a sweep."""

    lidars: tuple[str, ...] | None = None
    returns: tuple[int, ...] = (1, 2)

    def __post_init__(self) -> None:
        known = set(LASER_NAMES.values()) - {"UNKNOWN"}
        if self.lidars is not None and not set(self.lidars) <= known:
            raise InputError(None, f"unknown Waymo lidar(s) {sorted(set(self.lidars) - known)}; known: {sorted(known)}")
        if not self.returns or not set(self.returns) <= {1, 2}:
            raise InputError(None, f"Waymo returns must be a non-empty subset of (1, 2), got {self.returns}")

    def wants(self, laser_code: int) -> bool:
        return self.lidars is None or LASER_NAMES.get(laser_code) in self.lidars


def sweep_from_parts(xyz: list[np.ndarray], intensity: list[np.ndarray], path: Path, where: str) -> Sweep:
    """One sweep from the lidars' point arrays (an empty sweep when there are none)."""
    if not xyz:
        return Sweep(xyz=np.zeros((0, 3), np.float32), intensity=np.zeros(0, np.float32))
    points = np.concatenate(xyz)
    if not np.isfinite(points).all():
        raise InputError(path, f"{where}: range images give non-finite points")
    return Sweep(xyz=points.astype(np.float32), intensity=np.concatenate(intensity))


def camera_intrinsics(f_u: float, f_v: float, c_u: float, c_v: float) -> np.ndarray:
    return np.array([[f_u, 0.0, c_u], [0.0, f_v, c_v], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class ImageRecord:
    """Where one camera image is and when/where it was taken (no pixels)."""

    timestamp_ns: int
    world_from_camera: np.ndarray
    read_jpeg: Callable[[], bytes]


def image_cache_dir(source: Path, segment: str) -> Path:
    """Per-source cache directory for extracted JPEGs (``$XDG_CACHE_HOME/sot-apps/waymo-images/...``).

    Keyed by the source's resolved path, size and modification time, so a changed file gets a new one.
    """
    stat = source.stat()
    key = hashlib.sha1(f"{source.resolve()}|{stat.st_size}|{stat.st_mtime_ns}".encode()).hexdigest()[:12]
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "sot-apps" / "waymo-images"
    return base / f"{segment}-{key}"


class _LazyImageFrame(CameraFrame):
    """A CameraFrame whose JPEG is written to its ``image_path`` the first time the path is asked for."""

    def __init__(self, record: ImageRecord, path: Path) -> None:  # noqa: D107 - fields set like the dataclass's
        object.__setattr__(self, "timestamp_ns", record.timestamp_ns)
        object.__setattr__(self, "world_from_camera", record.world_from_camera)
        object.__setattr__(self, "_path", path)
        object.__setattr__(self, "_read", record.read_jpeg)

    @property  # type: ignore[override]
    def image_path(self) -> Path:
        path: Path = self._path  # type: ignore[attr-defined]
        if not path.is_file():
            write_bytes(path, self._read())  # type: ignore[attr-defined]
        return path


class LazyCameraFrames(SequenceABC):
    """A camera's ``frames`` list whose JPEGs stay in the dataset file until their path is used.

    ``frames[k].timestamp_ns`` and ``.world_from_camera`` cost nothing; ``frames[k].image_path`` writes
    the JPEG atomically into the cache directory the first time, so code that reads images by path works
    unchanged.
    """

    def __init__(self, records: list[ImageRecord], directory: Path) -> None:
        self._records = records
        self._directory = directory

    def __len__(self) -> int:
        return len(self._records)

    def __getitem__(self, index):  # type: ignore[override]
        if isinstance(index, slice):
            return [self[k] for k in range(*index.indices(len(self)))]
        record = self._records[index]
        k = index % len(self._records)
        return _LazyImageFrame(record, self._directory / f"{k:06d}.jpg")
