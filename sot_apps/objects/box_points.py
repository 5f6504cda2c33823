"""How many points each of many boxes holds (the floor under detection simulation and detection scoring)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from tracker import Box, points_in_box

__all__ = ["count_points_in_boxes"]


def count_points_in_boxes(points: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Number of ``points`` (N, 3) inside each box of ``boxes`` (M, 7) [x, y, z, heading, l, w, h] or (M, 9) [...,
    roll, pitch] (tilted boxes counted with their tilt): :func:`tracker.points_in_box` on the points within the
    box's half-diagonal in x/y (a KD-tree query), so many boxes cost little."""
    boxes = np.asarray(boxes, dtype=np.float64)
    boxes = boxes.reshape(-1, boxes.shape[-1] if boxes.ndim > 1 and boxes.shape[-1] == 9 else 7)
    counts = np.zeros(len(boxes), dtype=np.int64)
    if len(points) == 0 or len(boxes) == 0:
        return counts
    tree = cKDTree(points[:, :2])
    radii = 0.5 * np.sqrt(boxes[:, 4] ** 2 + boxes[:, 5] ** 2 + (boxes[:, 6] ** 2 if boxes.shape[1] == 9 else 0.0))
    for i, (box, near) in enumerate(zip(boxes, tree.query_ball_point(boxes[:, :2], radii), strict=True)):
        counts[i] = int(points_in_box(points[near], Box(*(float(v) for v in box))).sum())
    return counts
