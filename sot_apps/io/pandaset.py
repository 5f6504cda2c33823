"""PandaSet reader: the devkit's native layout and its ``.npz``/``.csv`` copy.

Layouts (one sequence directory):

- native (pandaset-devkit): ``lidar/NN.pkl.gz`` and ``annotations/cuboids/NN.pkl.gz`` pandas
  pickles. Reading them needs the optional ``pandas`` extra. **Pickles run code when loaded: only
  read PandaSet pickles from a source you trust.**
- converted: ``lidar/NN.npz`` (columns x, y, z, i, t, d) and ``annotations/cuboids/NN.csv``.

Both share ``lidar/poses.json``, ``lidar/timestamps.json`` and ``camera/<name>/{intrinsics,poses,
timestamps}.json`` + ``NN.jpg``.

PandaSet's quirks end here. The reader converts to the project's conventions:

- points are stored in the WORLD frame; we return them in the ego frame = the frame of ``lidar/poses.json``
  (its y axis points forward); despite its name that pose is NOT the Pandar64's optical centre: the beams
  are cones about a point 1.87 m ahead of and 1.97 m above it (points exist within 0.4 m of the pose
  origin, and the elevation histogram is sharpest from there; measured on the sweeps of pandaset_002,
  docs/lidar_sim.md), so ``ego_from_lidar`` is that translation (:data:`PANDAR64_IN_POSE_FRAME`);
- poses ``{position, heading{w,x,y,z}}`` (sensor->world) become 4x4 ``world_from_ego`` /
  ``world_from_camera``;
- seconds become integer nanoseconds; per-point ``t`` becomes an offset from the frame time;
- boxes: heading = yaw + pi/2 (PandaSet's yaw = 0 points the length along +y), length =
  ``dimensions.y``, width = ``dimensions.x``; rows with ``cuboids.sensor_id == 1`` (the PandarGT
  duplicate of an object in the lidars' overlap) are dropped;
- only the Pandar64 (``d == 0``) points are kept unless ``lidar_ids`` says otherwise;
- frames run from 00 to the last frame with a point file or a cuboid file; a frame in between
  without ``lidar/NN.npz`` (PandaSet 002's release lacks 56-58 and 71) is a frame without a sweep
  (``FrameInfo.has_sweep`` False) whose pose, time, boxes and images are still read.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from tracker.geometry import Box, invert_transform, make_transform, transform_points, wrap_angle

from ..errors import InputError, not_a_file
from .convert_util import rotation_matrices_xyzw
from .npz import read_npz
from .sequence import BoxAnnotation, Camera, CameraFrame, FrameInfo, Sequence, Sweep

__all__ = ["is_pandaset", "read_pandaset", "pose_to_matrix", "seconds_to_ns", "PANDAR64_IN_POSE_FRAME",
           "ego_from_pandar64"]

# The Pandar64's optical centre in the frame of lidar/poses.json (x right, y forward, z up; metres): median of
# `align_sensor_frame` over 5 sets of stationary-ego sweeps of pandaset_002 (spread 0.12 m in x, 0.3 m in y,
# 0.03 m in z; the fitted tilts, -0.75..0.09 degrees, were not consistent and are left out). docs/lidar_sim.md.
PANDAR64_IN_POSE_FRAME = (-0.06, 1.87, 1.97)


def ego_from_pandar64() -> np.ndarray:
    """``ego_from_lidar`` of a PandaSet sequence: the Pandar64's optical centre in the pose frame."""
    out = np.eye(4)
    out[:3, 3] = PANDAR64_IN_POSE_FRAME
    return out


_CAMERA_NAMES = ("front_camera", "front_left_camera", "front_right_camera", "left_camera",
                 "right_camera", "back_camera")


def seconds_to_ns(seconds: float) -> int:
    """Seconds (float) to integer nanoseconds, rounded to the microsecond PandaSet stores."""
    return int(round(float(seconds) * 1e6)) * 1000


