"""The ``compiled`` backend: a small C loop (``_embree_trace.c``, built by ``pip install``) over the Embree 4
library bundled in the embreex wheel, called through ctypes with the GIL released."""

from __future__ import annotations

import ctypes
import glob
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .hits import RayHits

__all__ = ["CompiledBackend", "compiled_backend_available", "SweepReturns", "ReturnModels", "compiled_sweep_returns",
           "compiled_draws"]


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
        if not hasattr(lib, "sot_rt_version") or lib.sot_rt_version() != _INTERFACE_VERSION:
            raise OSError(f"{built[0]} was built from an older _embree_trace.c (rebuild it: pip install, or "
                          "python setup.py build_ext --inplace)")
        ptr, c_long = ctypes.c_void_p, ctypes.c_long
        lib.sot_rt_error.restype = ctypes.c_char_p
        lib.sot_rt_load.argtypes = [ctypes.c_char_p]
        lib.sot_rt_scene_new.restype = ptr
        lib.sot_rt_scene_new.argtypes = [ctypes.c_char_p]
        lib.sot_rt_scene_add_mesh.argtypes = [ptr, ctypes.c_uint, ptr, c_long, ptr, c_long]
        lib.sot_rt_scene_add_rect.argtypes = [ptr, ctypes.c_uint] + [ctypes.c_double] * 5
        lib.sot_rt_scene_commit.argtypes = [ptr]
        lib.sot_rt_scene_free.argtypes = [ptr]
        lib.sot_rt_cast.argtypes = [ptr, ptr, ctypes.c_int, ptr, ctypes.c_int, c_long, ptr, ptr, ptr, ptr]
        lib.sot_rt_cast16.argtypes = lib.sot_rt_cast.argtypes
        lib.sot_rt_has_packets.restype = ctypes.c_int
        lib.sot_rt_draws.argtypes = [ctypes.c_uint64, ctypes.c_int, ctypes.c_int, c_long, ptr]
        lib.sot_rt_returns.restype = c_long
        lib.sot_rt_returns.argtypes = [c_long, ptr, ptr, ptr, ptr, ctypes.c_int, ptr, ptr, c_long, ptr, ptr, c_long,
                                       ctypes.POINTER(_Models), ptr, c_long, ptr] + [ptr] * 9
        if lib.sot_rt_load(str(embree).encode()) != 0:
            raise OSError(lib.sot_rt_error().decode(errors="replace"))
        return lib


_INTERFACE_VERSION = 3   # sot_rt_version() of _embree_trace.c


class _Models(ctypes.Structure):
    """The ``Models`` struct of _embree_trace.c."""

    _fields_ = [("min_range", ctypes.c_double), ("max_range", ctypes.c_double), ("seed", ctypes.c_uint64),
                ("noise_sigma", ctypes.c_double), ("drop_random", ctypes.c_double), ("drop_grazing", ctypes.c_int),
                ("grazing_start_deg", ctypes.c_double), ("drop_range", ctypes.c_int), ("range_a", ctypes.c_double),
                ("range_b", ctypes.c_double), ("intensity", ctypes.c_int), ("attenuation", ctypes.c_double)]


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
    """Trace with 16-ray packets (``sot_rt_cast16``) when Embree has them; ``SOT_APPS_RAY_PACKETS=0`` turns them
    off (tests compare both paths)."""
    import os

    return os.environ.get("SOT_APPS_RAY_PACKETS", "1") != "0" and bool(lib.sot_rt_has_packets())


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
        """Directions and origins float32, or float64 (rounded to float32 ray by ray in C: no converted copy)."""
        dtype = np.float64 if directions.dtype == np.float64 else np.float32
        directions = np.ascontiguousarray(directions, dtype=dtype)
        n = directions.shape[0]
        single = origins.ndim == 1 or origins.shape[0] == 1 or origins.strides[0] == 0  # one shared origin
        origins = np.ascontiguousarray(origins.reshape(-1, 3)[:1] if single else origins, dtype=dtype)
        distance = np.empty(n, np.float64)
        normal = np.empty((n, 3), np.float32)
        prim = np.empty(n, np.int32)
        geom = np.empty(n, np.int32)
        cast = self._lib.sot_rt_cast16 if _packets(self._lib) else self._lib.sot_rt_cast
        err = cast(self._handle, origins.ctypes.data, 0 if single else 1, directions.ctypes.data,
                   int(dtype == np.float64), n, distance.ctypes.data, normal.ctypes.data, prim.ctypes.data,
                   geom.ctypes.data)
        if err != 0:
            raise RuntimeError(f"Embree ray casting failed: {self._error()}")
        return RayHits(distance, normal, prim, geom)


@dataclass(frozen=True)
class SweepReturns:
    """The kept returns of a sweep, in ray order (the per-return arrays of a ``Scan``)."""

    keep: np.ndarray             # (K,) int64 ray index
    xyz: np.ndarray              # (K, 3) float32 point
    distance: np.ndarray         # (K,) float32 measured range
    intensity: np.ndarray        # (K,) float32
    beam: np.ndarray             # (K,) int32
    column: np.ndarray           # (K,) int32
    time_offset_ns: np.ndarray   # (K,) int64 firing time of the column
    object_index: np.ndarray     # (K,) int32
    instance: np.ndarray         # (K,) int32

    def __len__(self) -> int:
        return int(self.keep.shape[0])


