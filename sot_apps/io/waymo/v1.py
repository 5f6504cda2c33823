"""Waymo Open Dataset v1: one ``segment-*.tfrecord`` of ``Frame`` messages = one sequence.

No TensorFlow: :mod:`.tfrecord` reads the framing (CRC32C checked), :mod:`.messages` defines the
messages read with ``protobuf``, :mod:`.wire` locates the heavy fields (camera JPEGs, range images)
so that opening a segment decodes only poses, timestamps, calibrations and labels. Sweeps are built
on first use from all lidars' range images, first and second return (:mod:`.range_image`); JPEGs are
extracted on first use into a cache directory (:class:`.common.LazyCameraFrames`).

Conversions to the project's conventions:

- frame k = record k (0-based, file order); ``timestamp_ns`` = ``timestamp_micros`` * 1000 (Waymo:
  start of the TOP lidar's scan); ``world_from_ego`` = ``Frame.pose`` (vehicle -> global);
- points in the ego frame of ``Frame.pose``: the TOP lidar's points go through their own pixel's pose
  (world) and back with ``Frame.pose``^-1; the other lidars' points are already in that frame;
  ``intensity`` = range image channel 1; Waymo v1 has no per-point times (``time_offset_ns`` None);
- boxes: ``Label.id`` is the track id; ``Label.Box`` centre/heading are in the vehicle frame of
  ``Frame.pose`` with length along the heading (already our convention), level in the vehicle frame
  -> WORLD with ``world_from_ego`` (the box takes the vehicle's roll and pitch); classes Vehicle / Pedestrian / Sign / Cyclist / Unknown;
- cameras: intrinsic [f_u, f_v, c_u, c_v, k1, k2, p1, p2, k3] -> K + OpenCV distortion
  (k1, k2, p1, p2, k3); extrinsic (camera -> vehicle, camera x forward) -> ``ego_from_camera`` with
  OpenCV axes; an image's time is its ``pose_timestamp`` and its ``world_from_camera`` uses the
  image's own vehicle pose; ``ego_from_lidar`` = the TOP lidar's extrinsic.

Opening checks every record's framing and length CRC; a record's data CRC is checked when its points
or images are first read (checking all data at open would read the whole ~1 GB segment).
"""

from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np
from google.protobuf.message import DecodeError

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
from .messages import CAMERA_IMAGE_BYTES, CAMERA_NAMES, FRAME_IMAGES, FRAME_LASERS, LASER_NAMES, messages
from .range_image import LaserCalibration, decode_matrix_float, lidar_points
from .tfrecord import TFRecordFile
from .wire import WireError, fields, select

__all__ = ["read_waymo_v1", "is_waymo_v1"]

_HEADER_FIELDS = {1, 2, 3, 6}
_CAMERA_META_FIELDS = {1, 3, 5, 6, 7, 8}


def is_waymo_v1(path: Path) -> bool:
    """A ``*.tfrecord`` file, or a directory holding exactly one."""
    if path.is_file():
        return path.suffix == ".tfrecord"
    return path.is_dir() and len(list(path.glob("*.tfrecord"))) == 1


def _frame_parts(records: TFRecordFile, k: int):
    """(header message, [image slices], [laser slices]) of record k (its data CRC is checked only when
    it does not parse, to say whether the file is corrupt or not a Frame file)."""
    path = records.path
    payload = records.payload(k, verify=False)
    images: list[tuple[int, int]] = []
    lasers: list[tuple[int, int]] = []
    try:
        header_bytes = []
        for number, _, tag_start, start, end in fields(payload):
            if number == FRAME_IMAGES:
                images.append((start, end))
            elif number == FRAME_LASERS:
                lasers.append((start, end))
            elif number in _HEADER_FIELDS:
                header_bytes.append(bytes(payload[tag_start:end]))
        header = messages().FrameHeader.FromString(b"".join(header_bytes))
    except (WireError, DecodeError) as exc:
        records.payload(k, verify=True)  # a corrupt record is named as such
        raise InputError(path, f"record {k} is not a Waymo Frame message ({exc})") from exc
    return header, images, lasers