def _load_json(path: Path) -> Any:
    if not path.is_file():
        raise not_a_file(path)
    try:
        with open(path, encoding="utf-8") as handle:
            return json.load(handle)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(path, f"not valid JSON ({exc.msg if hasattr(exc, 'msg') else exc})") from exc


def pose_to_matrix(pose: dict, path: Path, what: str) -> np.ndarray:
    """PandaSet pose ``{position{x,y,z}, heading{w,x,y,z}}`` (sensor->world) -> 4x4 world_from_sensor."""
    try:
        t = [float(pose["position"][k]) for k in ("x", "y", "z")]
        q = [float(pose["heading"][k]) for k in ("x", "y", "z", "w")]
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(path, f"{what}: malformed pose ({exc})") from exc
    if not all(math.isfinite(v) for v in t + q):
        raise InputError(path, f"{what}: pose contains a non-finite number")
    norm = math.sqrt(sum(v * v for v in q))
    if not 0.5 < norm < 2.0:
        raise InputError(path, f"{what}: quaternion norm {norm:.3g} is not close to 1")
    return make_transform(rotation_matrices_xyzw(q)[0], np.array(t))


def _frame_files(directory: Path, suffixes: tuple[str, ...]) -> list[Path]:
    """The ``NN<suffix>`` files of ``directory``, one per frame number, in frame order; where a frame has several,
    the first suffix listed wins (so a frame that has only the native ``.pkl.gz`` among ``.npz`` copies is read)."""
    chosen: dict[int, Path] = {}
    for suffix in reversed(suffixes):
        for p in directory.glob(f"*{suffix}"):
            stem = p.name[: -len(suffix)]
            if stem.isdigit():
                chosen[int(stem)] = p
    return [chosen[k] for k in sorted(chosen)]


def is_pandaset(root: Path) -> bool:
    lidar = root / "lidar"
    return (lidar / "poses.json").is_file() and bool(_frame_files(lidar, (".npz", ".pkl.gz")))


def _read_native_pickle(path: Path) -> Any:
    try:
        import pandas as pd  # optional extra
    except ImportError as exc:
        raise InputError(path, "native PandaSet pickles need pandas: pip install 'sot-apps[pandas]'") from exc
    try:
        return pd.read_pickle(path)  # trusted source only: pickles run code
    except Exception as exc:  # noqa: BLE001 - any decoding problem is bad input
        raise InputError(path, f"cannot read pandas pickle ({type(exc).__name__}: {exc})") from exc


def _load_lidar_columns(path: Path) -> dict[str, np.ndarray]:
    if not path.is_file():
        raise not_a_file(path, "point file")
    if path.name.endswith(".npz"):
        return read_npz(path)
    frame = _read_native_pickle(path)
    return {k: frame[k].to_numpy() for k in frame.columns}


def _sweep_loader(frames: list[FrameInfo], lidar_ids: tuple[int, ...]):
    def load(index: int) -> Sweep:
        path = frames[index].points_path
        cols = _load_lidar_columns(path)
        missing = [c for c in ("x", "y", "z") if c not in cols]
        if missing:
            raise InputError(path, f"missing point columns {missing}")
        xyz_world = np.stack([cols["x"], cols["y"], cols["z"]], axis=1).astype(np.float64)
        keep = np.ones(len(xyz_world), dtype=bool)
        if "d" in cols:
            keep &= np.isin(cols["d"], lidar_ids)
        finite = np.isfinite(xyz_world).all(axis=1)
        if not finite[keep].all():
            raise InputError(path, f"{int((~finite[keep]).sum())} points have non-finite coordinates")
        xyz_world = xyz_world[keep]
        ego_from_world = invert_transform(frames[index].world_from_ego)
        xyz = transform_points(ego_from_world, xyz_world).astype(np.float32)
        intensity = cols["i"][keep].astype(np.float32) if "i" in cols else None
        offsets = None
        if "t" in cols:
            t = np.asarray(cols["t"], dtype=np.float64)[keep]
            if not np.isfinite(t).all():
                raise InputError(path, "per-point times contain non-finite values")
            offsets = np.round((t - frames[index].timestamp_ns * 1e-9) * 1e9).astype(np.int64)
        return Sweep(xyz=xyz, intensity=intensity, time_offset_ns=offsets)

    return load