@dataclass(frozen=True)
class ReturnModels:
    """What :func:`compiled_sweep_returns` applies (formulas in :mod:`sot_apps.sensor.noise`): returns with a finite
    distance in [min_range, max_range]; range noise ``noise_sigma`` (0: off); a random drop ``drop_random`` (0: off);
    the grazing drop (``drop_grazing``, from ``grazing_start_deg``); the range drop ``clip(range_a + range_b * r, 0,
    1)`` (``drop_range``); Lambertian intensity with ``attenuation`` per metre (``intensity``); draws from ``seed``."""

    min_range: float
    max_range: float
    seed: int = 0
    noise_sigma: float = 0.0
    drop_random: float = 0.0
    drop_grazing: bool = False
    grazing_start_deg: float = 75.0
    drop_range: bool = False
    range_a: float = 0.0
    range_b: float = 0.0
    intensity: bool = False
    attenuation: float = 0.0


def compiled_draws(seed: int, stream: int, n: int, normal: bool = False) -> np.ndarray | None:
    """The compiled loop's random draws of rays 0..n-1 in ``stream`` (uniforms, or standard normals); None when the
    loop is not built. :func:`sot_apps.sensor.noise.ray_draws` is the numpy twin."""
    lib = _CompiledTracer.load()
    if lib is None:
        return None
    out = np.empty(int(n), np.float64)
    lib.sot_rt_draws(int(seed) % 2**64, int(stream), int(bool(normal)), int(n), out.ctypes.data)
    return out


def compiled_sweep_returns(distance: np.ndarray, normal: np.ndarray, dirs: np.ndarray, origins: np.ndarray,
                           object_index: np.ndarray, reflectivity: np.ndarray, instance: np.ndarray,
                           models: ReturnModels, target_from_world: np.ndarray, columns: int,
                           column_time_ns: np.ndarray, object_of: np.ndarray | None = None) -> SweepReturns | None:
    """The per-return models of :func:`sot_apps.sensor.scan.simulate_scan` in the compiled loop (``sot_rt_returns``
    in _embree_trace.c: one pass over the rays, each ray's random numbers drawn there when it needs them, every
    per-return output written); None when the loop is not built. Ray ``i`` is beam ``i // columns``, column
    ``i % columns``; ``reflectivity`` and ``instance`` are per object (``object_index`` -1: none). With
    ``object_of``, ``object_index`` holds geometry ids and ray i's object is ``object_of[object_index[i]]`` (-1 for
    -1): the mapping is applied in the loop instead of a gather over every ray."""
    lib = _CompiledTracer.load()
    if lib is None:
        return None
    n = len(distance)
    single = origins.ndim == 1 or origins.shape[0] == 1 or origins.strides[0] == 0
    origins = np.ascontiguousarray(origins.reshape(-1, 3)[:1] if single else origins, dtype=np.float64)
    inputs = [np.ascontiguousarray(distance, dtype=np.float64), np.ascontiguousarray(normal, dtype=np.float32),
              np.ascontiguousarray(dirs, dtype=np.float64), origins, np.ascontiguousarray(object_index, dtype=np.int32),
              np.ascontiguousarray(reflectivity, dtype=np.float64), np.ascontiguousarray(instance, dtype=np.int32)]
    if len(inputs[5]) != len(inputs[6]):
        raise ValueError("reflectivity and instance need one entry per object")
    mapping = None if object_of is None else np.ascontiguousarray(object_of, dtype=np.int32)
    matrix = np.ascontiguousarray(np.asarray(target_from_world, dtype=np.float64)[:3, :4])
    times = np.ascontiguousarray(column_time_ns, dtype=np.int64)
    if len(times) != columns:
        raise ValueError("column_time_ns needs one entry per column")
    m = models
    c_models = _Models(float(m.min_range), float(m.max_range), int(m.seed) % 2**64, float(m.noise_sigma),
                       float(m.drop_random), int(bool(m.drop_grazing)), float(m.grazing_start_deg),
                       int(bool(m.drop_range)), float(m.range_a), float(m.range_b), int(bool(m.intensity)),
                       float(m.attenuation))
    out = SweepReturns(np.empty(n, np.int64), np.empty((n, 3), np.float32), np.empty(n, np.float32),
                       np.empty(n, np.float32), np.empty(n, np.int32), np.empty(n, np.int32), np.empty(n, np.int64),
                       np.empty(n, np.int32), np.empty(n, np.int32))
    arrays = [out.keep, out.xyz, out.distance, out.intensity, out.beam, out.column, out.time_offset_ns,
              out.object_index, out.instance]
    count = lib.sot_rt_returns(n, *(a.ctypes.data for a in inputs[:4]), 0 if single else 1, inputs[4].ctypes.data,
                               None if mapping is None else mapping.ctypes.data, 0 if mapping is None else len(mapping),
                               inputs[5].ctypes.data, inputs[6].ctypes.data, len(inputs[5]), ctypes.byref(c_models),
                               matrix.ctypes.data, int(columns), times.ctypes.data, *(a.ctypes.data for a in arrays))
    if count < 0:
        raise MemoryError("the compiled per-return pass could not allocate its scratch arrays")
    return SweepReturns(*(a[:count] for a in arrays))
