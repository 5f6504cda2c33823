"""The tracker's input: one LiDAR sweep with its ego pose and timing.

The tracker never reads files. Anything that can hand it :class:`LidarFrame` objects by index
(a :class:`FrameSource`) can be tracked; ``sot_apps.io.Sequence`` is one such source.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from .geometry import transform_points

__all__ = ["LidarFrame", "FrameSource"]


@dataclass(frozen=True)
class LidarFrame:
    """One sweep.

    Attributes:
        index: the frame's index in its sequence.
        timestamp_ns: the frame time (integer nanoseconds).
        points_ego: (N, 3) float32/float64 points in the ego frame.
        world_from_ego: 4x4 ego pose at ``timestamp_ns``.
        point_time_offset_ns: optional (N,) int64 capture time of each point relative to
            ``timestamp_ns`` (negative = before). Used to de-skew sweeps that are not motion-compensated.
        has_sweep: False when the sweep of this frame is missing (its pose and time are known): the
            tracker predicts through it without measuring and flags the estimate ``no_sweep``.
    """

    index: int
    timestamp_ns: int
    points_ego: np.ndarray
    world_from_ego: np.ndarray
    point_time_offset_ns: np.ndarray | None = None
    has_sweep: bool = True

    def points_world(self) -> np.ndarray:
        """(N, 3) float64 points in the world frame (no de-skew)."""
        return transform_points(self.world_from_ego, self.points_ego)


@runtime_checkable
class FrameSource(Protocol):
    """A sequence of sweeps addressed by frame index."""

    def __len__(self) -> int: ...

    def lidar_frame(self, index: int) -> LidarFrame: ...
