"""Several ego-motion-compensated sweeps in one cloud, and what sweep-to-sweep differences say about motion.

A static surface seen in the previous sweeps lies where the current sweep sees it (after ego-motion
compensation); a moving object's earlier returns lie behind it, along its travel. So:

- :func:`to_current_ego`: an earlier sweep moved into the CURRENT ego frame;
- :func:`near_mask`: which query points have a reference point within about ``distance`` in bird's-eye view
  (a BEV occupancy grid of cell ``distance``, dilated by one cell: the true reach is between ``distance``
  and 2.8 ``distance``; O(N), no tree). Earlier points near the current (non-ground) points are kept:
  static objects get the earlier sweeps' returns (other beams, other viewpoints: denser, fuller outlines),
  a moving object does not get its smear; a current point that no point of the oldest earlier sweep is near
  was elsewhere then: it is MOVING.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from tracker import transform_points

__all__ = ["to_current_ego", "near_mask"]


def to_current_ego(points_ego: np.ndarray, world_from_ego: np.ndarray, current_world_from_ego: np.ndarray
                   ) -> np.ndarray:
    """(N, 3) points of an earlier sweep (its own ego frame) in the ego frame of the current sweep."""
    current_from_ego = np.linalg.solve(np.asarray(current_world_from_ego, dtype=np.float64),
                                       np.asarray(world_from_ego, dtype=np.float64))
    return transform_points(current_from_ego, np.asarray(points_ego, dtype=np.float64).reshape(-1, 3))


def near_mask(reference_xy: np.ndarray, query_xy: np.ndarray, distance: float) -> np.ndarray:
    """Mask (M,) of the ``query_xy`` points with a ``reference_xy`` point within about ``distance`` (BEV)."""
    reference_xy = np.asarray(reference_xy, dtype=np.float64).reshape(-1, 2)
    query_xy = np.asarray(query_xy, dtype=np.float64).reshape(-1, 2)
    if len(reference_xy) == 0 or len(query_xy) == 0:
        return np.zeros(len(query_xy), dtype=bool)
    low = reference_xy.min(axis=0) - 2.0 * distance
    ref = np.floor((reference_xy - low) / distance).astype(np.int64)
    shape = ref.max(axis=0) + 3
    grid = np.zeros(shape, dtype=bool)
    grid[ref[:, 0], ref[:, 1]] = True
    grid = ndimage.binary_dilation(grid, structure=np.ones((3, 3), dtype=bool))
    q = np.floor((query_xy - low) / distance).astype(np.int64)
    inside = np.all((q >= 0) & (q < shape), axis=1)
    out = np.zeros(len(query_xy), dtype=bool)
    out[inside] = grid[q[inside, 0], q[inside, 1]]
    return out
