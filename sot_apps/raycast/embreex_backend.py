"""The ``embreex`` backend: ``embreex.rtcore_scene.EmbreeScene.run`` (one ``TriangleMesh`` per object), used when
the compiled loop is missing (no C compiler at install time) or when ``SOT_APPS_RAYCAST=embreex``."""

from __future__ import annotations

import numpy as np

from .hits import MISS, RayHits, _Rect, rect_hits

__all__ = ["EmbreexBackend"]

_EMBREE_MISS_T = 1e30  # embree reports tfar ~1e37 for a miss


class EmbreexBackend:
    """An embreex scene plus the analytic rectangles (each ray's Embree segment ends at its rectangle hit)."""

    def __init__(self) -> None:
        from embreex import rtcore_scene

        self._scene = rtcore_scene.EmbreeScene()
        self._meshes: list = []
        self._geom_of_embree: list[int] = []
        self._rects: list[_Rect] = []

    def add_rect(self, geom_id: int, rect: tuple[float, float, float, float, float]) -> None:
        self._rects.append(_Rect(geom_id, *rect))

    def add_mesh(self, geom_id: int, vertices: np.ndarray, faces: np.ndarray) -> None:
        from embreex.mesh_construction import TriangleMesh

        self._meshes.append(TriangleMesh(self._scene, vertices, faces))
        self._geom_of_embree.append(geom_id)

    def commit(self) -> None:
        """embreex builds its structure at the first ``run``."""

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> RayHits:
        n = directions.shape[0]
        directions = np.ascontiguousarray(directions, dtype=np.float32)
        origins = np.ascontiguousarray(np.broadcast_to(origins, (n, 3)), dtype=np.float32)
        rect_t, rect_geom = rect_hits(self._rects, origins, directions)
        if self._meshes:
            tfar = np.where(np.isfinite(rect_t), rect_t, 1e37).astype(np.float32)
            out = self._scene.run(origins, directions, dists=tfar, output=1)
            embree_geom = np.asarray(out["geomID"], dtype=np.int32)
        else:
            out, embree_geom = None, np.full(n, MISS, np.int32)
        mesh_hit = embree_geom >= 0
        ids = np.asarray(self._geom_of_embree + [MISS], dtype=np.int32)
        geom = np.where(mesh_hit, ids[np.where(mesh_hit, embree_geom, -1)], rect_geom).astype(np.int32)
        hit = geom >= 0
        dist = np.where(mesh_hit, np.asarray(out["tfar"], np.float64) if out is not None else np.inf, rect_t)
        dist[~hit | (dist > _EMBREE_MISS_T)] = np.inf
        normal = np.zeros((n, 3), np.float32)
        if out is not None:
            ng = np.asarray(out["Ng"], dtype=np.float32)[mesh_hit]
            length = np.linalg.norm(ng, axis=1)
            ng = ng / np.where(length > 0, length, 1.0)[:, None]
            facing = np.einsum("ij,ij->i", ng, directions[mesh_hit]) > 0
            ng[facing] *= -1.0
            normal[mesh_hit] = ng
        on_rect = ~mesh_hit & hit
        normal[on_rect, 2] = np.where(directions[on_rect, 2] > 0, -1.0, 1.0)
        prim = np.full(n, MISS, np.int32)
        if out is not None:
            prim[mesh_hit] = np.asarray(out["primID"], dtype=np.int32)[mesh_hit]
        prim[on_rect] = 0
        return RayHits(dist, normal, prim, geom)
