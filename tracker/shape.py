"""The object's shape: key-frame aggregation and the sub-shape of recent frames (voxelised at voxel centres,
:func:`tracker.metrics.voxel_downsample_centres`).

All points here are in the OBJECT frame (x along the box length, origin at the box centre).
"""

from __future__ import annotations

from collections import deque

import numpy as np

from .association import NearestNeighbors
from .geometry import Box, rotation_z, transform_points
from .metrics import voxel_downsample_centres

__all__ = ["to_object_frame", "to_world_frame", "ShapeModel", "SubShape"]


def to_object_frame(points_world: np.ndarray, box: Box) -> np.ndarray:
    return transform_points(box.object_from_world(), points_world)


def to_world_frame(points_object: np.ndarray, box: Box) -> np.ndarray:
    return transform_points(box.world_from_object(), points_object)


class ShapeModel:
    """The aggregated shape M: starts with the first frame's points, grows at key frames; nothing is removed."""

    def __init__(self, voxel_size: float) -> None:
        self.voxel_size = voxel_size
        self.points = np.zeros((0, 3))
        self._nearest: NearestNeighbors | None = None   # built on the points at the first query after a change

    def add(self, points_object: np.ndarray) -> None:
        if len(points_object) == 0:
            return
        self.points = voxel_downsample_centres(np.vstack([self.points, points_object]), self.voxel_size)
        self._nearest = None

    def turn(self, angle: float) -> None:
        """Turn the points by ``angle`` about the object frame's vertical axis."""
        self.points = _turned(self.points, angle)
        self._nearest = None

    def slide(self, distance: float) -> None:
        """Move the points by ``distance`` along the object frame's x axis (the box's length)."""
        if len(self.points):
            self.points = self.points + np.array([distance, 0.0, 0.0])
        self._nearest = None

    def explained(self, points_object: np.ndarray, radius: float = 0.2) -> tuple[float, int]:
        """The share of ``points_object`` within ``radius`` of a shape point (0 for an empty shape), and their
        number."""
        if len(points_object) == 0 or len(self.points) == 0:
            return 0.0, len(points_object)
        if self._nearest is None:
            self._nearest = NearestNeighbors(self.points)
        dist, _ = self._nearest.query(points_object)
        return float((dist <= radius).mean()), len(points_object)

    def __len__(self) -> int:
        return len(self.points)


class SubShape:
    """The points of the last ``frames`` frames (each voxelised), aggregated in the object frame."""

    def __init__(self, frames: int, voxel_size: float) -> None:
        self.voxel_size = voxel_size
        self._frames: deque[np.ndarray] = deque(maxlen=max(frames, 0) or None)
        self._enabled = frames > 0
        self._held = self._dense = 0

    def add(self, points_object: np.ndarray) -> None:
        """The frame's object points (object frame); none while held (:meth:`hold`: the older frames still drop
        out)."""
        if self._enabled:
            held = self._held > 0 and not 0 < self._dense <= len(points_object)
            self._held = max(self._held - 1, 0)
            self._frames.append(voxel_downsample_centres(points_object[:0] if held else points_object, self.voxel_size))

    def hold(self, frames: int, dense: int = 0) -> None:
        """Take no points for the next ``frames`` frames (this one included), except from a frame of ``dense`` points
        or more (0: from none)."""
        self._held, self._dense = max(self._held, frames), dense

    def turn(self, angle: float) -> None:
        """Turn every frame's points by ``angle`` about the object frame's vertical axis."""
        self._frames = deque((_turned(f, angle) for f in self._frames), maxlen=self._frames.maxlen)

    def slide(self, distance: float) -> None:
        """Move every frame's points by ``distance`` along the object frame's x axis."""
        step = np.array([distance, 0.0, 0.0])
        self._frames = deque((f + step for f in self._frames), maxlen=self._frames.maxlen)

    @property
    def points(self) -> np.ndarray:
        if not self._enabled or not self._frames:
            return np.zeros((0, 3))
        return np.vstack(list(self._frames))


def _turned(points_object: np.ndarray, angle: float) -> np.ndarray:
    return points_object @ rotation_z(angle).T if len(points_object) else points_object
