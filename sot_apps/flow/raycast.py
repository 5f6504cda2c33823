"""All objects' meshes in one Embree scene; geometry id i = object i.

A single first-hit query per ray gives the instance (which object is nearest) and its depth, so
inter-object occlusion comes for free. It uses the LiDAR simulator's ``RaycastScene`` (the compiled
Embree loop, or embreex when that is not built). Camera rays are ``(x, y, 1)``, not unit vectors, so the
returned ray parameter is the depth z.
"""

from __future__ import annotations

import numpy as np

from ..objects.meshes import Mesh
from ..raycast import RaycastScene

__all__ = ["MultiMeshScene"]


class MultiMeshScene:
    """Meshes already placed in the ray frame (e.g. camera k); ``meshes[i]`` gets geometry id i."""

    def __init__(self, meshes: list[Mesh]) -> None:
        self._scene = RaycastScene()
        for m in meshes:
            self._scene.add_mesh(m.vertices, m.faces)
        self.count = len(meshes)

    def first_hit(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For (N, 3) rays (any length): (object index or -1, ray parameter t in units of the given
        direction, inf on a miss). With directions (x, y, 1) in a camera frame, t is the depth z."""
        directions = np.asarray(directions)   # float64 stays float64: the tracer rounds each ray to float32 itself
        directions = np.ascontiguousarray(directions, dtype=np.float64 if directions.dtype == np.float64
                                          else np.float32).reshape(-1, 3)
        n = len(directions)
        if n == 0 or self.count == 0:
            return np.full(n, -1, dtype=np.int32), np.full(n, np.inf)
        hits = self._scene.cast(origins, directions)
        return hits.geom_id, hits.distance
