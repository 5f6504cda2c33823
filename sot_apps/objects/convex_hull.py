"""Convex hull of 3D points in numpy (incremental quickhull), so meshing a shape needs no scipy.spatial (qhull):
importing scipy.spatial costs ~0.35 s, more than meshing and the flow of ten image pairs together.

:func:`hull_faces` returns the hull's triangles, outward (counter-clockwise seen from outside), in a canonical
order: each triangle starts at its smallest point index, triangles sorted. Points within a tolerance of a face
(``1e-13`` of the points' extent, about qhull's round-off) count as inside. Flat input (no volume) gives None, as
qhull's error does. Points in general position give exactly qhull's triangles; where more than three points lie
on one face (a voxel grid's planes), both triangulate that polygon, each its own way. A result that is not a
closed surface holding every point (only nearly degenerate input can do that), or a hull of more than 512
vertices (each costs a Python step; vehicle shapes have 40-250), is qhull's.
"""

from __future__ import annotations

import numpy as np

__all__ = ["hull_faces", "canonical_faces"]

_MAX_VERTICES = 512   # hulls with more vertices (vehicles have 40-250) go to qhull: each vertex costs a Python step
_TOLERANCE = 1e-13  # of the points' extent: a point nearer to a face than this is on it (inside; qhull: its round-off)


def canonical_faces(faces: np.ndarray) -> np.ndarray:
    """Triangles rotated to start at their smallest index (orientation kept), sorted: the same surface gives the
    same array whichever algorithm found it."""
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    shift = np.argmin(faces, axis=1)
    rotated = faces[np.arange(len(faces))[:, None], (shift[:, None] + np.arange(3)) % 3]
    return rotated[np.lexsort(rotated.T[::-1])]


def hull_faces(points: np.ndarray) -> np.ndarray | None:
    """(F, 3) int64 triangles (indices into ``points`` (N, 3)) of their convex hull, outward and canonical (module
    doc); None when they span no volume (flat, fewer than 4) or hold a non-finite value."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) < 4 or not np.isfinite(points).all():
        return None
    extent = float(np.ptp(points, axis=0).max())
    eps = _TOLERANCE * max(extent, float(np.abs(points).max()))
    if extent <= eps:
        return None
    faces = _quickhull(points, eps)
    if faces is None or not _closed_and_holding(points, faces, eps):
        faces = _qhull_faces(points)
        if faces is None:
            return None
    return canonical_faces(faces)


def _qhull_faces(points: np.ndarray) -> np.ndarray | None:
    """The hull by scipy's qhull, oriented outward (the fallback for input too degenerate for :func:`_quickhull`)."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        faces = ConvexHull(points).simplices.astype(np.int64)
    except (QhullError, ValueError):
        return None
    a, b, c = points[faces[:, 0]], points[faces[:, 1]], points[faces[:, 2]]
    inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), a - points.mean(axis=0)) < 0
    faces[inward] = faces[inward][:, ::-1]
    return faces


def _initial_simplex(points: np.ndarray, eps: float) -> list[int] | None:
    axis = int(np.argmax(np.ptp(points, axis=0)))
    i0, i1 = int(np.argmin(points[:, axis])), int(np.argmax(points[:, axis]))
    a, d = points[i0], points[i1] - points[i0]
    off_line = np.cross(points - a, d)
    i2 = int(np.argmax(np.einsum("ij,ij->i", off_line, off_line)))
    if np.linalg.norm(off_line[i2]) <= eps * np.linalg.norm(d):
        return None
    normal = np.cross(d, points[i2] - a)
    normal /= np.linalg.norm(normal)
    height = (points - a) @ normal
    i3 = int(np.argmax(np.abs(height)))
    if abs(height[i3]) <= eps:
        return None
    return [i0, i1, i2, i3]


