"""One embree scene holding every object's mesh; geometry id i = object index i.

A single first-hit query per ray gives the instance (which object is nearest) and its depth, so
inter-object occlusion comes for free.
"""

from __future__ import annotations

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from .meshing import Mesh

__all__ = ["MultiMeshScene"]


class MultiMeshScene:
    """Meshes already placed in the ray frame (e.g. camera k); ``meshes[i]`` gets geometry id i."""

    def __init__(self, meshes: list[Mesh]) -> None:
        self.scene = rtcore_scene.EmbreeScene()
        self.count = len(meshes)
        self._geometries = []
        for mesh in meshes:
            triangles = np.ascontiguousarray(mesh.vertices[mesh.faces], dtype=np.float32)
            self._geometries.append(TriangleMesh(self.scene, triangles))

    def first_hit(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For (N, 3) rays: (object index or -1, ray parameter t or inf)."""
        n = len(directions)
        if n == 0 or self.count == 0:
            return np.full(n, -1, dtype=np.int32), np.full(n, np.inf)
        out = self.scene.run(np.ascontiguousarray(np.broadcast_to(origins, (n, 3)), dtype=np.float32),
                             np.ascontiguousarray(directions, dtype=np.float32), output=1)
        geom = np.asarray(out["geomID"], dtype=np.int32)
        t = np.where(geom >= 0, np.asarray(out["tfar"], dtype=np.float64), np.inf)
        return geom, t