def read_waymo_v1(path: str | Path, image_cache: str | Path | None = None,
                  points: PointSelection = PointSelection()) -> Sequence:
    """Open a Waymo v1 segment (a ``.tfrecord`` file, or a directory holding exactly one).

    ``points`` chooses the lidars and returns of the sweeps (default: all lidars, both returns);
    ``image_cache`` is where JPEGs are extracted (default: the user cache, see :func:`.common.image_cache_dir`).
    """
    path = Path(path)
    if path.is_dir():
        found = sorted(path.glob("*.tfrecord"))
        if len(found) != 1:
            raise InputError(path, f"expected exactly one .tfrecord file, found {len(found)}")
        path = found[0]
    records = TFRecordFile(path)
    if len(records) == 0:
        raise InputError(path, "the TFRecord file holds no records")

    frames: list[FrameInfo] = []
    annotations: list[list[BoxAnnotation]] = []
    image_slices: list[list[tuple[int, int]]] = []
    laser_slices: list[list[tuple[int, int]]] = []
    context = None
    for k in range(len(records)):
        header, images, lasers = _frame_parts(records, k)
        if context is None:
            context = header.context
        elif header.context.name != context.name:
            raise InputError(path, f"record {k} belongs to segment {header.context.name!r}, not {context.name!r}")
        if not header.HasField("pose"):
            raise InputError(path, f"record {k}: the Frame has no pose")
        world_from_ego = transform_4x4(header.pose.transform, path, f"record {k} pose")
        frames.append(FrameInfo(index=k, timestamp_ns=micros_to_ns(header.timestamp_micros),
                                world_from_ego=world_from_ego, points_path=path))
        annotations.append([box_annotation(label.id, label.type, (label.box.center_x, label.box.center_y,
                                                                   label.box.center_z),
                                           label.box.length, label.box.width, label.box.height, label.box.heading,
                                           world_from_ego, path, f"record {k}",
                                           label.num_lidar_points_in_box if label.HasField("num_lidar_points_in_box")
                                           else None)
                            for label in header.laser_labels])
        image_slices.append(images)
        laser_slices.append(lasers)
    stamps = np.array([f.timestamp_ns for f in frames])
    if np.any(np.diff(stamps) <= 0):
        raise InputError(path, f"frame timestamps must increase strictly (record {int(np.argmax(np.diff(stamps) <= 0)) + 1})")

    lasers: dict[int, LaserCalibration] = {}
    for calib in context.laser_calibrations:
        name = LASER_NAMES.get(calib.name, f"LASER_{calib.name}")
        lasers[calib.name] = LaserCalibration(
            name, transform_4x4(calib.extrinsic.transform, path, f"laser calibration {name}"),
            np.asarray(calib.beam_inclinations, dtype=np.float64) if len(calib.beam_inclinations) else None,
            calib.beam_inclination_min, calib.beam_inclination_max)
    ego_from_lidar = lasers[1].vehicle_from_lidar if 1 in lasers else np.eye(4)

    def load(index: int) -> Sweep:
        return _load_sweep(records, index, laser_slices[index], lasers, frames[index].world_from_ego, points)

    cache_root = Path(image_cache) if image_cache is not None else image_cache_dir(path, context.name)
    cameras = _cameras(records, context, image_slices, path, cache_root)
    return Sequence(id=context.name or path.stem, root=path, format="waymo_v1", frames=frames, load_sweep=load,
                    ego_from_lidar=ego_from_lidar, cameras=cameras, annotations=annotations)


