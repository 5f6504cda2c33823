"""PLY files: point clouds with numpy only (binary little-endian), meshes through trimesh.

``write_ply_points(path, xyz, intensity=..., nx=..., ...)`` writes float32 x, y, z plus optional
per-point scalar properties (float32, or uint8/int32/... as given). ``read_ply(path)`` reads the
``vertex`` element of any PLY (binary little/big endian or ascii) into a dict of arrays;
``read_ply_points(path)`` returns (N, 3) float64 xyz.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..interrupts import import_trimesh
from .atomic import atomic_path, write_bytes

__all__ = ["write_ply_points", "read_ply", "read_ply_points", "write_ply_mesh", "read_ply_mesh"]

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_NUMPY_TO_PLY = {"i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort", "i4": "int", "u4": "uint",
                 "f4": "float", "f8": "double"}


def write_ply_points(path: str | Path, xyz: np.ndarray, **properties: np.ndarray) -> None:
    """Write points (x, y, z as float32) and optional per-point scalar properties, atomically.

    Float properties are stored as float32; integer/bool ones keep their type (bool -> uchar).
    """
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    if not np.isfinite(xyz).all():
        raise ValueError(f"{path}: refusing to write non-finite point coordinates")
    n = len(xyz)
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    columns: dict[str, np.ndarray] = {"x": xyz[:, 0], "y": xyz[:, 1], "z": xyz[:, 2]}
    for name, values in properties.items():
        values = np.asarray(values).reshape(-1)
        if values.shape != (n,):
            raise ValueError(f"property {name!r} has {values.size} values for {n} points")
        if values.dtype == bool:
            values = values.astype(np.uint8)
        kind = "<f4" if values.dtype.kind == "f" else "<" + values.dtype.str[1:]
        if kind[1:] not in _NUMPY_TO_PLY:
            raise ValueError(f"property {name!r}: unsupported dtype {values.dtype}")
        fields.append((name, kind))
        columns[name] = values
    table = np.empty(n, dtype=np.dtype(fields))
    for name, values in columns.items():
        table[name] = values
    header = ["ply", "format binary_little_endian 1.0", "comment written by sot-apps", f"element vertex {n}"]
    header += [f"property {_NUMPY_TO_PLY[kind[1:]]} {name}" for name, kind in fields]
    header.append("end_header")
    write_bytes(path, ("\n".join(header) + "\n").encode("ascii") + table.tobytes())


def _parse_header(path: Path, data: bytes) -> tuple[str, int, list[tuple[str, str]], int]:
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise InputError(path, "not a PLY file (no 'ply' magic or 'end_header')")
    newline = data.find(b"\n", end)
    body_start = newline + 1 if newline >= 0 else len(data)
    lines = data[:end].decode("ascii", errors="replace").splitlines()
    fmt = ""
    count = None
    props: list[tuple[str, str]] = []
    element = None
    seen_before_vertex = False
    for line in lines:
        words = line.split()
        if not words:
            continue
        if words[0] == "format":
            fmt = words[1]
        elif words[0] == "element":
            element = words[1]
            if element == "vertex":
                count = int(words[2])
            elif count is None:
                seen_before_vertex = True
        elif words[0] == "property" and element == "vertex":
            if words[1] == "list":
                raise InputError(path, "list properties on vertices are not supported")
            if words[1] not in _PLY_TYPES:
                raise InputError(path, f"unknown PLY property type {words[1]!r}")
            props.append((words[2], _PLY_TYPES[words[1]]))
    if count is None:
        raise InputError(path, "PLY has no 'vertex' element")
    if seen_before_vertex:
        raise InputError(path, "the 'vertex' element must come first")
    if fmt not in ("binary_little_endian", "binary_big_endian", "ascii"):
        raise InputError(path, f"unsupported PLY format {fmt!r}")
    return fmt, count, props, body_start


def read_ply(path: str | Path) -> dict[str, np.ndarray]:
    """All vertex properties of a PLY file as arrays (InputError naming the file if malformed)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "PLY file is missing")
    data = path.read_bytes()
    fmt, count, props, start = _parse_header(path, data)
    if fmt == "ascii":
        text = data[start:].decode("ascii", errors="replace").splitlines()
        if len(text) < count:
            raise InputError(path, f"PLY is truncated: {len(text)} of {count} vertex lines")
        try:
            rows = np.array([line.split()[: len(props)] for line in text[:count]], dtype=np.float64).reshape(count, len(props))
        except ValueError as exc:
            raise InputError(path, f"malformed ascii PLY vertex data ({exc})") from exc
        return {name: rows[:, i].astype(kind) for i, (name, kind) in enumerate(props)}
    order = "<" if fmt == "binary_little_endian" else ">"
    dtype = np.dtype([(name, order + kind) for name, kind in props])
    need = dtype.itemsize * count
    if len(data) - start < need:
        raise InputError(path, f"PLY is truncated: {len(data) - start} bytes of vertex data, expected {need}")
    table = np.frombuffer(data, dtype=dtype, count=count, offset=start)
    return {name: table[name].astype(table[name].dtype.newbyteorder("=")) for name, _ in props}


def read_ply_points(path: str | Path) -> np.ndarray:
    """(N, 3) float64 x, y, z of a PLY file; non-finite coordinates are an InputError."""
    props = read_ply(path)
    missing = [c for c in "xyz" if c not in props]
    if missing:
        raise InputError(path, f"PLY vertices lack properties {missing}")
    xyz = np.stack([props["x"], props["y"], props["z"]], axis=1).astype(np.float64)
    if not np.isfinite(xyz).all():
        raise InputError(path, "PLY has non-finite vertex coordinates")
    return xyz


def write_ply_mesh(path: str | Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    """Write a triangle mesh as binary PLY (via trimesh), atomically."""
    trimesh = import_trimesh()

    mesh = trimesh.Trimesh(vertices=np.asarray(vertices, dtype=np.float64), faces=np.asarray(faces, dtype=np.int64),
                           process=False)
    with atomic_path(path) as tmp:
        tmp.write_bytes(mesh.export(file_type="ply"))


def read_ply_mesh(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V,3) float64, faces (F,3) int64) of a PLY mesh (via trimesh)."""
    trimesh = import_trimesh()

    path = Path(path)
    if not path.is_file():
        raise InputError(path, "PLY file is missing")
    try:
        mesh = trimesh.load(path, file_type="ply", process=False, force="mesh")
    except Exception as exc:  # noqa: BLE001 - trimesh raises many types on bad files
        raise InputError(path, f"cannot read PLY mesh ({type(exc).__name__}: {exc})") from exc
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
