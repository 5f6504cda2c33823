"""All objects' meshes in one embree scene; geometry id i = object i.

A single first-hit query per ray gives the instance (which object is nearest) and its depth, so
inter-object occlusion comes for free. embreex is called directly (as the LiDAR simulator's
``sot_apps.lidar_sim.raycast`` does) because the flow needs only geometry id and ray parameter for
non-unit camera rays ``(x, y, 1)`` -- skipping normals and re-normalisation halves the cost per pixel.
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
        self._scene = rtcore_scene.EmbreeScene()
        self._geometries = [TriangleMesh(self._scene, np.ascontiguousarray(m.vertices, dtype=np.float32),
                                         np.ascontiguousarray(m.faces, dtype=np.int32)) for m in meshes]
        self.count = len(meshes)

    def first_hit(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For (N, 3) rays (any length): (object index or -1, ray parameter t in units of the given
        direction, inf on a miss). With directions (x, y, 1) in a camera frame, t is the depth z."""
        directions = np.ascontiguousarray(directions, dtype=np.float32).reshape(-1, 3)
        n = len(directions)
        if n == 0 or self.count == 0:
            return np.full(n, -1, dtype=np.int32), np.full(n, np.inf)
        origins = np.ascontiguousarray(np.broadcast_to(np.asarray(origins, dtype=np.float32), (n, 3)))
        out = self._scene.run(origins, directions, output=1)
        geom = np.asarray(out["geomID"], dtype=np.int32)
        t = np.where(geom >= 0, np.asarray(out["tfar"], dtype=np.float64), np.inf)
        return geom, t
