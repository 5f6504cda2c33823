"""Waymo Open Dataset v2: component parquet tables per segment, read with pyarrow.

Layout (the official one): ``DATA_DIR/<component>/<segment>.parquet`` for the components
``vehicle_pose`` (required), ``lidar``, ``lidar_pose``, ``lidar_calibration``, ``lidar_box``,
``camera_image`` and ``camera_calibration`` (each optional). Open with the directory ``DATA_DIR``
(when it holds one segment) or with any component file of the segment, e.g.
``DATA_DIR/vehicle_pose/<segment>.parquet``. Columns are the v2 names: ``key.segment_context_name``,
``key.frame_timestamp_micros``, ``key.laser_name``, ``key.camera_name``, ``key.laser_object_id`` and
``[Component].field.subfield`` (e.g. ``[LiDARBoxComponent].box.center.x``).

Same conventions as v1 (see :mod:`.v1`): frames are the vehicle-pose rows in time order,
``world_from_ego`` = ``world_from_vehicle``; sweeps from the range images of every lidar (both
returns; the TOP lidar through its per-pixel poses from ``lidar_pose``); boxes from ``lidar_box``
(``box.size.x`` = length along ``box.heading``) to WORLD; cameras from ``camera_calibration`` and
``camera_image`` (image time = ``pose_timestamp``). Only the key columns and small tables are read at
open; range images and JPEGs are read per row group on first use.
"""

from __future__ import annotations

from collections import OrderedDict
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from tracker.geometry import invert_transform

from ...errors import InputError
from ..sequence import BoxAnnotation, Camera, FrameInfo, Sequence, Sweep
from .common import (
    WAYMO_CAMERA_FROM_OPENCV,
    ImageRecord,
    LazyCameraFrames,
    PointSelection,
    box_annotation,
    camera_intrinsics,
    image_cache_dir,
    micros_to_ns,
    seconds_to_ns,
    sweep_from_parts,
    transform_4x4,
)
from .messages import CAMERA_NAMES, LASER_NAMES
from .range_image import LaserCalibration, lidar_points
from .wire import WireError

__all__ = ["read_waymo_v2", "is_waymo_v2", "COMPONENTS", "v2_segment_files"]

COMPONENTS = ("vehicle_pose", "lidar", "lidar_pose", "lidar_calibration", "lidar_box", "camera_image",
              "camera_calibration")
SEGMENT = "key.segment_context_name"
TIME = "key.frame_timestamp_micros"
LASER = "key.laser_name"
CAMERA = "key.camera_name"
OBJECT = "key.laser_object_id"
POSE = "[VehiclePoseComponent].world_from_vehicle.transform"
LIDAR = "[LiDARComponent].range_image_return{}.{}"
LIDAR_POSE = "[LiDARPoseComponent].range_image_return1.{}"
LCAL = "[LiDARCalibrationComponent]."
BOX = "[LiDARBoxComponent]."
CIMG = "[CameraImageComponent]."
CCAL = "[CameraCalibrationComponent]."


def _segment_root(path: Path) -> tuple[Path, str] | None:
    """(DATA_DIR, segment) for a component file or a one-segment data directory, else None."""
    if path.is_file() and path.suffix == ".parquet" and path.parent.name in COMPONENTS:
        root = path.parent.parent
        if (root / "vehicle_pose" / path.name).is_file():
            return root, path.stem
        return None
    if path.is_dir() and (path / "vehicle_pose").is_dir():
        files = sorted((path / "vehicle_pose").glob("*.parquet"))
        if len(files) == 1:
            return path, files[0].stem
    return None


def is_waymo_v2(path: Path) -> bool:
    return _segment_root(path) is not None


def v2_segment_files(root: Path, segment: str) -> dict[str, Path]:
    """The component files of ``segment`` under ``root`` that exist."""
    return {c: root / c / f"{segment}.parquet" for c in COMPONENTS if (root / c / f"{segment}.parquet").is_file()}


