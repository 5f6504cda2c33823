"""Shape points (object frame) -> triangle mesh for raycasting.

Uses the LiDAR simulator's surfel meshing when it is available (``sot_apps.lidar_sim.meshing``);
otherwise the convex hull of the points, which suits vehicles (convex-ish) and always closes the
surface, so every pixel of the silhouette gets a hit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

__all__ = ["Mesh", "mesh_from_points", "box_mesh", "voxel_downsample"]


@dataclass(frozen=True)
class Mesh:
    """Triangle mesh: ``vertices`` (V, 3) float64, ``faces`` (F, 3) int32 (object frame unless said)."""

    vertices: np.ndarray
    faces: np.ndarray

    def transformed(self, target_from_source: np.ndarray) -> "Mesh":
        v = self.vertices @ np.ascontiguousarray(target_from_source[:3, :3].T) + target_from_source[:3, 3]
        return Mesh(v, self.faces)


def voxel_downsample(points: np.ndarray, voxel: float) -> np.ndarray:
    """One point (the mean) per occupied voxel of size ``voxel``."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) == 0 or voxel <= 0:
        return points
    keys = np.floor(points / voxel).astype(np.int64)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    sums = np.zeros((len(counts), 3))
    np.add.at(sums, inverse, points)
    return sums / counts[:, None]


def box_mesh(length: float, width: float, height: float) -> Mesh:
    """Closed box centred at the origin, 12 outward-facing triangles."""
    l, w, h = length / 2.0, width / 2.0, height / 2.0
    v = np.array([[x, y, z] for x in (-l, l) for y in (-w, w) for z in (-h, h)], dtype=np.float64)
    hull = ConvexHull(v)
    return Mesh(v, _outward(v, hull.simplices.astype(np.int32)))


def _outward(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    centre = vertices.mean(axis=0)
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    normal = np.cross(b - a, c - a)
    flip = np.einsum("ij,ij->i", normal, a - centre) < 0
    faces = faces.copy()
    faces[flip] = faces[flip][:, ::-1]
    return faces


def _convex_hull(points: np.ndarray) -> Mesh | None:
    try:
        hull = ConvexHull(points)
    except (QhullError, ValueError):
        return None
    used = np.unique(hull.simplices)
    remap = np.full(len(points), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    vertices = points[used]
    return Mesh(vertices, _outward(vertices, remap[hull.simplices].astype(np.int32)))


def mesh_from_points(points: np.ndarray, method: str = "auto") -> Mesh | None:
    """Mesh an object's shape points (object frame). ``method``: "auto", "surfel" or "hull".

    Returns None when the points cannot span a surface (fewer than 4, or all coplanar).
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) < 4:
        return None
    if method in ("auto", "surfel"):
        mesh = _surfel_mesh(points)
        if mesh is not None:
            return mesh
        if method == "surfel":
            return None
    return _convex_hull(points)


def _surfel_mesh(points: np.ndarray) -> Mesh | None:
    """The LiDAR simulator's surfel meshing, when that module exists."""
    try:
        from ..lidar_sim import meshing as sim_meshing  # type: ignore[attr-defined]
    except ImportError:
        return None
    fn = getattr(sim_meshing, "mesh_from_points", None) or getattr(sim_meshing, "surfel_mesh", None)
    if fn is None:
        return None
    result = fn(points)
    vertices = np.asarray(getattr(result, "vertices", result[0] if isinstance(result, tuple) else None), dtype=np.float64)
    faces = np.asarray(getattr(result, "faces", result[1] if isinstance(result, tuple) else None), dtype=np.int32)
    if vertices.ndim != 2 or len(faces) == 0:
        return None
    return Mesh(vertices, faces)
