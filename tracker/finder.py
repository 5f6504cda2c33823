"""Frame-1 search in the authors' style (their ``Finder``): ICP of the start frame's object points against a
FIXED wide crop of frame 1.

Frame 1 has no motion prior. The authors register the frame-0 points inside the start box (scale 1.0, no
sub-shape) against the frame-1 points inside the START box scaled 3.0 (length, width and height) — the
crop does not follow the estimate — for a fixed number of ICP iterations without an early stop. Each
iteration draws fresh random subsets (with replacement) of at most ``max_points`` of both sides, pairs each
moved source point with its nearest crop point, and solves the point-to-point loss for the motion. The
result is the motion prediction (and motion-prior reference) of frame 1's regular step.

Our default frame-1 search (``TrackerConfig.first_search="moving"``) instead crops around the current
estimate and uses the previous-frame points plus the sub-shape.
"""

from __future__ import annotations

from functools import partial

import numpy as np
from scipy.spatial import cKDTree

from .geometry import Box, points_in_box
from .solver import solve
from .terms import ResidualBlock, apply_motion, point_pair_block

__all__ = ["resample", "finder_icp"]


def resample(points: np.ndarray, max_points: int, rng: np.random.Generator) -> np.ndarray:
    """``points`` if at most ``max_points``, else ``max_points`` rows drawn uniformly WITH replacement."""
    if len(points) <= max_points:
        return points
    return points[rng.integers(len(points), size=max_points)]


def _icp_blocks(source: np.ndarray, paired: np.ndarray, pivot: np.ndarray, x: np.ndarray) -> list[ResidualBlock]:
    """The point-to-point block of ``source`` moved by ``x`` (about ``pivot``) against its ``paired`` points."""
    return [point_pair_block("icp", x, source, paired, pivot, 1.0)]


def finder_icp(source: np.ndarray, frame_points: np.ndarray, box: Box, rng: np.random.Generator, *,
               scale: float = 3.0, iterations: int = 50, max_points: int = 1000, min_points: int = 10,
               solver_iterations: int = 50) -> np.ndarray:
    """Motion [dx, dy, dz, dtheta] (rotation about ``box``'s centre, then translation) that registers the
    world ``source`` points (the start box's points) to ``frame_points`` inside ``box`` scaled ``scale``.
    Zero motion when either side has fewer than ``min_points`` points."""
    crop = frame_points[points_in_box(frame_points, box, scale)]
    x = np.zeros(4)
    if len(source) < min_points or len(crop) < min_points:
        return x
    pivot = box.center
    for _ in range(iterations):
        src = resample(source, max_points, rng)
        tgt = resample(crop, max_points, rng)
        _, idx = cKDTree(tgt).query(apply_motion(x, src, pivot), k=1)
        paired = tgt[idx]
        x = solve(partial(_icp_blocks, src, paired, pivot), x,
                  max_iterations=solver_iterations, tolerance=1e-7).x
    return x