class _ComponentTable:
    """One component file: key columns read at open, other columns read per row group on demand."""

    def __init__(self, path: Path, segment: str, keys: list[str], eager: list[str] | None = None,
                 optional: tuple[str, ...] = ()) -> None:
        self.path = path
        try:
            self._file = pq.ParquetFile(path)
            names = set(self._file.schema_arrow.names)
            missing = [c for c in [SEGMENT, *keys, *(eager or [])] if c not in names]
            if missing:
                raise InputError(path, f"missing columns {missing}")
            present = [c for c in optional if c in names]
            self.keys = self._file.read(columns=[SEGMENT, *keys, *(eager or []), *present])
        except (pa.ArrowException, OSError) as exc:
            raise InputError(path, f"cannot read parquet ({exc})") from exc
        other = set(self.keys.column(SEGMENT).to_pylist()) - {segment}
        if other:
            raise InputError(path, f"rows of other segments {sorted(other)[:3]} in the file of segment {segment}")
        sizes = [self._file.metadata.row_group(i).num_rows for i in range(self._file.metadata.num_row_groups)]
        self._starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self._cache: OrderedDict[tuple[int, tuple[str, ...]], pa.Table] = OrderedDict()

    def column(self, name: str) -> list:
        return self.keys.column(name).to_pylist()

    def has(self, name: str) -> bool:
        return name in self.keys.column_names

    def row(self, index: int, columns: list[str]) -> pa.Table:
        """One row's ``columns`` as a one-row table (reads and caches the row group that holds it)."""
        group = int(np.searchsorted(self._starts, index, side="right") - 1)
        key = (group, tuple(columns))
        if key not in self._cache:
            try:
                self._cache[key] = self._file.read_row_group(group, columns=columns)
            except (pa.ArrowException, OSError, KeyError) as exc:
                raise InputError(self.path, f"cannot read row group {group} ({exc})") from exc
            while len(self._cache) > 2:
                self._cache.popitem(last=False)
        return self._cache[key].slice(index - int(self._starts[group]), 1)


def _range_image(row: pa.Table, values: str, shape: str, path: Path, what: str) -> np.ndarray | None:
    """The [H, W, C] image of a one-row table's ``values``/``shape`` list columns (None when null or empty)."""
    data, dims = row.column(values).combine_chunks(), row.column(shape).combine_chunks()
    if data.null_count or dims.null_count:
        return None
    array = data.flatten().to_numpy(zero_copy_only=False).astype(np.float32, copy=False)
    dims = dims.flatten().to_numpy(zero_copy_only=False)
    if array.size == 0:
        return None
    if int(np.prod(dims)) != array.size:
        raise InputError(path, f"{what}: {array.size} values for shape {list(dims)}")
    return array.reshape([int(d) for d in dims])


def read_waymo_v2(path: str | Path, image_cache: str | Path | None = None,
                  points: PointSelection = PointSelection()) -> Sequence:
    """Open one Waymo v2 segment (a data directory with one segment, or any component file of it).

    ``points`` and ``image_cache`` as for :func:`.v1.read_waymo_v1`.
    """
    path = Path(path)
    found = _segment_root(path)
    if found is None:
        raise InputError(path, "not a Waymo v2 segment: expected DATA_DIR/vehicle_pose/<segment>.parquet")
    root, segment = found
    files = v2_segment_files(root, segment)

    poses = _ComponentTable(files["vehicle_pose"], segment, [TIME], [POSE])
    stamps = np.asarray(poses.column(TIME), dtype=np.int64)
    order = np.argsort(stamps, kind="stable")
    if np.any(np.diff(stamps[order]) <= 0):
        raise InputError(files["vehicle_pose"], "frame timestamps must be unique")
    pose_values = poses.column(POSE)
    frames = [FrameInfo(index=k, timestamp_ns=micros_to_ns(stamps[i]),
                        world_from_ego=transform_4x4(pose_values[i], files["vehicle_pose"], f"row {i}"),
                        points_path=files.get("lidar", files["vehicle_pose"]))
              for k, i in enumerate(order)]
    frame_of = {int(stamps[i]): k for k, i in enumerate(order)}

    calibrations = _lidar_calibrations(files["lidar_calibration"], segment) if "lidar_calibration" in files else {}
    load = _sweep_loader(files, segment, frames, frame_of, calibrations, points)
    annotations = _boxes(files["lidar_box"], segment, frames, frame_of) if "lidar_box" in files else None
    cameras = {}
    if "camera_image" in files and "camera_calibration" in files:
        cache = Path(image_cache) if image_cache is not None else image_cache_dir(files["camera_image"], segment)
        cameras = _cameras(files, segment, frames, frame_of, cache)
    ego_from_lidar = calibrations[1].vehicle_from_lidar if 1 in calibrations else np.eye(4)
    return Sequence(id=segment, root=files["vehicle_pose"], format="waymo_v2", frames=frames, load_sweep=load,
                    ego_from_lidar=ego_from_lidar, cameras=cameras, annotations=annotations)


