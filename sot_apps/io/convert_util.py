"""Small conversions shared by the dataset readers (quaternions, boxes from poses, pose lookup, files)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from tracker.geometry import Box, interpolate_pose, make_transform, zyx_angles

from ..errors import InputError, not_a_file

__all__ = ["rotation_matrices_xyzw", "quaternion_wxyz_to_matrix", "quaternions_wxyz_to_matrices", "transform_from_quaternion", "box_from_transform", "pose_at",
           "split_selector", "read_text_lines", "read_float32_records"]


def rotation_matrices_xyzw(xyzw: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions (x, y, z, w) of any non-zero norm -> (N, 3, 3) rotation matrices: each normalised, then the
    usual products. The same arithmetic as scipy's ``Rotation.from_quat(q).as_matrix()``, bit for bit (tested), so
    the readers need no scipy.spatial (its import, with scipy.sparse and scipy.linalg, was ~0.3-0.45 s of CPU of the
    pipeline's planning process, which needs nothing else from it)."""
    q = np.asarray(xyzw, dtype=np.float64).reshape(-1, 4)
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    norm = np.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    matrices = np.empty((len(q), 3, 3))
    matrices[:, 0, 0] = x2 - y2 - z2 + w2
    matrices[:, 1, 0] = 2 * (xy + zw)
    matrices[:, 2, 0] = 2 * (xz - yw)
    matrices[:, 0, 1] = 2 * (xy - zw)
    matrices[:, 1, 1] = -x2 + y2 - z2 + w2
    matrices[:, 2, 1] = 2 * (yz + xw)
    matrices[:, 0, 2] = 2 * (xz + yw)
    matrices[:, 1, 2] = 2 * (yz - xw)
    matrices[:, 2, 2] = -x2 - y2 + z2 + w2
    return matrices


def quaternion_wxyz_to_matrix(w: float, x: float, y: float, z: float, path: Path, where: str) -> np.ndarray:
    """3x3 rotation of a (w, x, y, z) quaternion; InputError unless finite with a norm near 1."""
    q = np.array([x, y, z, w], dtype=np.float64)
    norm = float(np.linalg.norm(q))
    if not np.isfinite(q).all() or not 0.5 < norm < 2.0:
        raise InputError(path, f"{where}: quaternion {q.tolist()} is not a rotation (norm {norm:.3g})")
    return rotation_matrices_xyzw(q / norm)[0]


def quaternions_wxyz_to_matrices(wxyz: np.ndarray, path: Path, what: str) -> np.ndarray:
    """(N, 4) (w, x, y, z) quaternions -> (N, 3, 3) rotations; InputError naming the first bad row."""
    q = np.asarray(wxyz, dtype=np.float64).reshape(-1, 4)[:, [1, 2, 3, 0]]
    norm = np.linalg.norm(q, axis=1)
    bad = ~(np.isfinite(q).all(axis=1) & (norm > 0.5) & (norm < 2.0))
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(path, f"{what} {i}: quaternion {q[i].tolist()} is not a rotation")
    if len(q) == 0:
        return np.zeros((0, 3, 3))
    return rotation_matrices_xyzw(q / norm[:, None])


def transform_from_quaternion(wxyz, translation, path: Path, where: str) -> np.ndarray:
    """4x4 ``target_from_source`` from a (w, x, y, z) quaternion and a translation."""
    t = np.asarray(translation, dtype=np.float64).reshape(3)
    if not np.isfinite(t).all():
        raise InputError(path, f"{where}: translation is not finite")
    return make_transform(quaternion_wxyz_to_matrix(*[float(v) for v in wxyz], path=path, where=where), t)


def box_from_transform(target_from_object: np.ndarray, length: float, width: float, height: float,
                       path: Path, where: str) -> Box:
    """A box whose object frame (x along the length, z up, origin at the centre) is ``target_from_object``.

    The heading is the yaw of the object's x axis in ``target``; roll and pitch keep the rest of the rotation
    (``Box.rotation()`` reproduces it).
    """
    size = [float(length), float(width), float(height)]
    if not all(math.isfinite(v) and v > 0 for v in size):
        raise InputError(path, f"{where}: box size {size} must be finite and positive")
    heading, pitch, roll = zyx_angles(target_from_object[:3, :3])
    c = target_from_object[:3, 3]
    return Box(float(c[0]), float(c[1]), float(c[2]), heading, *size, roll=roll, pitch=pitch)


def pose_at(times_ns: np.ndarray, poses: np.ndarray, time_ns: int, path: Path, max_gap_ns: int = 200_000_000) -> np.ndarray:
    """The pose at ``time_ns``: the exact row when there is one, else SLERP/linear between the two
    neighbouring rows (at most ``max_gap_ns`` apart); outside the pose times -> InputError."""
    i = int(np.searchsorted(times_ns, time_ns))
    if i < len(times_ns) and int(times_ns[i]) == time_ns:
        return poses[i].copy()
    if i == 0 or i == len(times_ns):
        raise InputError(path, f"no ego pose around time {time_ns} ns (poses cover {int(times_ns[0])}..{int(times_ns[-1])})")
    t0, t1 = int(times_ns[i - 1]), int(times_ns[i])
    if t1 - t0 > max_gap_ns:
        raise InputError(path, f"no ego pose within {max_gap_ns * 1e-6:.0f} ms of time {time_ns} ns")
    return interpolate_pose(times_ns[i - 1:i + 1], poses[i - 1:i + 1], time_ns)


def split_selector(path: str | Path) -> tuple[Path, str | None]:
    """``DIR#NAME`` (a sequence NAME inside a multi-sequence DIR) -> (DIR, NAME); a plain path -> (path, None).

    A path that exists as written is never split.
    """
    text = str(path)
    if "#" in text and not Path(text).exists():
        base, _, name = text.rpartition("#")
        return Path(base), name
    return Path(text), None


def read_text_lines(path: Path) -> list[str]:
    """The file's lines (InputError if it is missing or not text)."""
    if not path.is_file():
        raise not_a_file(path)
    try:
        return path.read_text(encoding="utf-8").splitlines()
    except UnicodeDecodeError as exc:
        raise InputError(path, f"not a text file ({exc})") from exc


def read_float32_records(path: Path, columns: int) -> np.ndarray:
    """(N, columns) float32 of a headerless little-endian float32 point file (KITTI ``.bin``, nuScenes
    ``.pcd.bin``); InputError if it is missing, truncated or has non-finite x, y, z."""
    if not path.is_file():
        raise not_a_file(path, "point file")
    size = path.stat().st_size
    if size % (4 * columns):
        raise InputError(path, f"size {size} bytes is not a multiple of {4 * columns} ({columns} float32 per point): "
                               "file is truncated")
    data = np.fromfile(path, dtype="<f4").reshape(-1, columns)
    bad = ~np.isfinite(data[:, :3]).all(axis=1)
    if bad.any():
        raise InputError(path, f"{int(bad.sum())} points have non-finite coordinates")
    return data