def _load_sweep(records: TFRecordFile, index: int, slices: list[tuple[int, int]], lasers: dict[int, LaserCalibration],
                world_from_ego: np.ndarray, selection: PointSelection) -> Sweep:
    path = records.path
    payload = records.payload(index, verify=True)
    vehicle_from_world = invert_transform(world_from_ego)
    xyz_parts, intensity_parts = [], []
    m = messages()
    for start, end in slices:
        try:
            laser = m.Laser.FromString(bytes(payload[start:end]))
        except DecodeError as exc:
            raise InputError(path, f"record {index}: malformed Laser message ({exc})") from exc
        returns = [ri for r, ri in ((1, laser.ri_return1), (2, laser.ri_return2))
                   if r in selection.returns and ri.range_image_compressed]
        if not returns or not selection.wants(laser.name):
            continue
        name = LASER_NAMES.get(laser.name, str(laser.name))
        if laser.name not in lasers:
            raise InputError(path, f"record {index}: lidar {name} has range images but no calibration")
        try:
            pixel_pose = None
            if laser.ri_return1.range_image_pose_compressed:
                pixel_pose = decode_matrix_float(laser.ri_return1.range_image_pose_compressed)
            images = [decode_matrix_float(ri.range_image_compressed) for ri in returns]
            xyz, intensity = lidar_points(images, lasers[laser.name], pixel_pose, vehicle_from_world)
        except zlib.error as exc:
            raise InputError(path, f"record {index}: lidar {name}: range image does not decompress ({exc})") from exc
        except (WireError, ValueError) as exc:
            raise InputError(path, f"record {index}: lidar {name}: bad range image ({exc})") from exc
        xyz_parts += xyz
        intensity_parts += intensity
    return sweep_from_parts(xyz_parts, intensity_parts, path, f"record {index}")


def _cameras(records: TFRecordFile, context, image_slices: list[list[tuple[int, int]]], path: Path,
             cache_root: Path) -> dict[str, Camera]:
    m = messages()
    per_camera: dict[int, list[ImageRecord]] = {}
    calibrations = {c.name: c for c in context.camera_calibrations}
    ego_from_camera = {name: transform_4x4(c.extrinsic.transform, path, f"camera calibration {CAMERA_NAMES.get(name)}")
                       @ WAYMO_CAMERA_FROM_OPENCV for name, c in calibrations.items()}
    complete = {name: True for name in calibrations}
    for k, slices in enumerate(image_slices):
        payload = records.payload(k, verify=False)
        seen = set()
        for start, end in slices:
            try:
                meta = m.CameraImage.FromString(select(payload, _CAMERA_META_FIELDS, start, end))
            except (WireError, DecodeError) as exc:
                raise InputError(path, f"record {k}: malformed CameraImage ({exc})") from exc
            name = meta.name
            if name not in calibrations or not complete[name]:
                continue
            seen.add(name)
            world_from_vehicle = transform_4x4(meta.pose.transform, path, f"record {k} image pose")
            per_camera.setdefault(name, []).append(ImageRecord(
                timestamp_ns=seconds_to_ns(meta.pose_timestamp),
                world_from_camera=world_from_vehicle @ ego_from_camera[name],
                read_jpeg=_jpeg_reader(records, k, start, end)))
        for name in calibrations:  # a camera's frames must be the first n lidar frames
            if name not in seen:
                complete[name] = False
    cameras: dict[str, Camera] = {}
    for name, calib in sorted(calibrations.items()):
        images = per_camera.get(name, [])
        if not images:
            continue
        label = CAMERA_NAMES.get(name, f"CAMERA_{name}")
        intr = list(calib.intrinsic) + [0.0] * max(0, 9 - len(calib.intrinsic))
        cameras[label] = Camera(name=label, K=camera_intrinsics(*intr[:4]), distortion=np.array(intr[4:9]),
                                width=int(calib.width), height=int(calib.height),
                                frames=LazyCameraFrames(images, cache_root / label),  # type: ignore[arg-type]
                                ego_from_camera=ego_from_camera[name])
    return cameras


def _jpeg_reader(records: TFRecordFile, k: int, start: int, end: int):
    def read() -> bytes:
        payload = records.payload(k, verify=True)
        for number, _, _, value_start, value_end in fields(payload, start, end):
            if number == CAMERA_IMAGE_BYTES:
                return bytes(payload[value_start:value_end])
        raise InputError(records.path, f"record {k}: a camera image has no JPEG data")

    return read