def _lidar_calibrations(path: Path, segment: str) -> dict[int, LaserCalibration]:
    cols = [LCAL + "extrinsic.transform", LCAL + "beam_inclination.min", LCAL + "beam_inclination.max"]
    values = LCAL + "beam_inclination.values"
    table = _ComponentTable(path, segment, [LASER], cols, optional=(values,))
    per_beam = table.column(values) if table.has(values) else [None] * len(table.keys)
    out = {}
    for i, code in enumerate(table.column(LASER)):
        name = LASER_NAMES.get(int(code), str(code))
        out[int(code)] = LaserCalibration(
            name, transform_4x4(table.column(cols[0])[i], path, f"laser {name} extrinsic"),
            np.asarray(per_beam[i], dtype=np.float64) if per_beam[i] else None,
            float(table.column(cols[1])[i]), float(table.column(cols[2])[i]))
    return out


def _sweep_loader(files: dict[str, Path], segment: str, frames: list[FrameInfo], frame_of: dict[int, int],
                  calibrations: dict[int, LaserCalibration], selection: PointSelection):
    if "lidar" not in files:
        return lambda index: sweep_from_parts([], [], files["vehicle_pose"], f"frame {index}")
    if "lidar_calibration" not in files:
        raise InputError(files["lidar"], "range images need lidar_calibration/<segment>.parquet beside lidar/")
    lidar = _ComponentTable(files["lidar"], segment, [TIME, LASER])
    rows: dict[int, list[tuple[int, int]]] = {}
    for i, (t, laser) in enumerate(zip(lidar.column(TIME), lidar.column(LASER), strict=True)):
        if int(t) in frame_of and selection.wants(int(laser)):
            rows.setdefault(frame_of[int(t)], []).append((i, int(laser)))
    pose_rows: dict[tuple[int, int], int] = {}
    lidar_pose = None
    if "lidar_pose" in files:
        lidar_pose = _ComponentTable(files["lidar_pose"], segment, [TIME, LASER])
        for i, (t, laser) in enumerate(zip(lidar_pose.column(TIME), lidar_pose.column(LASER), strict=True)):
            if int(t) in frame_of:
                pose_rows[(frame_of[int(t)], int(laser))] = i
    range_columns = [LIDAR.format(r, f) for r in selection.returns for f in ("values", "shape")]
    pose_columns = [LIDAR_POSE.format("values"), LIDAR_POSE.format("shape")]

    def load(index: int) -> Sweep:
        vehicle_from_world = invert_transform(frames[index].world_from_ego)
        xyz_parts, intensity_parts = [], []
        for row_index, laser in rows.get(index, []):
            name = LASER_NAMES.get(laser, str(laser))
            if laser not in calibrations:
                raise InputError(files["lidar_calibration"], f"no calibration for lidar {name}")
            row = lidar.row(row_index, range_columns)
            pixel_pose = None
            if lidar_pose is not None and (index, laser) in pose_rows:
                pose_row = lidar_pose.row(pose_rows[(index, laser)], pose_columns)
                pixel_pose = _range_image(pose_row, *pose_columns, files["lidar_pose"], f"frame {index} lidar {name}")
            images = [_range_image(row, LIDAR.format(r, "values"), LIDAR.format(r, "shape"), files["lidar"],
                                   f"frame {index} lidar {name} return {r}") for r in selection.returns]
            try:
                xyz, intensity = lidar_points([i for i in images if i is not None], calibrations[laser], pixel_pose,
                                              vehicle_from_world)
            except WireError as exc:
                raise InputError(files["lidar"], f"frame {index} lidar {name}: {exc}") from exc
            xyz_parts += xyz
            intensity_parts += intensity
        return sweep_from_parts(xyz_parts, intensity_parts, files["lidar"], f"frame {index}")

    return load


