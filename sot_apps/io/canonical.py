"""The canonical sequence format: ``sequence.json`` + npz point files (+ camera images).

Layout (docs/data-formats.md)::

    DIR/sequence.json            validated against data_schema/sequence.schema.json
    DIR/points/000000.npz        xyz float32 (N,3) EGO frame; optional intensity float32 (N,),
                                 time_offset_ns int64 (N,); a frame without "points" has no sweep
    DIR/cameras/<name>/000000.jpg

Reading validates ``sequence.json`` and checks that every referenced file exists; points are read
lazily (and checked: shapes, dtypes, finite values) when a frame is first used. Writing is atomic
per file and writes ``sequence.json`` last, so a crash never leaves a ``sequence.json`` that names
missing files; rerunning resumes (point files that already hold the right content are kept).
"""

from __future__ import annotations

import contextlib
import os
import shutil
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from tracker.geometry import Box

from ..errors import InputError, not_a_file
from ..schemas import load_json_validated, validate
from .atomic import atomic_path, write_json, write_npz
from .npz import read_npz
from .sequence import BoxAnnotation, Camera, CameraFrame, FrameInfo, Sequence, Sweep

__all__ = ["read_sequence", "write_sequence", "read_points_file", "sequence_to_json", "SCHEMA_VERSION"]

SCHEMA_VERSION = 2  # 2: boxes may carry roll, pitch, num_points (a version-1 file reads as level boxes)
POINT_ARRAYS = {"xyz": np.float32, "intensity": np.float32, "time_offset_ns": np.int64}


# ---------------------------------------------------------------------------------------- reading

def _matrix(value: Any, shape: tuple[int, int]) -> np.ndarray:
    return np.asarray(value, dtype=np.float64).reshape(shape)


