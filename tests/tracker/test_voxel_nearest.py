"""VoxelNearest answers exactly as scipy's cKDTree (distances and indices bit for bit), on voxel-centre shapes,
query points on and near cell borders, outside the grid, non-finite (refused), and on targets that are not voxel centres."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from tracker.metrics import voxel_downsample_centres
from tracker.voxel_nearest import VoxelNearest


def _shape(rng: np.random.Generator, voxel: float) -> np.ndarray:
    """A car-like surface (box faces, noisy) as voxel centres."""
    n = 4000
    face = rng.integers(0, 3, n)
    p = rng.uniform(-1, 1, (n, 3)) * [2.3, 0.9, 0.8]
    p[face == 0, 0] = np.sign(p[face == 0, 0]) * 2.3
    p[face == 1, 1] = np.sign(p[face == 1, 1]) * 0.9
    p[face == 2, 2] = 0.8
    return voxel_downsample_centres(p + rng.normal(0, 0.02, p.shape) + [10.0, -3.0, 0.5], voxel)


@pytest.mark.parametrize("voxel", [0.05, 0.1])
def test_same_answers_as_the_kd_tree(voxel):
    rng = np.random.default_rng(3)
    shape = _shape(rng, voxel)
    near = shape[rng.integers(0, len(shape), 3000)] + rng.normal(0, voxel, (3000, 3))
    far = rng.uniform(-5, 25, (500, 3))                       # mostly outside the grid
    border = np.round(near[:500] / voxel) * voxel             # on cell borders (exact ties of two centres)
    border[:, 1] = near[:500, 1]
    special = np.array([[np.nan, 0, 0], [np.inf, 1, 1], shape[0], shape[-1]])
    queries = np.vstack([near, far, border, special[2:]])
    nearest = VoxelNearest(shape, voxel)
    assert nearest.table is not None                          # the look-up is in use
    want_d, want_i = cKDTree(shape).query(queries, k=1)
    got_d, got_i = nearest.query(queries)
    assert np.array_equal(got_d, want_d)
    assert np.array_equal(got_i, want_i)
    assert np.all(got_d[-2:] == 0.0)
    for bad in special[:2]:   # non-finite query points: refused as the kd-tree refuses them
        with pytest.raises(ValueError):
            cKDTree(shape).query(bad[None], k=1)
        with pytest.raises(ValueError):
            nearest.query(bad[None])


def test_targets_off_the_lattice_go_to_the_kd_tree():
    rng = np.random.default_rng(4)
    target = rng.normal(0, 1, (500, 3))
    nearest = VoxelNearest(target, 0.05)
    assert nearest.table is None
    queries = rng.normal(0, 1, (200, 3))
    want = cKDTree(target).query(queries, k=1)
    got = nearest.query(queries)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
