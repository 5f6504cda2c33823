"""Pseudo-ground-truth shapes (LiDAR-SOT): ground-removed points inside the ground-truth boxes of all
frames, moved to the object frame and voxelised.

Per frame: the world points near the ground-truth box (its bird's-eye-view square grown by ``margin``
metres, the same local region the tracker fits its ground planes on) are ground-removed with GPF
(:mod:`tracker.ground`), the points inside the box (scale 1.0) are moved to the object frame, and the
union over all frames is voxelised at ``voxel`` (one point per voxel, at the voxel centre). Points are
used as the sensor reported them (no de-skew), like the annotations they were labelled on.
"""

from __future__ import annotations

from typing import Iterable, Sequence

import numpy as np

from .frames import FrameSource
from .geometry import Box, points_in_box, transform_points
from .ground import GroundParams, ground_mask
from .metrics import voxel_downsample_centres

__all__ = ["object_points_in_box", "pseudo_gt_shape", "mean_points_in_boxes"]


def _points_world(source: FrameSource, index: int) -> np.ndarray:
    """World points of a frame; uses the source's own (possibly cached) ``points_world`` when it has one."""
    getter = getattr(source, "points_world", None)
    return getter(int(index)) if callable(getter) else source.lidar_frame(int(index)).points_world()


def object_points_in_box(points_world: np.ndarray, box: Box, ground_params: GroundParams | None = None,
                         margin: float = 3.0, remove_ground: bool = True) -> np.ndarray:
    """Object-frame (N, 3) points of ``points_world`` inside ``box`` after local ground removal."""
    pts = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    reach = 0.5 * max(box.length, box.width) + margin
    local = pts[np.all(np.abs(pts[:, :2] - box.center[:2]) <= reach, axis=1)]
    if remove_ground and len(local) >= 3:
        local = local[~ground_mask(local, ground_params)]
    inside = local[points_in_box(local, box, 1.0)]
    return transform_points(box.object_from_world(), inside)


def pseudo_gt_shape(source: FrameSource, frames: Sequence[int], boxes: Sequence[Box],
                    ground_params: GroundParams | None = None, voxel: float = 0.05, margin: float = 3.0,
                    remove_ground: bool = True) -> np.ndarray:
    """The pseudo-ground-truth shape (M, 3), object frame, voxel centres at ``voxel``."""
    if len(frames) != len(boxes):
        raise ValueError(f"{len(frames)} frames but {len(boxes)} boxes")
    parts: list[np.ndarray] = []
    for k, box in zip(frames, boxes, strict=True):
        parts.append(object_points_in_box(_points_world(source, k), box, ground_params, margin, remove_ground))
    if not parts:
        return np.zeros((0, 3))
    return voxel_downsample_centres(np.vstack(parts), voxel)


def mean_points_in_boxes(source: FrameSource, frames: Iterable[int], boxes: Iterable[Box]) -> float:
    """Mean number of sweep points (not ground-removed) inside the boxes: the LiDAR-SOT difficulty statistic
    when given a tracklet's first 10 frames."""
    counts = [int(points_in_box(_points_world(source, k), box, 1.0).sum())
              for k, box in zip(frames, boxes, strict=True)]
    return float(np.mean(counts)) if counts else float("nan")