def _truthy(value: Any) -> bool | None:
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    text = str(value).strip().lower()
    if text in ("true", "1"):
        return True
    if text in ("false", "0"):
        return False
    return None


def _dict_rows(reader: Iterator[list[str]]) -> list[dict[str, Any]]:
    """``list(csv.DictReader(...))`` of the rows (blank rows skipped, missing values None, extra ones under None) in
    one loop, at a third of DictReader's cost."""
    header = next(reader, None)
    if header is None:
        return []
    width, out = len(header), []
    for row in reader:
        if not row:
            continue
        record: dict[str, Any] = dict(zip(header, row, strict=False))   # other lengths: below
        if len(row) > width:
            record[None] = row[width:]   # type: ignore[index]
        elif len(row) < width:
            record.update(dict.fromkeys(header[len(row):]))
        out.append(record)
    return out


def _cuboid_rows(path: Path) -> list[dict[str, Any]]:
    if path.name.endswith(".csv"):
        try:
            with open(path, newline="", encoding="utf-8") as handle:
                return _dict_rows(csv.reader(handle))
        except UnicodeDecodeError as exc:
            raise InputError(path, f"not UTF-8 text (byte {exc.object[exc.start]:#04x} at offset {exc.start}); "
                                   "cuboid CSVs must be UTF-8") from None
        except csv.Error as exc:
            raise InputError(path, f"malformed CSV ({exc})") from None
    frame = _read_native_pickle(path)
    return frame.to_dict("records")


_CUBOID_VALUES = ("position.x", "position.y", "position.z", "yaw", "dimensions.y", "dimensions.x", "dimensions.z")


def _read_cuboids(path: Path) -> list[BoxAnnotation]:
    kept: list[dict[str, Any]] = []
    values: list[list[float]] = []
    for row_number, row in enumerate(_cuboid_rows(path), start=2):
        try:
            sensor_id = int(float(row.get("cuboids.sensor_id", -1)))
        except (TypeError, ValueError):
            sensor_id = -1
        if sensor_id == 1:
            continue
        try:
            row_values = [float(row[k]) for k in _CUBOID_VALUES]
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(path, f"row {row_number}: malformed cuboid ({exc})") from exc
        if not all(map(math.isfinite, row_values)):
            raise InputError(path, f"row {row_number}: cuboid contains a non-finite number")
        kept.append(row)
        values.append(row_values)
    # the yaw is the width axis' heading: the length axis' is a quarter turn on (wrapped in one numpy pass)
    headings = wrap_angle(np.array([v[3] for v in values]) + math.pi / 2.0).tolist() if values else []
    return [BoxAnnotation(track_id=str(row["uuid"]), label=str(row.get("label", "")),
                          box=Box(x, y, z, heading, length, width, height), stationary=_truthy(row.get("stationary")))
            for row, (x, y, z, _, length, width, height), heading in zip(kept, values, headings, strict=True)]


def _read_cameras(root: Path, num_frames: int) -> dict[str, Camera]:
    cameras: dict[str, Camera] = {}
    camera_root = root / "camera"
    if not camera_root.is_dir():
        return cameras
    names = [n for n in _CAMERA_NAMES if (camera_root / n).is_dir()]
    names += sorted(p.name for p in camera_root.iterdir() if p.is_dir() and p.name not in names)
    for name in names:
        directory = camera_root / name
        intr = _load_json(directory / "intrinsics.json")
        try:
            fx, fy, cx, cy = (float(intr[k]) for k in ("fx", "fy", "cx", "cy"))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(directory / "intrinsics.json", f"malformed intrinsics ({exc})") from exc
        poses = _load_json(directory / "poses.json")
        stamps = _load_json(directory / "timestamps.json")
        images = _frame_files(directory, (".jpg", ".png"))
        count = min(len(poses), len(stamps), len(images), num_frames)
        if count == 0:
            continue
        frames = [CameraFrame(timestamp_ns=seconds_to_ns(stamps[k]), image_path=images[k],
                              world_from_camera=pose_to_matrix(poses[k], directory / "poses.json", f"frame {k}"))
                  for k in range(count)]
        width, height = _image_size(images[0])
        K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        cameras[name] = Camera(name=name, K=K, distortion=np.zeros(5), width=width, height=height, frames=frames)
    return cameras


