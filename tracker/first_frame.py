"""Frame 1's search: several motion hypotheses along the heading, each refined, scored by the points they explain.

Frame 1 has no motion prior: the object may stand still or have moved up to ``max_speed * dt`` along its
heading (or a little backwards). A single ICP search started from zero motion can stop in a local minimum
(on a flat vehicle side, where the sensor's scan pattern leaves ridges), and every later frame is relative
to it. Here the ICP search starts from each of ``count`` evenly spaced displacements along the heading (the
same search region and yaw limit as any later frame), and the refined hypothesis whose box explains most of
the frame's points wins: a point explains when it lies in the box and within ``threshold`` of the moved
source points (previous-frame object points). Ties go to the smaller motion.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .geometry import Box, points_in_box

__all__ = ["motion_hypotheses", "explained_points"]


def motion_hypotheses(heading: float, count: int, max_forward: float, max_backward: float) -> list[np.ndarray]:
    """``count`` motions [dx, dy, 0, 0] along ``heading`` from -max_backward to +max_forward (zero included),
    ordered by distance from zero motion."""
    if count <= 1:
        return [np.zeros(4)]
    steps = np.linspace(-max_backward, max_forward, count)
    steps = np.unique(np.append(steps, 0.0))
    steps = steps[np.argsort(np.abs(steps), kind="stable")]
    c, s = np.cos(heading), np.sin(heading)
    return [np.array([d * c, d * s, 0.0, 0.0]) for d in steps]


def explained_points(local: np.ndarray, box: Box, moved_source: np.ndarray, threshold: float) -> int:
    """Number of ``local`` points inside ``box`` that lie within ``threshold`` of a ``moved_source`` point."""
    inside = local[points_in_box(local, box, 1.0)]
    if len(inside) == 0 or len(moved_source) == 0:
        return 0
    dist, _ = cKDTree(moved_source).query(inside, k=1, distance_upper_bound=threshold)
    return int(np.isfinite(dist).sum())
