"""Argoverse 2 sensor-dataset log reader (one log directory).

Layout: ``LOG/sensors/lidar/<timestamp_ns>.feather`` (x, y, z float16 in the EGO frame, intensity
uint8, laser_number, offset_ns int32), ``LOG/annotations.feather`` (one row per cuboid and annotated
timestamp), ``LOG/city_SE3_egovehicle.feather`` (ego poses), ``LOG/calibration/
{egovehicle_SE3_sensor,intrinsics}.feather`` and optionally ``LOG/sensors/cameras/<name>/<ts>.jpg``.

Conversion to the project's conventions (the dataset's quirks stay here):

- frames are the union of the sweep timestamps and the annotated timestamps, in time order; an
  annotated timestamp without a sweep file is a frame without a sweep (``FrameInfo.has_sweep``);
- ``world_from_ego`` = ``city_SE3_egovehicle`` (the row at the frame time, else interpolated);
- points stay in the ego frame (AV2 stores them so); ``offset_ns`` is the per-point time offset;
- cuboids: quaternion (qw, qx, qy, qz) rotates object -> ego, (tx, ty, tz) is the centre, length
  along the object's x; in the world the box keeps its full rotation (world_from_ego @ ego_from_object:
  heading = yaw of the object's x axis, plus the roll and pitch the ego pose gives it);
  ``track_uuid`` is the track id, ``category`` the label and ``num_interior_pts`` the box's
  ``num_points``;
- cameras: ``egovehicle_SE3_sensor`` of a ring/stereo camera is ``ego_from_camera`` (OpenCV axes),
  distortion (k1, k2, k3) -> OpenCV (k1, k2, 0, 0, k3); an image per frame is the camera's image
  nearest in time (per-image time from its file name); without images the camera has no frames;
- ``ego_from_lidar`` is the ``up_lidar`` mounting (the points merge both lidars, already in ego).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tracker.geometry import Box

from ..errors import InputError, not_a_file
from .convert_util import box_from_transform, pose_at, quaternions_wxyz_to_matrices
from .sequence import BoxAnnotation, Camera, CameraFrame, FrameInfo, Sequence, Sweep

__all__ = ["is_av2_log", "read_av2", "read_cuboids", "cuboid_box_in_ego", "cuboid_boxes_in_ego"]

_POSE_COLUMNS = ("qw", "qx", "qy", "qz", "tx_m", "ty_m", "tz_m")
_BOX_COLUMNS = ("timestamp_ns", "track_uuid", "category", "length_m", "width_m", "height_m") + _POSE_COLUMNS


def is_av2_log(root: Path) -> bool:
    return (root / "city_SE3_egovehicle.feather").is_file() and (
        (root / "annotations.feather").is_file() or (root / "sensors" / "lidar").is_dir())


def _read_feather(path: Path, columns: tuple[str, ...]) -> dict[str, np.ndarray]:
    import pyarrow.feather as feather

    if not path.is_file():
        raise not_a_file(path)
    try:
        table = feather.read_table(path)
    except Exception as exc:  # noqa: BLE001 - any decoding problem is bad input
        raise InputError(path, f"cannot read feather file ({type(exc).__name__}: {exc})") from exc
    missing = [c for c in columns if c not in table.column_names]
    if missing:
        raise InputError(path, f"missing columns {missing}")
    return {c: table.column(c).to_numpy(zero_copy_only=False) for c in table.column_names}


def _transforms(cols: dict[str, np.ndarray], path: Path, what: str) -> np.ndarray:
    """(N, 4, 4) transforms from the quaternion and translation columns."""
    rotations = quaternions_wxyz_to_matrices(np.stack([cols[k] for k in _POSE_COLUMNS[:4]], axis=1), path, f"{what} row")
    translations = np.stack([cols[k] for k in _POSE_COLUMNS[4:]], axis=1).astype(np.float64)
    if not np.isfinite(translations).all():
        raise InputError(path, f"{what} row {int(np.argmax(~np.isfinite(translations).all(axis=1)))}: translation is not finite")
    out = np.tile(np.eye(4), (len(rotations), 1, 1))
    out[:, :3, :3] = rotations
    out[:, :3, 3] = translations
    return out


def _stamp_files(directory: Path, suffixes: tuple[str, ...]) -> dict[int, Path]:
    if not directory.is_dir():
        return {}
    return {int(p.name.split(".")[0]): p for p in directory.iterdir()
            if p.name.split(".")[0].isdigit() and p.suffix in suffixes}


def _load_sweep(path: Path) -> Sweep:
    cols = _read_feather(path, ("x", "y", "z"))
    xyz = np.stack([cols["x"], cols["y"], cols["z"]], axis=1).astype(np.float32)
    if not np.isfinite(xyz).all():
        raise InputError(path, f"{int((~np.isfinite(xyz).all(axis=1)).sum())} points have non-finite coordinates")
    intensity = cols["intensity"].astype(np.float32) if "intensity" in cols else None
    offsets = cols["offset_ns"].astype(np.int64) if "offset_ns" in cols else None
    return Sweep(xyz=xyz, intensity=intensity, time_offset_ns=offsets)


def cuboid_boxes_in_ego(cols: dict[str, np.ndarray], path: Path) -> list[Box]:
    """The rows of ``annotations.feather`` (as columns) as boxes in the EGO frame at their timestamps."""
    ego_from_object = _transforms(cols, path, "cuboid")
    return [box_from_transform(ego_from_object[i], cols["length_m"][i], cols["width_m"][i], cols["height_m"][i], path,
                               f"row {i}") for i in range(len(ego_from_object))]


def cuboid_box_in_ego(cols: dict[str, np.ndarray], i: int, path: Path) -> Box:
    """Row ``i`` of ``annotations.feather`` (as columns) as a box in the EGO frame."""
    return cuboid_boxes_in_ego({k: v[i:i + 1] for k, v in cols.items()}, path)[0]


def read_cuboids(path: Path) -> dict[str, np.ndarray]:
    """The columns of ``annotations.feather`` (checked)."""
    return _read_feather(path, _BOX_COLUMNS)


def _annotations(path: Path, frame_index: dict[int, int], world_from_ego: list[np.ndarray]) -> list[list[BoxAnnotation]]:
    cols = read_cuboids(path)
    out: list[list[BoxAnnotation]] = [[] for _ in world_from_ego]
    for i, box_ego in enumerate(cuboid_boxes_in_ego(cols, path)):
        k = frame_index[int(cols["timestamp_ns"][i])]
        box = box_ego.transformed(world_from_ego[k], keep_tilt=True)
        count = int(cols["num_interior_pts"][i]) if "num_interior_pts" in cols else None
        out[k].append(BoxAnnotation(track_id=str(cols["track_uuid"][i]), label=str(cols["category"][i]), box=box,
                                    num_points=count))
    return out


def _cameras(root: Path, frames: list[FrameInfo], pose_times: np.ndarray, poses: np.ndarray) -> dict[str, Camera]:
    calib = root / "calibration"
    if not (calib / "intrinsics.feather").is_file():
        return {}
    intr = _read_feather(calib / "intrinsics.feather", ("sensor_name", "fx_px", "fy_px", "cx_px", "cy_px", "k1", "k2",
                                                        "k3", "height_px", "width_px"))
    ext_path = calib / "egovehicle_SE3_sensor.feather"
    ext = _read_feather(ext_path, ("sensor_name",) + _POSE_COLUMNS)
    mounts = dict(zip((str(n) for n in ext["sensor_name"]), _transforms(ext, ext_path, "sensor"), strict=True))
    cameras: dict[str, Camera] = {}
    for i, name in enumerate(str(n) for n in intr["sensor_name"]):
        if name not in mounts:
            raise InputError(ext_path, f"no mounting for camera {name!r}")
        K = np.array([[intr["fx_px"][i], 0.0, intr["cx_px"][i]], [0.0, intr["fy_px"][i], intr["cy_px"][i]], [0, 0, 1.0]])
        images = _stamp_files(root / "sensors" / "cameras" / name, (".jpg", ".png"))
        cam_frames: list[CameraFrame] = []
        if images:
            stamps = np.array(sorted(images), dtype=np.int64)
            for info in frames:
                j = int(np.argmin(np.abs(stamps - info.timestamp_ns)))
                t = int(stamps[j])
                cam_frames.append(CameraFrame(timestamp_ns=t, image_path=images[t],
                                              world_from_camera=pose_at(pose_times, poses, t, root / "city_SE3_egovehicle.feather")
                                              @ mounts[name]))
        cameras[name] = Camera(name=name, K=K, distortion=np.array([intr["k1"][i], intr["k2"][i], 0.0, 0.0, intr["k3"][i]],
                                                                    dtype=np.float64),
                               width=int(intr["width_px"][i]), height=int(intr["height_px"][i]), frames=cam_frames,
                               ego_from_camera=mounts[name])
    return cameras


def read_av2(root: str | Path) -> Sequence:
    """Open one Argoverse 2 sensor log directory."""
    root = Path(root)
    pose_path = root / "city_SE3_egovehicle.feather"
    pose_cols = _read_feather(pose_path, ("timestamp_ns",) + _POSE_COLUMNS)
    order = np.argsort(pose_cols["timestamp_ns"], kind="stable")
    pose_cols = {k: v[order] for k, v in pose_cols.items()}
    pose_times = pose_cols["timestamp_ns"].astype(np.int64)
    if len(pose_times) == 0:
        raise InputError(pose_path, "no poses")
    poses = _transforms(pose_cols, pose_path, "pose")
    sweeps = _stamp_files(root / "sensors" / "lidar", (".feather",))
    ann_path = root / "annotations.feather"
    ann_times = (_read_feather(ann_path, ("timestamp_ns",))["timestamp_ns"].astype(np.int64)
                 if ann_path.is_file() else np.zeros(0, np.int64))
    times = sorted(set(sweeps) | {int(t) for t in ann_times})
    if not times:
        raise InputError(root, "no lidar sweeps (sensors/lidar/*.feather) and no annotations")
    frames = [FrameInfo(index=k, timestamp_ns=t, world_from_ego=pose_at(pose_times, poses, t, pose_path),
                        points_path=sweeps.get(t), has_sweep=t in sweeps) for k, t in enumerate(times)]
    annotations = None
    if ann_path.is_file():
        annotations = _annotations(ann_path, {t: k for k, t in enumerate(times)}, [f.world_from_ego for f in frames])
    cameras = _cameras(root, frames, pose_times, poses)
    ego_from_lidar = np.eye(4)
    ext_path = root / "calibration" / "egovehicle_SE3_sensor.feather"
    if ext_path.is_file():
        ext = _read_feather(ext_path, ("sensor_name",) + _POSE_COLUMNS)
        names = [str(n) for n in ext["sensor_name"]]
        if "up_lidar" in names:
            ego_from_lidar = _transforms(ext, ext_path, "sensor")[names.index("up_lidar")]

    def load(index: int) -> Sweep:
        return _load_sweep(frames[index].points_path)

    return Sequence(id=root.resolve().name, root=root, format="av2", frames=frames, load_sweep=load,
                    ego_from_lidar=ego_from_lidar, cameras=cameras, annotations=annotations)
