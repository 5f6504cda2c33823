"""Exact nearest neighbours among voxel centres (a shape from :func:`~tracker.metrics.voxel_downsample_centres`).

The target points sit on the lattice of a grid's cell centres, one per occupied cell. A query point strictly inside
an occupied cell is nearer to that cell's centre than to any other lattice point (along every axis the centre is
less than half a cell away, every other lattice point at least half a cell), so its nearest target point is that
centre: one table look-up instead of a tree search. Points in an empty cell, within 1e-6 of a cell's size of a
cell border (where rounding could decide), or outside the grid are answered by scipy's ``cKDTree``. Squared
distances are summed as ``cKDTree`` sums them (x, then y, then z, in float64), so every answer, distance and index,
is bit for bit the kd-tree's.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .rows import all3

__all__ = ["VoxelNearest"]

_MAX_CELLS = 1 << 23     # a larger grid (a long, sparse shape): the kd-tree answers every query
_BORDER = 1e-6           # a query point this close (in cells) to a cell border goes to the kd-tree


class VoxelNearest:
    """The nearest of ``target`` (M, 3) points to each query point, as ``cKDTree(target).query(points, k=1)``
    gives it. ``cell``: the grid size of a voxel-centre shape (points (i + 0.5) * cell, at most one per cell);
    other targets (or too large a grid) send every query to the kd-tree. ``tree``: a kd-tree of ``target`` when the
    caller has one (else one is built the first time a query needs it)."""

    def __init__(self, target: np.ndarray, cell: float, tree: cKDTree | None = None) -> None:
        self.target = np.ascontiguousarray(target, dtype=np.float64).reshape(-1, 3)
        self.cell = float(cell)
        self._tree = tree
        self.table: np.ndarray | None = None
        if len(self.target) == 0 or not self.cell > 0 or not np.all(np.isfinite(self.target)):
            return
        keys = np.floor(self.target / self.cell)
        if not np.array_equal((keys + 0.5) * self.cell, self.target):   # not the centres of this grid
            return
        keys = keys.astype(np.int64)
        self.low = keys.min(axis=0)
        self.dims = keys.max(axis=0) - self.low + 1
        if float(np.prod(self.dims.astype(np.float64))) > _MAX_CELLS:
            return
        self.strides = np.array([self.dims[1] * self.dims[2], self.dims[2], 1], dtype=np.int64)
        flat = (keys - self.low) @ self.strides
        table = np.full(int(np.prod(self.dims)), -1, dtype=np.int64)
        table[flat] = np.arange(len(flat))
        if np.count_nonzero(table >= 0) == len(flat):   # one point per cell
            self.table = table

    @property
    def tree(self) -> cKDTree:
        if self._tree is None:
            self._tree = cKDTree(self.target)
        return self._tree

    def query(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distances (N,) and target indices (N,) of each point's nearest target point."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if self.table is None or len(points) == 0:
            return self.tree.query(points, k=1)
        with np.errstate(invalid="ignore"):   # a non-finite point gives NaN here: not clear, the tree refuses it
            scaled = points / self.cell
            keys = np.floor(scaled)
            scaled -= keys                               # the position inside the cell, 0..1
            scaled -= 0.5
            np.abs(scaled, out=scaled)
            keys -= self.low
            # inside the grid and clear of the cell's borders (NaN: neither)
            clear = all3((scaled <= 0.5 - _BORDER) & (keys >= 0) & (keys < self.dims))
        rows = np.flatnonzero(clear)
        cells = keys[rows] @ self.strides.astype(np.float64)    # exact: integers below 2**23
        cand = self.table[cells.astype(np.int64)]
        hit = cand >= 0
        rows, cand = rows[hit], cand[hit]
        q, t = points[rows], self.target[cand]
        d2 = (q[:, 0] - t[:, 0]) ** 2
        d2 += (q[:, 1] - t[:, 1]) ** 2
        d2 += (q[:, 2] - t[:, 2]) ** 2
        dist = np.empty(len(points))
        idx = np.empty(len(points), dtype=np.intp)
        dist[rows], idx[rows] = np.sqrt(d2), cand
        rest = np.ones(len(points), dtype=bool)
        rest[rows] = False
        if rest.any():
            dist[rest], idx[rest] = self.tree.query(points[rest], k=1)
        return dist, idx