class _Faces:
    """The hull's triangles so far: vertex indices, unit normals, offsets (n . x = offset on the plane), alive."""

    def __init__(self, points: np.ndarray, capacity: int) -> None:
        self.points = points
        self.tri: list[tuple[int, int, int]] = []
        self.normal = np.zeros((capacity, 3))
        self.offset = np.zeros(capacity)
        self.alive = np.zeros(capacity, dtype=bool)
        self.edge_face: dict[tuple[int, int], int] = {}   # directed edge (a, b) -> the face holding it

    @property
    def count(self) -> int:
        return len(self.tri)

    def add(self, tris: list[tuple[int, int, int]]) -> np.ndarray | None:
        """Faces (a, b, c), counter-clockwise seen from outside; their ids, or None when one is degenerate or
        their edges clash with the surface's (not a surface)."""
        f0, f1 = self.count, self.count + len(tris)
        while f1 > len(self.offset):
            grow = len(self.offset)
            self.normal = np.concatenate([self.normal, np.zeros((grow, 3))])
            self.offset = np.concatenate([self.offset, np.zeros(grow)])
            self.alive = np.concatenate([self.alive, np.zeros(grow, dtype=bool)])
        corners = self.points[np.asarray(tris, dtype=np.int64).reshape(-1, 3)]   # (T, 3 corners, 3)
        a = corners[:, 0]
        n = np.cross(corners[:, 1] - a, corners[:, 2] - a)
        length = np.sqrt(np.einsum("ij,ij->i", n, n))
        if not (length > 0.0).all():
            return None
        n /= length[:, None]
        self.normal[f0:f1] = n
        self.offset[f0:f1] = np.einsum("ij,ij->i", n, a)
        self.alive[f0:f1] = True
        edge_face = self.edge_face
        for f, (i, j, k) in enumerate(tris, start=f0):
            for edge in ((i, j), (j, k), (k, i)):
                if edge in edge_face:
                    return None
                edge_face[edge] = f
        self.tri.extend(tris)
        return np.arange(f0, f1)

    def remove(self, f: int) -> None:
        a, b, c = self.tri[f]
        del self.edge_face[(a, b)], self.edge_face[(b, c)], self.edge_face[(c, a)]
        self.alive[f] = False


def _quickhull(points: np.ndarray, eps: float) -> np.ndarray | None:
    simplex = _initial_simplex(points, eps)
    if simplex is None:
        return None
    faces = _Faces(points, 256)
    i0, i1, i2, i3 = simplex
    centre = points[simplex].mean(axis=0)
    first = []
    for a, b, c in ((i0, i1, i2), (i0, i3, i1), (i1, i3, i2), (i0, i2, i3)):
        n = np.cross(points[b] - points[a], points[c] - points[a])
        first.append((a, b, c) if n @ (points[a] - centre) >= 0 else (a, c, b))
    if faces.add(first) is None:
        return None
    # per point: the face it lies highest above, -1 once it is on or inside the hull, and that height
    owner, height = _assign(points, faces, np.arange(4), eps)
    owner[simplex] = -1
    for _ in range(min(len(points), _MAX_VERTICES)):
        outside = np.flatnonzero(owner >= 0)
        if len(outside) == 0:
            return np.asarray(faces.tri, dtype=np.int64)[faces.alive[:faces.count]]
        p = int(outside[np.argmax(height[outside])])
        point = points[p]
        above = (faces.normal[:faces.count] @ point - faces.offset[:faces.count] > eps).tolist()
        visible = _visible_region(faces, int(owner[p]), above)
        horizon = [(b, a) for f in visible for a, b in _reversed_edges(faces.tri[f])
                   if faces.edge_face[(a, b)] not in visible]
        for f in visible:
            faces.remove(f)
        new = faces.add([(a, b, p) for a, b in horizon])
        if new is None:
            return None
        owner[p] = -1
        # the points above a removed face are above a new face or inside the hull now
        moved = outside[~faces.alive[owner[outside]]]
        if len(moved):
            owner[moved], height[moved] = _assign(points[moved], faces, new, eps)
    return None


def _reversed_edges(tri: tuple[int, int, int]) -> tuple[tuple[int, int], ...]:
    a, b, c = tri
    return (b, a), (c, b), (a, c)


def _assign(points: np.ndarray, faces: _Faces, face_ids: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray]:
    """For each point: the face of ``face_ids`` it lies highest above (-1: above none by more than ``eps``) and
    that height."""
    heights = points @ faces.normal[face_ids].T - faces.offset[face_ids]
    best = np.argmax(heights, axis=1)
    height = heights[np.arange(len(points)), best]
    return np.where(height > eps, face_ids[best], -1), height


def _visible_region(faces: _Faces, start: int, above: list[bool]) -> set[int]:
    """The faces marked ``above`` (the new point lies above them) connected to ``start`` (which is above)."""
    visible, stack = {start}, [start]
    edge_face = faces.edge_face
    while stack:
        for edge in _reversed_edges(faces.tri[stack.pop()]):
            g = edge_face[edge]
            if above[g] and g not in visible:
                visible.add(g)
                stack.append(g)
    return visible


def _closed_and_holding(points: np.ndarray, faces: np.ndarray, eps: float) -> bool:
    """Every directed edge has its reverse exactly once (a closed, consistently oriented surface) and no point
    lies above any face by more than the tolerance."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    forward = {tuple(e) for e in edges.tolist()}
    if len(forward) != len(edges) or any((b, a) not in forward for a, b in forward):
        return False
    a, b, c = points[faces[:, 0]], points[faces[:, 1]], points[faces[:, 2]]
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    above = points @ normal.T - np.einsum("ij,ij->i", normal, a)
    return bool(above.max() <= 10 * eps)
