"""Ray casting with Embree (embreex called directly).

Every object is its own ``TriangleMesh`` in one Embree scene, so Embree's geometry id of a hit is the
object's index in the order the meshes were added. Embree holds the GIL while it traces, so large jobs
are split over processes (:func:`cast_rays` with ``processes > 1``; the workers are forked and rebuild the
scene from the inherited triangle arrays).
"""

from __future__ import annotations

import multiprocessing as mp
import os
from dataclasses import dataclass

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

__all__ = ["RayHits", "RaycastScene", "cast_rays", "MISS"]

MISS = -1
_EMBREE_MISS_T = 1e30  # embree reports tfar ~1e37 for a miss


@dataclass
class RayHits:
    """Per-ray results. Misses have ``distance = inf`` and ``geom_id = prim_id = -1``.

    ``distance``: (N,) float64 metres along the unit direction; ``normal``: (N, 3) float32 unit geometric
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


class RaycastScene:
    """An Embree scene of triangle meshes; ``add_mesh`` returns the object's geometry id."""

    def __init__(self) -> None:
        self._scene = rtcore_scene.EmbreeScene()
        self._meshes: list[TriangleMesh] = []
        self.vertices: list[np.ndarray] = []
        self.faces: list[np.ndarray] = []

    def __len__(self) -> int:
        return len(self._meshes)

    def add_mesh(self, vertices: np.ndarray, faces: np.ndarray) -> int:
        """Add one object's mesh ((V, 3) vertices, (F, 3) int faces); returns its geometry id."""
        vertices = np.ascontiguousarray(vertices, dtype=np.float32).reshape(-1, 3)
        faces = np.ascontiguousarray(faces, dtype=np.int32).reshape(-1, 3)
        if len(faces) == 0:
            raise ValueError("a mesh needs at least one triangle")
        self._meshes.append(TriangleMesh(self._scene, vertices, faces))
        self.vertices.append(vertices)
        self.faces.append(faces)
        return len(self._meshes) - 1

    @property
    def num_triangles(self) -> int:
        return int(sum(len(f) for f in self.faces))

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> RayHits:
        """Trace rays (unit ``directions``) and return the first hit of each."""
        origins = np.ascontiguousarray(np.broadcast_to(np.asarray(origins, dtype=np.float32),
                                                       np.shape(directions)), dtype=np.float32)
        directions = np.ascontiguousarray(directions, dtype=np.float32)
        n = directions.shape[0]
        if n == 0 or not self._meshes:
            return RayHits(np.full(n, np.inf), np.zeros((n, 3), np.float32), np.full(n, MISS, np.int32),
                           np.full(n, MISS, np.int32))
        out = self._scene.run(origins, directions, output=1)
        geom = np.asarray(out["geomID"], dtype=np.int32)
        hit = geom >= 0
        dist = np.asarray(out["tfar"], dtype=np.float64)
        dist[~hit | (dist > _EMBREE_MISS_T)] = np.inf
        normal = np.asarray(out["Ng"], dtype=np.float32)
        length = np.linalg.norm(normal, axis=1)
        normal = normal / np.where(length > 0, length, 1.0)[:, None]
        facing = np.einsum("ij,ij->i", normal, directions) > 0
        normal[facing] *= -1.0
        normal[~hit] = 0.0
        prim = np.asarray(out["primID"], dtype=np.int32)
        prim[~hit] = MISS
        return RayHits(dist, normal, prim, geom)


_WORKER_SCENE: RaycastScene | None = None
_WORKER_ARGS: tuple | None = None


def _worker_cast(span: tuple[int, int]) -> RayHits:
    global _WORKER_SCENE
    assert _WORKER_ARGS is not None
    vertices, faces, origins, directions = _WORKER_ARGS
    if _WORKER_SCENE is None:
        _WORKER_SCENE = RaycastScene()
        for v, f in zip(vertices, faces):
            _WORKER_SCENE.add_mesh(v, f)
    a, b = span
    o = origins if origins.ndim == 1 else origins[a:b]
    return _WORKER_SCENE.cast(o, directions[a:b])


def cast_rays(scene: RaycastScene, origins: np.ndarray, directions: np.ndarray, processes: int = 1,
              min_rays_per_process: int = 200_000) -> RayHits:
    """Cast rays, splitting them over ``processes`` forked workers when the job is large enough."""
    n = int(np.shape(directions)[0])
    processes = max(1, min(int(processes), n // max(1, min_rays_per_process), os.cpu_count() or 1))
    if processes <= 1 or "fork" not in mp.get_all_start_methods():
        return scene.cast(origins, directions)
    global _WORKER_ARGS, _WORKER_SCENE
    origins = np.asarray(origins, dtype=np.float32)
    _WORKER_ARGS = (scene.vertices, scene.faces, origins, np.asarray(directions, dtype=np.float32))
    _WORKER_SCENE = None
    bounds = np.linspace(0, n, processes + 1).astype(int)
    spans = [(int(bounds[i]), int(bounds[i + 1])) for i in range(processes)]
    try:
        with mp.get_context("fork").Pool(processes) as pool:
            parts = pool.map(_worker_cast, spans)
    finally:
        _WORKER_ARGS = None
    return RayHits.concatenate(parts)
