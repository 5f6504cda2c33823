"""Ray casting with Embree.

Every object is its own triangle mesh in one Embree scene, so the geometry id of a hit is the object's
index in the order the meshes were added (:meth:`RaycastScene.add_mesh`).

Two backends, one file each, trace the same scene and return the same hits (:class:`RaycastScene` picks one
and never branches on it again):

- ``compiled`` (:mod:`.compiled`, the default when available): a small C loop (``_embree_trace.c``, built by ``pip install``)
  over the Embree 4 library bundled in the embreex wheel, called through ctypes with the GIL released.
  It traces 16-ray coherent packets (``rtcIntersect16``; ``SOT_APPS_RAY_PACKETS=0``: one ray at a time, same
  hits), takes float32 or float64 rays without a converted copy, and writes final outputs directly.
- ``embreex`` (:mod:`.embreex_backend`): ``embreex.rtcore_scene.EmbreeScene.run`` (one ``TriangleMesh`` per object), used when the
  compiled loop is missing (no C compiler at install time) or when ``SOT_APPS_RAYCAST=embreex``.

A mesh that is an axis-aligned horizontal rectangle of two triangles (a ground plane) is intersected
analytically instead of by Embree, with identical results (primitive id 0): each ray's Embree segment ends
at its rectangle hit, so rays to the ground never search the vehicles beyond that point.

Large jobs are split over workers (:func:`cast_rays`): threads with the compiled backend (ctypes releases
the GIL), forked processes with embreex (which holds it).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .compiled import CompiledBackend, _CompiledTracer, compiled_backend_available
from .hits import MISS, RayHits, _horizontal_rectangle

__all__ = ["RayHits", "RaycastScene", "cast_rays", "MISS", "compiled_backend_available", "BACKENDS"]

BACKENDS = ("auto", "compiled", "embreex")


def _resolve_backend(backend: str) -> str:
    if backend not in BACKENDS:
        raise ValueError(f"unknown ray-casting backend {backend!r} (one of {', '.join(BACKENDS)})")
    if backend == "auto":
        backend = os.environ.get("SOT_APPS_RAYCAST", "auto")
        if backend not in BACKENDS:
            raise ValueError(f"SOT_APPS_RAYCAST={backend!r} is not one of {', '.join(BACKENDS)}")
    if backend == "auto":
        return "compiled" if compiled_backend_available() else "embreex"
    if backend == "compiled" and not compiled_backend_available():
        raise RuntimeError(f"the compiled ray tracer is not available: {_CompiledTracer.error}")
    return backend


class RaycastScene:
    """An Embree scene of triangle meshes; ``add_mesh`` returns the object's geometry id.

    ``backend``: ``auto`` (compiled when available, else embreex; ``SOT_APPS_RAYCAST`` overrides),
    ``compiled`` or ``embreex``.
    """

    def __init__(self, backend: str = "auto") -> None:
        self.backend = _resolve_backend(backend)
        self.vertices: list[np.ndarray] = []
        self.faces: list[np.ndarray] = []
        self.rectangle_ids: list[int] = []   # meshes intersected analytically (horizontal rectangles)
        self._dirty = True
        if self.backend == "compiled":
            self._engine = CompiledBackend()
        else:
            from .embreex_backend import EmbreexBackend

            self._engine = EmbreexBackend()

    def __len__(self) -> int:
        return len(self.faces)

    def add_mesh(self, vertices: np.ndarray, faces: np.ndarray) -> int:
        """Add one object's mesh ((V, 3) vertices, (F, 3) int faces); returns its geometry id."""
        vertices = np.ascontiguousarray(vertices, dtype=np.float32).reshape(-1, 3)
        faces = np.ascontiguousarray(faces, dtype=np.int32).reshape(-1, 3)
        if len(faces) == 0:
            raise ValueError("a mesh needs at least one triangle")
        if faces.min() < 0 or faces.max() >= len(vertices):
            raise ValueError("a face refers to a vertex that does not exist")
        geom_id = len(self.faces)
        rect = _horizontal_rectangle(vertices.astype(np.float64), faces)
        if rect is not None:
            self._engine.add_rect(geom_id, rect)
            self.rectangle_ids.append(geom_id)
        else:
            self._engine.add_mesh(geom_id, vertices, faces)
        self.vertices.append(vertices)
        self.faces.append(faces)
        self._dirty = True
        return geom_id

    @property
    def num_triangles(self) -> int:
        return int(sum(len(f) for f in self.faces))

    def commit(self) -> None:
        """Build the acceleration structure now (``cast`` does it on demand)."""
        if self._dirty:
            self._engine.commit()
        self._dirty = False

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> RayHits:
        """Trace rays ``directions`` (N, 3) (unit for metric distances) from ``origins`` ((3,) or (N, 3));
        the first hit of each."""
        directions = np.asarray(directions)
        # float64 rays stay float64 (each backend rounds them to Embree's float32; the compiled one ray by ray)
        dtype = np.float64 if directions.dtype == np.float64 else np.float32
        directions = np.ascontiguousarray(directions, dtype=dtype).reshape(-1, 3)
        n = directions.shape[0]
        origins = np.asarray(origins)
        if origins.ndim == 2 and len(origins) > 1 and origins.strides[0] == 0:
            origins = origins[0]                     # one origin broadcast to every ray: keep it single
        origins = origins.astype(dtype, copy=False)
        if n == 0 or not self.faces:
            return RayHits(np.full(n, np.inf), np.zeros((n, 3), np.float32), np.full(n, MISS, np.int32),
                           np.full(n, MISS, np.int32))
        self.commit()
        return self._engine.cast(origins, directions)


