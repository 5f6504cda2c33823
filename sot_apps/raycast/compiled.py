"""The ``compiled`` backend: a small C loop (``_embree_trace.c``, built by ``pip install``) over the Embree 4
library bundled in the embreex wheel, called through ctypes with the GIL released."""

from __future__ import annotations

import ctypes
import glob
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .hits import RayHits

__all__ = ["CompiledBackend", "compiled_backend_available", "SweepReturns", "compiled_sweep_returns"]


class _CompiledTracer:
    """ctypes binding of _embree_trace.c (loaded once per process)."""

    lib: ctypes.CDLL | None = None
    error: str | None = None

    @classmethod
    def load(cls) -> ctypes.CDLL | None:
        if cls.lib is not None or cls.error is not None:
            return cls.lib
        try:
            cls.lib = cls._load()
        except OSError as exc:
            cls.error = str(exc)
        return cls.lib

    @staticmethod
    def _load() -> ctypes.CDLL:
        here = Path(__file__).resolve().parent
        built = sorted(glob.glob(str(here / "_embree_trace*.so")))
        if not built:
            raise OSError("the compiled ray tracer was not built (pip install needs a C compiler)")
        embree = _embree_library_path()
        lib = ctypes.CDLL(built[0])
        lib.sot_rt_error.restype = ctypes.c_char_p
        lib.sot_rt_load.argtypes = [ctypes.c_char_p]
        lib.sot_rt_scene_new.restype = ctypes.c_void_p
        lib.sot_rt_scene_new.argtypes = [ctypes.c_char_p]
        lib.sot_rt_scene_add_mesh.argtypes = [ctypes.c_void_p, ctypes.c_uint, ctypes.c_void_p, ctypes.c_long,
                                              ctypes.c_void_p, ctypes.c_long]
        lib.sot_rt_scene_add_rect.argtypes = [ctypes.c_void_p, ctypes.c_uint] + [ctypes.c_double] * 5
        lib.sot_rt_scene_commit.argtypes = [ctypes.c_void_p]
        lib.sot_rt_scene_free.argtypes = [ctypes.c_void_p]
        c_double_p, c_long = ctypes.c_void_p, ctypes.c_long
        if hasattr(lib, "sot_rt_returns"):   # absent from a library built before it existed (rebuild: pip install)
            lib.sot_rt_returns.restype = c_long
            lib.sot_rt_returns.argtypes = [c_long, c_double_p, c_double_p, c_double_p, c_double_p, ctypes.c_int,
                                           c_double_p, c_double_p, c_long, ctypes.c_double, ctypes.c_double, c_double_p,
                                           c_double_p, ctypes.c_double, c_double_p, ctypes.c_double, c_double_p,
                                           ctypes.c_double, ctypes.c_double, ctypes.c_int, ctypes.c_double, c_double_p,
                                           c_double_p, c_double_p, c_double_p, c_double_p]
        lib.sot_rt_cast.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p, ctypes.c_long,
                                    ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
        if hasattr(lib, "sot_rt_cast8"):   # absent from a library built before it existed (rebuild: pip install)
            lib.sot_rt_cast8.argtypes = lib.sot_rt_cast.argtypes
            lib.sot_rt_has_packets.restype = ctypes.c_int
        if lib.sot_rt_load(str(embree).encode()) != 0:
            raise OSError(lib.sot_rt_error().decode(errors="replace"))
        return lib


def _embree_library_path() -> Path:
    """The Embree 4 shared library that the embreex wheel bundles (loaded by importing embreex)."""
    import embreex
    from embreex import rtcore_scene  # noqa: F401 - maps the library into this process

    site = Path(embreex.__file__).resolve().parent.parent
    found = sorted(glob.glob(str(site / "embreex.libs" / "libembree4*")))
    if found:
        return Path(found[0])
    try:
        with open("/proc/self/maps", encoding="utf-8") as maps:
            for line in maps:
                if "libembree4" in line:
                    return Path(line.split()[-1])
    except OSError:
        pass
    raise OSError("embreex's Embree 4 library was not found")


def _packets(lib: ctypes.CDLL) -> bool:
    """Trace with 8-ray packets (``sot_rt_cast8``) when the library has them; ``SOT_APPS_RAY_PACKETS=0`` turns
    them off (tests compare both paths)."""
    import os

    return (os.environ.get("SOT_APPS_RAY_PACKETS", "1") != "0" and hasattr(lib, "sot_rt_cast8")
            and bool(lib.sot_rt_has_packets()))


def compiled_backend_available() -> bool:
    """True when the compiled tracer was built and loads against embreex's Embree."""
    return _CompiledTracer.load() is not None


