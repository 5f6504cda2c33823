"""The object's shape: key-frame aggregation and the sub-shape of recent frames (voxelised at voxel centres,
:func:`tracker.metrics.voxel_downsample_centres`).

All points here are in the OBJECT frame (x along the box length, origin at the box centre).
"""

from __future__ import annotations

from collections import deque

import numpy as np

from .geometry import Box, transform_points
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

    def add(self, points_object: np.ndarray) -> None:
        if len(points_object) == 0:
            return
        self.points = voxel_downsample_centres(np.vstack([self.points, points_object]), self.voxel_size)

    def __len__(self) -> int:
        return len(self.points)


class SubShape:
    """The points of the last ``frames`` frames (each voxelised), aggregated in the object frame."""

    def __init__(self, frames: int, voxel_size: float) -> None:
        self.voxel_size = voxel_size
        self._frames: deque[np.ndarray] = deque(maxlen=max(frames, 0) or None)
        self._enabled = frames > 0

    def add(self, points_object: np.ndarray) -> None:
        if self._enabled:
            self._frames.append(voxel_downsample_centres(points_object, self.voxel_size))

    @property
    def points(self) -> np.ndarray:
        if not self._enabled or not self._frames:
            return np.zeros((0, 3))
        return np.vstack(list(self._frames))