def _check_rigid(matrix: np.ndarray, path: Path, where: str) -> np.ndarray:
    rotation = matrix[:3, :3]
    if not np.allclose(matrix[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise InputError(path, f"{where}: last row of a 4x4 transform must be [0, 0, 0, 1]")
    if not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-5) or np.linalg.det(rotation) < 0:
        raise InputError(path, f"{where}: rotation part is not a proper rotation matrix")
    return matrix


def read_points_file(path: str | Path) -> Sweep:
    """Read and check one canonical point file (InputError naming the file on any problem)."""
    path = Path(path)
    if not path.is_file():
        raise not_a_file(path, "point file")
    arrays = read_npz(path)
    unknown = sorted(set(arrays) - set(POINT_ARRAYS))
    if unknown:
        raise InputError(path, f"unknown arrays {unknown}; allowed: {sorted(POINT_ARRAYS)}")
    if "xyz" not in arrays:
        raise InputError(path, "array 'xyz' is missing")
    xyz = arrays["xyz"]
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise InputError(path, f"'xyz' must have shape (N, 3), got {xyz.shape}")
    n = xyz.shape[0]
    for name, dtype in POINT_ARRAYS.items():
        if name in arrays and arrays[name].dtype != dtype:
            raise InputError(path, f"'{name}' must be {np.dtype(dtype).name}, got {arrays[name].dtype}")
        if name != "xyz" and name in arrays and arrays[name].shape != (n,):
            raise InputError(path, f"'{name}' must have shape ({n},), got {arrays[name].shape}")
    bad = ~np.isfinite(xyz).all(axis=1)
    if bad.any():
        raise InputError(path, f"'xyz' has {int(bad.sum())} points with non-finite coordinates (first at row {int(np.argmax(bad))})")
    if "intensity" in arrays and not np.isfinite(arrays["intensity"]).all():
        raise InputError(path, "'intensity' has non-finite values")
    return Sweep(xyz=xyz, intensity=arrays.get("intensity"), time_offset_ns=arrays.get("time_offset_ns"))


def _resolve(root: Path, rel: str, json_path: Path, where: str) -> Path:
    path = root / rel
    if not path.is_file():
        raise not_a_file(path, f"{where}: file {rel!r}", report_as=json_path)
    return path


def read_sequence(root: str | Path) -> Sequence:
    """Open a canonical sequence directory (validated; every referenced file must exist)."""
    root = Path(root)
    json_path = root / "sequence.json"
    doc = load_json_validated(json_path, "sequence")
    frames: list[FrameInfo] = []
    for k, frame in enumerate(doc["frames"]):
        frames.append(FrameInfo(
            index=k, timestamp_ns=int(frame["timestamp_ns"]),
            world_from_ego=_check_rigid(_matrix(frame["world_from_ego"], (4, 4)), json_path, f"frames[{k}].world_from_ego"),
            points_path=_resolve(root, frame["points"], json_path, f"frames[{k}].points") if "points" in frame else None,
            has_sweep="points" in frame))
    stamps = np.array([f.timestamp_ns for f in frames], dtype=np.int64)
    if np.any(np.diff(stamps) <= 0):
        k = int(np.argmax(np.diff(stamps) <= 0)) + 1
        raise InputError(json_path, f"frames[{k}].timestamp_ns: frame timestamps must increase strictly")
    ego_from_lidar = _check_rigid(_matrix(doc["ego_from_lidar"], (4, 4)), json_path, "ego_from_lidar")

    cameras: dict[str, Camera] = {}
    for name, cam in doc.get("cameras", {}).items():
        where = f"cameras.{name}"
        if len(cam["frames"]) > len(frames):
            raise InputError(json_path, f"{where}.frames: {len(cam['frames'])} images but only {len(frames)} lidar frames")
        ego_from_camera = None
        if "ego_from_camera" in cam:
            ego_from_camera = _check_rigid(_matrix(cam["ego_from_camera"], (4, 4)), json_path, f"{where}.ego_from_camera")
        cam_frames = []
        for k, cf in enumerate(cam["frames"]):
            if "world_from_camera" in cf:
                world_from_camera = _check_rigid(_matrix(cf["world_from_camera"], (4, 4)), json_path,
                                                 f"{where}.frames[{k}].world_from_camera")
            else:
                world_from_camera = frames[k].world_from_ego @ ego_from_camera
            cam_frames.append(CameraFrame(timestamp_ns=int(cf["timestamp_ns"]),
                                          image_path=_resolve(root, cf["image"], json_path, f"{where}.frames[{k}].image"),
                                          world_from_camera=world_from_camera))
        cameras[name] = Camera(name=name, K=_matrix(cam["K"], (3, 3)), distortion=np.asarray(cam["distortion"], dtype=np.float64),
                               width=int(cam["width"]), height=int(cam["height"]), frames=cam_frames,
                               ego_from_camera=ego_from_camera)

    annotations = None
    if any("boxes" in f for f in doc["frames"]):
        annotations = [[BoxAnnotation(track_id=b["track_id"], label=b["label"],
                                      box=Box(float(b["x"]), float(b["y"]), float(b["z"]), float(b["heading"]),
                                              float(b["length"]), float(b["width"]), float(b["height"]),
                                              roll=float(b.get("roll", 0.0)), pitch=float(b.get("pitch", 0.0))),
                                      stationary=b.get("stationary"), num_points=b.get("num_points"))
                        for b in f.get("boxes", [])] for f in doc["frames"]]

    paths = [f.points_path for f in frames]

    def load(index: int) -> Sweep:
        return read_points_file(paths[index])

    return Sequence(id=doc["id"], root=root, format="sequence", frames=frames, load_sweep=load,
                    ego_from_lidar=ego_from_lidar, cameras=cameras, annotations=annotations)


# ---------------------------------------------------------------------------------------- writing

def _points_name(k: int) -> str:
    return f"points/{k:06d}.npz"


def _image_name(camera: str, k: int, source: Path) -> str:
    suffix = "".join(source.suffixes[-1:]).lower() or ".jpg"
    return f"cameras/{camera}/{k:06d}{suffix}"


def _box_json(ann: BoxAnnotation) -> dict[str, Any]:
    b = ann.box
    out: dict[str, Any] = {"track_id": ann.track_id, "label": ann.label, "x": b.x, "y": b.y, "z": b.z,
                           "heading": b.heading, "length": b.length, "width": b.width, "height": b.height}
    if not b.is_level:
        out["roll"], out["pitch"] = b.roll, b.pitch
    if ann.num_points is not None:
        out["num_points"] = int(ann.num_points)
    if ann.stationary is not None:
        out["stationary"] = bool(ann.stationary)
    return out


def sequence_to_json(seq: Sequence) -> dict[str, Any]:
    """The ``sequence.json`` document for ``seq`` as written by :func:`write_sequence`."""
    frames = []
    for k, info in enumerate(seq.frames):
        frame: dict[str, Any] = {"timestamp_ns": int(info.timestamp_ns), "world_from_ego": np.asarray(info.world_from_ego).tolist()}
        if info.has_sweep:
            frame["points"] = _points_name(k)
        if seq.annotations is not None:
            frame["boxes"] = [_box_json(a) for a in seq.annotations[k]]
        frames.append(frame)
    cameras: dict[str, Any] = {}
    for name, cam in seq.cameras.items():
        entry: dict[str, Any] = {"K": np.asarray(cam.K).tolist(), "distortion": np.asarray(cam.distortion).ravel().tolist(),
                                 "width": int(cam.width), "height": int(cam.height)}
        if cam.ego_from_camera is not None:
            entry["ego_from_camera"] = np.asarray(cam.ego_from_camera).tolist()
        entry["frames"] = [{"timestamp_ns": int(cf.timestamp_ns), "image": _image_name(name, k, Path(cf.image_path)),
                            "world_from_camera": np.asarray(cf.world_from_camera).tolist()}
                           for k, cf in enumerate(cam.frames)]
        cameras[name] = entry
    doc: dict[str, Any] = {"schema_version": SCHEMA_VERSION, "id": seq.id, "source": f"{seq.format}:{seq.root}",
                           "ego_from_lidar": np.asarray(seq.ego_from_lidar).tolist(), "frames": frames}
    if cameras:
        doc["cameras"] = cameras
    return doc


def _sweep_arrays(sweep: Sweep) -> dict[str, np.ndarray]:
    arrays = {"xyz": np.ascontiguousarray(sweep.xyz, dtype=np.float32).reshape(-1, 3)}
    if sweep.intensity is not None:
        arrays["intensity"] = np.asarray(sweep.intensity, dtype=np.float32).reshape(-1)
    if sweep.time_offset_ns is not None:
        arrays["time_offset_ns"] = np.asarray(sweep.time_offset_ns, dtype=np.int64).reshape(-1)
    return arrays


def _same_points(path: Path, arrays: dict[str, np.ndarray]) -> bool:
    """True if ``path`` is a valid point file holding exactly ``arrays``."""
    if not path.is_file():
        return False
    try:
        existing = read_points_file(path)
    except InputError:
        return False
    return _sweep_arrays(existing).keys() == arrays.keys() and all(
        np.array_equal(_sweep_arrays(existing)[k], v) for k, v in arrays.items())


def _copy_file(source: Path, target: Path) -> None:
    """Hard-link ``source`` to ``target`` when possible, else copy; atomic either way."""
    if target.exists():
        with contextlib.suppress(OSError):
            if os.path.samefile(source, target):
                return
        if target.stat().st_size == source.stat().st_size and _same_bytes(source, target):
            return
    with atomic_path(target) as tmp:
        tmp.unlink()
        try:
            os.link(source, tmp)
        except OSError:
            shutil.copyfile(source, tmp)


def _same_bytes(a: Path, b: Path) -> bool:
    with open(a, "rb") as fa, open(b, "rb") as fb:
        while True:
            chunk_a, chunk_b = fa.read(1 << 20), fb.read(1 << 20)
            if chunk_a != chunk_b:
                return False
            if not chunk_a:
                return True


def write_sequence(seq: Sequence, out_dir: str | Path, progress: bool = True) -> Path:
    """Write ``seq`` in the canonical format to ``out_dir``; returns the path of ``sequence.json``.

    The document is validated before anything is written; point files and images are written
    atomically and ``sequence.json`` last. An existing ``sequence.json`` in ``out_dir`` is removed
    first. Rerunning after an interruption keeps point files that already hold the right points.
    """
    out_dir = Path(out_dir)
    json_path = out_dir / "sequence.json"
    if out_dir.exists() and seq.root.exists() and os.path.samefile(out_dir, seq.root):
        raise InputError(out_dir, "output directory is the input sequence; choose another --out")
    doc = sequence_to_json(seq)
    validate("sequence", doc, json_path)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(out_dir, "output exists and is not a directory")
    out_dir.mkdir(parents=True, exist_ok=True)
    with contextlib.suppress(FileNotFoundError):
        json_path.unlink()

    jobs = len(seq.frames) + sum(len(c.frames) for c in seq.cameras.values())
    with tqdm(total=jobs, desc=f"writing {seq.id}", unit="file", disable=not progress, leave=False) as bar:
        for k in range(len(seq.frames)):
            if not seq.frames[k].has_sweep:  # a missing sweep stays missing (no "points" entry)
                bar.update()
                continue
            arrays = _sweep_arrays(seq.sweep(k))
            target = out_dir / _points_name(k)
            if not _same_points(target, arrays):
                write_npz(target, **arrays)
            bar.update()
        for name, cam in seq.cameras.items():
            for k, cf in enumerate(cam.frames):
                source = Path(cf.image_path)
                if not source.is_file():
                    raise InputError(source, "camera image is missing")
                _copy_file(source, out_dir / doc["cameras"][name]["frames"][k]["image"])
                bar.update()
        bar.refresh()   # the last files go faster than tqdm's redraw interval: show 100 % before closing
    write_json(json_path, doc)
    return json_path
