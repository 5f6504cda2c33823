"""The ray-casting engine (Embree) as a service for every app: meshes in, first hits out.

``RaycastScene`` is the one entry point (flow and lidar_sim both use it); see :mod:`sot_apps.raycast.scene`.
"""

from .scene import BACKENDS, MISS, RaycastScene, RayHits, cast_rays, compiled_backend_available

__all__ = ["RayHits", "RaycastScene", "cast_rays", "MISS", "compiled_backend_available", "BACKENDS"]