_WORKER_SCENE: RaycastScene | None = None
_WORKER_ARGS: tuple | None = None


def _worker_cast(span: tuple[int, int]) -> RayHits:
    global _WORKER_SCENE
    assert _WORKER_ARGS is not None
    vertices, faces, origins, directions, backend = _WORKER_ARGS
    if _WORKER_SCENE is None:
        _WORKER_SCENE = RaycastScene(backend)
        for v, f in zip(vertices, faces, strict=True):
            _WORKER_SCENE.add_mesh(v, f)
    a, b = span
    o = origins if origins.ndim == 1 else origins[a:b]
    return _WORKER_SCENE.cast(o, directions[a:b])


def cast_rays(scene: RaycastScene, origins: np.ndarray, directions: np.ndarray, processes: int = 1,
              min_rays_per_process: int = 200_000) -> RayHits:
    """Cast rays, splitting them over ``processes`` workers when the job is large enough.

    The compiled backend traces the shared scene from threads; embreex, which holds the GIL, from forked
    processes that rebuild the scene from the inherited triangle arrays.
    """
    n = int(np.shape(directions)[0])
    processes = max(1, min(int(processes), n // max(1, min_rays_per_process), os.cpu_count() or 1))
    if processes <= 1:
        return scene.cast(origins, directions)
    origins = np.asarray(origins, dtype=np.float32)
    directions = np.asarray(directions, dtype=np.float32)
    bounds = np.linspace(0, n, processes + 1).astype(int)
    spans = [(int(bounds[i]), int(bounds[i + 1])) for i in range(processes)]
    if scene.backend == "compiled":
        scene.commit()
        with ThreadPoolExecutor(processes) as pool:
            parts = list(pool.map(lambda s: scene.cast(origins if origins.ndim == 1 else origins[s[0]:s[1]],
                                                       directions[s[0]:s[1]]), spans))
        return RayHits.concatenate(parts)
    import multiprocessing as mp  # only here (~20 ms of start-up for every caster that never forks)

    if "fork" not in mp.get_all_start_methods():
        return scene.cast(origins, directions)
    global _WORKER_ARGS, _WORKER_SCENE
    _WORKER_ARGS = (scene.vertices, scene.faces, origins, directions, scene.backend)
    _WORKER_SCENE = None
    try:
        with mp.get_context("fork").Pool(processes) as pool:
            parts = pool.map(_worker_cast, spans)
    finally:
        _WORKER_ARGS = None
    return RayHits.concatenate(parts)