def _image_size(path: Path) -> tuple[int, int]:
    """Image width and height: from the JPEG header when possible, else by decoding."""
    size = _jpeg_size(path)
    if size is not None:
        return size
    import cv2

    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise InputError(path, "cannot decode image")
    return int(image.shape[1]), int(image.shape[0])


def _jpeg_size(path: Path) -> tuple[int, int] | None:
    """Width and height from a JPEG's SOF marker (no decoding)."""
    with open(path, "rb") as handle:
        data = handle.read(65536)
    if data[:2] != b"\xff\xd8":
        return None
    i = 2
    while i + 9 < len(data):
        if data[i] != 0xFF:
            i += 1
            continue
        marker = data[i + 1]
        length = int.from_bytes(data[i + 2:i + 4], "big")
        if marker in (0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF):
            height = int.from_bytes(data[i + 5:i + 7], "big")
            width = int.from_bytes(data[i + 7:i + 9], "big")
            return width, height
        i += 2 + length
    return None


def read_pandaset(root: str | Path, lidar_ids: tuple[int, ...] = (0,)) -> Sequence:
    """Open a PandaSet sequence directory (native pickles or the npz/csv copy)."""
    root = Path(root)
    lidar = root / "lidar"
    files = _frame_files(lidar, (".npz", ".pkl.gz"))
    if not files:
        raise InputError(lidar, "no lidar/NN.npz or lidar/NN.pkl.gz files")
    poses = _load_json(lidar / "poses.json")
    stamps = _load_json(lidar / "timestamps.json")
    if not isinstance(poses, list) or not isinstance(stamps, list):
        raise InputError(lidar / "poses.json", "poses.json and timestamps.json must be lists")
    by_index = {int(p.name.split(".")[0]): p for p in files}
    cuboid_dir = root / "annotations" / "cuboids"
    cuboid_files = _frame_files(cuboid_dir, (".csv", ".pkl.gz")) if cuboid_dir.is_dir() else []
    cuboid_by_index = {int(p.name.split(".")[0]): p for p in cuboid_files}
    # frames run to the last one with a sweep or boxes; a frame in between without NN.npz has a missing sweep
    num_frames = max(max(by_index), max(cuboid_by_index, default=-1)) + 1
    if len(poses) < num_frames or len(stamps) < num_frames:
        raise InputError(lidar, f"{num_frames} frames but {len(poses)} poses and {len(stamps)} timestamps")
    frames: list[FrameInfo] = []
    for k in range(num_frames):
        try:
            stamp = float(stamps[k])
        except (TypeError, ValueError) as exc:
            raise InputError(lidar / "timestamps.json", f"frame {k}: not a number") from exc
        if not math.isfinite(stamp):
            raise InputError(lidar / "timestamps.json", f"frame {k}: non-finite timestamp")
        frames.append(FrameInfo(index=k, timestamp_ns=seconds_to_ns(stamp),
                                world_from_ego=pose_to_matrix(poses[k], lidar / "poses.json", f"frame {k}"),
                                points_path=by_index.get(k), has_sweep=k in by_index))
    annotations = None
    if cuboid_by_index:
        annotations = [_read_cuboids(cuboid_by_index[k]) if k in cuboid_by_index else [] for k in range(num_frames)]
    return Sequence(id=root.resolve().name, root=root, format="pandaset", frames=frames,
                    load_sweep=_sweep_loader(frames, lidar_ids), ego_from_lidar=ego_from_pandar64(),
                    cameras=_read_cameras(root, len(frames)), annotations=annotations)
