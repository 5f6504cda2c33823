"""A frame source that keeps every LiDAR frame it has read (the tracker evaluation and the auto-labeller read
each sweep many times)."""

from __future__ import annotations

import numpy as np

from tracker import LidarFrame

from .sequence import Sequence

__all__ = ["CachedSource"]


class CachedSource:
    """A FrameSource that keeps every frame it has read (evaluation reads each sweep many times)."""

    def __init__(self, sequence: Sequence) -> None:
        self.sequence = sequence
        self._frames: dict[int, LidarFrame] = {}
        self._world: dict[int, np.ndarray] = {}

    def __len__(self) -> int:
        return len(self.sequence)

    @property
    def frames(self):
        """The sequence's frame records (timestamps, poses; no sweep is read)."""
        return self.sequence.frames

    def lidar_frame(self, index: int) -> LidarFrame:
        frame = self._frames.get(index)
        if frame is None:
            frame = self.sequence.lidar_frame(index)
            self._frames[index] = frame
        return frame

    def points_world(self, index: int) -> np.ndarray:
        """(N, 3) float64 world points of a frame (no de-skew), cached."""
        pts = self._world.get(index)
        if pts is None:
            pts = self.lidar_frame(index).points_world()
            self._world[index] = pts
        return pts