def _boxes(path: Path, segment: str, frames: list[FrameInfo], frame_of: dict[int, int]) -> list[list[BoxAnnotation]]:
    fields = ["box.center.x", "box.center.y", "box.center.z", "box.size.x", "box.size.y", "box.size.z", "box.heading",
              "type"]
    count = BOX + "num_lidar_points_in_box"
    table = _ComponentTable(path, segment, [TIME, OBJECT], [BOX + f for f in fields], optional=(count,))
    columns = {f: table.column(BOX + f) for f in fields}
    counts = table.column(count) if table.has(count) else [None] * len(table.keys)
    out: list[list[BoxAnnotation]] = [[] for _ in frames]
    for i, (t, object_id) in enumerate(zip(table.column(TIME), table.column(OBJECT), strict=True)):
        k = frame_of.get(int(t))
        if k is None:
            raise InputError(path, f"row {i}: box at {t} us, a time with no vehicle pose")
        c = {f: columns[f][i] for f in fields}
        out[k].append(box_annotation(str(object_id), c["type"], (c["box.center.x"], c["box.center.y"], c["box.center.z"]),
                                     c["box.size.x"], c["box.size.y"], c["box.size.z"], c["box.heading"],
                                     frames[k].world_from_ego, path, f"row {i}", counts[i]))
    return out


def _cameras(files: dict[str, Path], segment: str, frames: list[FrameInfo], frame_of: dict[int, int],
             cache: Path) -> dict[str, Camera]:
    cal_path = files["camera_calibration"]
    intr = ["f_u", "f_v", "c_u", "c_v", "k1", "k2", "p1", "p2", "k3"]
    cal = _ComponentTable(cal_path, segment, [CAMERA], [CCAL + f"intrinsic.{f}" for f in intr]
                          + [CCAL + "extrinsic.transform", CCAL + "width", CCAL + "height"])
    img_path = files["camera_image"]
    images = _ComponentTable(img_path, segment, [TIME, CAMERA], [CIMG + "pose.transform", CIMG + "pose_timestamp"])
    by_camera: dict[int, dict[int, int]] = {}
    for i, (t, name) in enumerate(zip(images.column(TIME), images.column(CAMERA), strict=True)):
        if int(t) in frame_of:
            by_camera.setdefault(int(name), {})[frame_of[int(t)]] = i
    img_poses, img_times = images.column(CIMG + "pose.transform"), images.column(CIMG + "pose_timestamp")
    cameras: dict[str, Camera] = {}
    for j, name in enumerate(cal.column(CAMERA)):
        name = int(name)
        label = CAMERA_NAMES.get(name, f"CAMERA_{name}")
        ego_from_camera = transform_4x4(cal.column(CCAL + "extrinsic.transform")[j], cal_path,
                                        f"camera {label} extrinsic") @ WAYMO_CAMERA_FROM_OPENCV
        rows = by_camera.get(name, {})
        records = []
        for k in range(len(frames)):  # the camera's frames are the first n lidar frames
            if k not in rows:
                break
            i = rows[k]
            records.append(ImageRecord(
                timestamp_ns=seconds_to_ns(img_times[i]),
                world_from_camera=transform_4x4(img_poses[i], img_path, f"row {i} pose") @ ego_from_camera,
                read_jpeg=_jpeg_reader(images, i)))
        if not records:
            continue
        values = [float(cal.column(CCAL + f"intrinsic.{f}")[j]) for f in intr]
        cameras[label] = Camera(name=label, K=camera_intrinsics(*values[:4]), distortion=np.array(values[4:]),
                                width=int(cal.column(CCAL + "width")[j]), height=int(cal.column(CCAL + "height")[j]),
                                frames=LazyCameraFrames(records, cache / label),  # type: ignore[arg-type]
                                ego_from_camera=ego_from_camera)
    return dict(sorted(cameras.items()))


def _jpeg_reader(images: _ComponentTable, index: int):
    def read() -> bytes:
        data = images.row(index, [CIMG + "image"]).column(0)[0].as_py()
        if not data:
            raise InputError(images.path, f"row {index}: no JPEG data")
        return bytes(data)

    return read
