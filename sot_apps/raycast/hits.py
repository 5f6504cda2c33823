"""What every ray-casting backend returns (:class:`RayHits`), and the analytic horizontal rectangle (a ground
plane) that both backends intersect without Embree."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["RayHits", "MISS"]

MISS = -1


@dataclass
class RayHits:
    """Per-ray results. Misses have ``distance = inf`` and ``geom_id = prim_id = -1``.

    ``distance``: (N,) float64 ray parameter (metres for unit directions; the depth z for camera rays
    ``(x, y, 1)``); ``normal``: (N, 3) float32 unit geometric
    normal facing the ray origin (zero for misses); ``prim_id``: triangle index within its mesh;
    ``geom_id``: object index (order of :meth:`RaycastScene.add_mesh`).
    """

    distance: np.ndarray
    normal: np.ndarray
    prim_id: np.ndarray
    geom_id: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        return self.geom_id >= 0

    def __len__(self) -> int:
        return int(self.distance.shape[0])

    @staticmethod
    def concatenate(parts: list["RayHits"]) -> "RayHits":
        return RayHits(np.concatenate([p.distance for p in parts]), np.concatenate([p.normal for p in parts]),
                       np.concatenate([p.prim_id for p in parts]), np.concatenate([p.geom_id for p in parts]))


@dataclass(frozen=True)
class _Rect:
    geom_id: int
    z: float
    x0: float
    x1: float
    y0: float
    y1: float


def _horizontal_rectangle(vertices: np.ndarray, faces: np.ndarray) -> tuple[float, float, float, float, float] | None:
    """(z, x0, x1, y0, y1) when the mesh is exactly an axis-aligned horizontal rectangle of two triangles."""
    if len(faces) != 2:
        return None
    used = vertices[np.unique(faces)]
    if len(used) != 4 or np.ptp(used[:, 2]) != 0.0:
        return None
    xs, ys = np.unique(used[:, 0]), np.unique(used[:, 1])
    if len(xs) != 2 or len(ys) != 2:
        return None
    corners = {(float(x), float(y)) for x, y in used[:, :2]}
    if corners != {(float(x), float(y)) for x in xs for y in ys}:
        return None
    tri = vertices[faces]
    e1, e2 = tri[:, 1, :2] - tri[:, 0, :2], tri[:, 2, :2] - tri[:, 0, :2]
    areas = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    rect_area = float((xs[1] - xs[0]) * (ys[1] - ys[0]))
    if (areas <= 0).any() or not np.isclose(areas.sum(), rect_area, rtol=1e-9):
        return None   # the two triangles do not tile the rectangle
    return float(used[0, 2]), float(xs[0]), float(xs[1]), float(ys[0]), float(ys[1])


def rect_hits(rects: list[_Rect], origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance (inf: none) and geometry id of the nearest analytic rectangle along each ray."""
    n = directions.shape[0]
    best_t = np.full(n, np.inf)
    best_g = np.full(n, MISS, np.int32)
    o = origins.astype(np.float64)
    d = directions.astype(np.float64)
    for r in rects:
        with np.errstate(divide="ignore", invalid="ignore"):   # rays parallel to the plane: rejected below
            t = (r.z - o[:, 2]) / d[:, 2]
            x = o[:, 0] + t * d[:, 0]
            y = o[:, 1] + t * d[:, 1]
        ok = (d[:, 2] != 0) & (t > 0) & (t < best_t) & (x >= r.x0) & (x <= r.x1) & (y >= r.y0) & (y <= r.y1)
        best_t[ok] = t[ok]
        best_g[ok] = r.geom_id
    return best_t, best_g
