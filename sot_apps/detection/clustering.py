"""Bird's-eye-view clustering with a range-adaptive radius: connected components of a KD-tree graph.

Points are first thinned to one per ``voxel`` BEV cell (dense near points would make the graph large);
two cells are linked when their distance is at most the link radius at their range, ``radius(r) =
clip(base + slope * r, base, maximum)`` (beams spread with range, so a far object's returns lie further
apart); the clusters are the graph's connected components (scipy.sparse.csgraph). No loop over points.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

__all__ = ["link_radius", "cluster_bev"]


def link_radius(range_m: np.ndarray, base: float, slope: float, maximum: float) -> np.ndarray:
    """The link radius (m) at BEV range ``range_m`` from the sensor."""
    return np.clip(base + slope * np.asarray(range_m, dtype=np.float64), base, maximum)


def cluster_bev(xy: np.ndarray, sensor_xy: np.ndarray, base: float = 0.3, slope: float = 0.01,
                maximum: float = 0.7, voxel: float = 0.1) -> np.ndarray:
    """Cluster label (N,) of every (N, 2) point, 0 .. n_clusters - 1 (every point belongs to a cluster)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    if len(xy) == 0:
        return np.zeros(0, dtype=np.int64)
    key = np.floor(xy / voxel).astype(np.int64)
    key -= key.min(axis=0)
    flat = key[:, 0] * (int(key[:, 1].max()) + 1) + key[:, 1]      # one integer per cell: a 1-D unique
    _, first, inverse = np.unique(flat, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    cells = key[first]
    centres = (cells + 0.5) * voxel + np.floor(xy.min(axis=0) / voxel) * voxel
    radius = link_radius(np.hypot(*(centres - sensor_xy).T), base, slope, maximum)
    pairs = cKDTree(centres).query_pairs(float(radius.max()), output_type="ndarray")
    if len(pairs):
        gap = np.hypot(*(centres[pairs[:, 0]] - centres[pairs[:, 1]]).T)
        pairs = pairs[gap <= np.minimum(radius[pairs[:, 0]], radius[pairs[:, 1]])]
    graph = coo_matrix((np.ones(len(pairs), dtype=np.int8), (pairs[:, 0], pairs[:, 1])),
                       shape=(len(cells), len(cells)))
    _, labels = connected_components(graph, directed=False)
    return labels[inverse].astype(np.int64)