class CompiledBackend:
    """One Embree scene in the compiled tracer (rectangles are intersected analytically in C)."""

    def __init__(self) -> None:
        self._lib = _CompiledTracer.load()
        self._handle = self._lib.sot_rt_scene_new(None)
        if not self._handle:
            raise RuntimeError(f"Embree scene creation failed: {self._error()}")

    def _error(self) -> str:
        return self._lib.sot_rt_error().decode(errors="replace")

    def __del__(self) -> None:
        handle = getattr(self, "_handle", None)
        if handle:
            self._lib.sot_rt_scene_free(handle)
            self._handle = None

    def add_rect(self, geom_id: int, rect: tuple[float, float, float, float, float]) -> None:
        self._lib.sot_rt_scene_add_rect(self._handle, geom_id, *rect)

    def add_mesh(self, geom_id: int, vertices: np.ndarray, faces: np.ndarray) -> None:
        if self._lib.sot_rt_scene_add_mesh(self._handle, geom_id, vertices.ctypes.data, len(vertices),
                                           faces.ctypes.data, len(faces)) != 0:
            raise RuntimeError(f"Embree rejected mesh {geom_id}: {self._error()}")

    def commit(self) -> None:
        if self._lib.sot_rt_scene_commit(self._handle) != 0:
            raise RuntimeError(f"Embree scene build failed: {self._error()}")

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> RayHits:
        n = directions.shape[0]
        single = origins.ndim == 1 or origins.shape[0] == 1 or origins.strides[0] == 0  # one shared origin
        origins = np.ascontiguousarray(origins.reshape(-1, 3)[:1] if single else origins, dtype=np.float32)
        distance = np.empty(n, np.float64)
        normal = np.empty((n, 3), np.float32)
        prim = np.empty(n, np.int32)
        geom = np.empty(n, np.int32)
        cast = self._lib.sot_rt_cast8 if _packets(self._lib) else self._lib.sot_rt_cast
        err = cast(self._handle, origins.ctypes.data, 0 if single else 1, directions.ctypes.data, n,
                                    distance.ctypes.data, normal.ctypes.data, prim.ctypes.data, geom.ctypes.data)
        if err != 0:
            raise RuntimeError(f"Embree ray casting failed: {self._error()}")
        return RayHits(distance, normal, prim, geom)


@dataclass(frozen=True)
class SweepReturns:
    """The kept returns of a sweep, in ray order: ray index, measured range, intensity, point (float32)."""

    keep: np.ndarray        # (K,) int64
    measured: np.ndarray    # (K,) float64
    intensity: np.ndarray   # (K,) float32
    xyz: np.ndarray         # (K, 3) float32


def _pointer(array: np.ndarray | None, dtype) -> int | None:
    if array is None:
        return None
    assert array.dtype == dtype and array.flags.c_contiguous
    return array.ctypes.data


def compiled_sweep_returns(distance: np.ndarray, normal: np.ndarray, dirs: np.ndarray, origins: np.ndarray,
                           object_index: np.ndarray, reflectivity: np.ndarray, min_range: float, max_range: float,
                           noise: np.ndarray | None, u_random: np.ndarray | None, drop_random: float,
                           u_grazing: np.ndarray | None, grazing_start_deg: float, u_range: np.ndarray | None,
                           range_a: float, range_b: float, with_intensity: bool, attenuation: float,
                           target_from_world: np.ndarray) -> SweepReturns | None:
    """The per-return models of :func:`sot_apps.sensor.scan.simulate_scan` in the compiled loop (``sot_rt_returns``
    in _embree_trace.c: same formulas, same random draws, one pass); None when the loop is not built."""
    lib = _CompiledTracer.load()
    if lib is None or not hasattr(lib, "sot_rt_returns"):
        return None
    n = len(distance)
    single = origins.ndim == 1 or origins.shape[0] == 1 or origins.strides[0] == 0
    origins = np.ascontiguousarray(origins.reshape(-1, 3)[:1] if single else origins, dtype=np.float64)
    arrays = {"distance": np.ascontiguousarray(distance, dtype=np.float64),
              "normal": np.ascontiguousarray(normal, dtype=np.float32),
              "dirs": np.ascontiguousarray(dirs, dtype=np.float64),
              "object_index": np.ascontiguousarray(object_index, dtype=np.int32),
              "reflectivity": np.ascontiguousarray(reflectivity, dtype=np.float64),
              "matrix": np.ascontiguousarray(np.asarray(target_from_world, dtype=np.float64)[:3, :4])}
    draws = [None if u is None else np.ascontiguousarray(u, dtype=np.float64) for u in (noise, u_random, u_grazing, u_range)]
    keep = np.empty(n, np.int64)
    measured = np.empty(n, np.float64)
    intensity = np.empty(n, np.float32)
    xyz = np.empty((n, 3), np.float32)
    count = lib.sot_rt_returns(
        n, arrays["distance"].ctypes.data, arrays["normal"].ctypes.data, arrays["dirs"].ctypes.data,
        origins.ctypes.data, 0 if single else 1, arrays["object_index"].ctypes.data, arrays["reflectivity"].ctypes.data,
        len(arrays["reflectivity"]), float(min_range), float(max_range), _pointer(draws[0], np.float64),
        _pointer(draws[1], np.float64), float(drop_random), _pointer(draws[2], np.float64), float(grazing_start_deg),
        _pointer(draws[3], np.float64), float(range_a), float(range_b), int(bool(with_intensity)), float(attenuation),
        arrays["matrix"].ctypes.data, keep.ctypes.data, measured.ctypes.data, intensity.ctypes.data, xyz.ctypes.data)
    return SweepReturns(keep[:count], measured[:count], intensity[:count], xyz[:count])
