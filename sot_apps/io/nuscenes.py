"""nuScenes reader: the v1.0 JSON tables + ``samples/`` and ``sweeps/`` (one scene).

Layout (DATAROOT)::

    v1.0-*/{scene,sample,sample_data,ego_pose,calibrated_sensor,sensor,sample_annotation,instance,category,log}.json
    samples/LIDAR_TOP/*.pcd.bin    sweeps/LIDAR_TOP/*.pcd.bin    samples/CAM_*/*.jpg

A scene is chosen with ``DATAROOT#scene-0061`` (name or token); a DATAROOT with one scene needs none.

Conversion to the project's conventions:

- frames are the scene's ``LIDAR_TOP`` sample_data in time order: keyframes (``is_key_frame``) carry
  the sample's annotations, the sweeps between them are frames without boxes; a sample_data whose
  file is absent is a frame without a sweep;
- ``world_from_ego`` = the sample_data's ``ego_pose`` (rotation w, x, y, z + translation; the nuScenes
  global frame is the world); timestamps are microseconds -> nanoseconds;
- points: ``.pcd.bin`` float32 x 5 (x, y, z, intensity, ring) in the LIDAR_TOP frame, moved to the
  ego frame with the sample_data's ``calibrated_sensor`` (``ego_from_lidar``); no per-point times;
- boxes: ``translation`` is the centre in the global frame, ``size`` is (width, length, height),
  ``rotation`` turns the box frame (x along the length) into the global frame: heading = yaw of the
  box's x axis, roll and pitch the rest of the rotation; the ``instance_token`` is the track id, the category name the label;
- cameras: ``camera_intrinsic`` is K (images are undistorted), the camera's ``calibrated_sensor`` is
  ``ego_from_camera`` (OpenCV axes); frame k's image is the camera's sample_data nearest in time,
  posed with its own ``ego_pose`` (per-image time); images only when all files exist.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from tracker.geometry import Box, transform_points

from ..errors import InputError
from .convert_util import box_from_transform, read_float32_records, transform_from_quaternion
from .sequence import BoxAnnotation, Camera, CameraFrame, FrameInfo, Sequence, Sweep

__all__ = ["is_nuscenes", "read_nuscenes", "annotation_box", "read_pcd_bin", "lidar_sweep_in_ego", "TABLES"]

TABLES = ("scene", "sample", "sample_data", "ego_pose", "calibrated_sensor", "sensor", "sample_annotation",
          "instance", "category", "log")
LIDAR_CHANNEL = "LIDAR_TOP"


def _version_dirs(root: Path) -> list[Path]:
    return sorted(p for p in root.glob("v1.0-*") if (p / "sample.json").is_file() and (p / "scene.json").is_file())


def is_nuscenes(path: Path) -> bool:
    return Path(path).is_dir() and bool(_version_dirs(Path(path)))


def _load_table(directory: Path, name: str) -> list[dict[str, Any]]:
    path = directory / f"{name}.json"
    if not path.is_file():
        raise InputError(path, "nuScenes table is missing")
    try:
        with open(path, encoding="utf-8") as handle:
            table = json.load(handle)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(path, f"not valid JSON ({exc})") from exc
    if not isinstance(table, list) or not all(isinstance(r, dict) and "token" in r for r in table):
        raise InputError(path, "expected a JSON list of records with a 'token'")
    return table


def _pose(record: dict[str, Any], path: Path, where: str) -> np.ndarray:
    try:
        return transform_from_quaternion(record["rotation"], record["translation"], path, where)
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(path, f"{where}: malformed rotation/translation ({exc})") from exc


def annotation_box(record: dict[str, Any], path: Path = Path("sample_annotation.json")) -> Box:
    """A ``sample_annotation`` record -> its box in the global (world) frame."""
    where = f"sample_annotation {record.get('token', '?')}"
    try:
        width, length, height = (float(v) for v in record["size"])
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(path, f"{where}: 'size' must be [width, length, height] ({exc})") from exc
    return box_from_transform(_pose(record, path, where), length, width, height, path, where)


def read_pcd_bin(path: Path) -> np.ndarray:
    """(N, 5) float32 x, y, z, intensity, ring of a nuScenes ``.pcd.bin``."""
    return read_float32_records(path, 5)


def lidar_sweep_in_ego(path: Path, ego_from_lidar: np.ndarray) -> Sweep:
    """A LIDAR_TOP file's points in the ego frame, with intensity."""
    data = read_pcd_bin(path)
    xyz = transform_points(ego_from_lidar, data[:, :3].astype(np.float64)).astype(np.float32)
    return Sweep(xyz=xyz, intensity=np.ascontiguousarray(data[:, 3]))


def read_nuscenes(root: str | Path, scene: str | None = None) -> Sequence:
    """Open one scene of a nuScenes DATAROOT (``scene``: name or token; optional with a single scene)."""
    root = Path(root)
    versions = _version_dirs(root)
    if len(versions) != 1:
        raise InputError(root, f"expected one v1.0-* table folder, found {len(versions)}")
    tables_dir = versions[0]
    t = {name: _load_table(tables_dir, name) for name in TABLES}
    by = {name: {r["token"]: r for r in rows} for name, rows in t.items()}
    scenes = t["scene"]
    if scene is None:
        if len(scenes) != 1:
            names = ", ".join(s.get("name", s["token"]) for s in scenes[:8])
            raise InputError(root, f"{len(scenes)} scenes ({names}); name one: {root}#<scene name>")
        record = scenes[0]
    else:
        matches = [s for s in scenes if scene in (s.get("name"), s["token"])]
        if not matches:
            raise InputError(tables_dir / "scene.json", f"no scene named {scene!r}")
        record = matches[0]
    sd_path = tables_dir / "sample_data.json"
    samples = {s["token"] for s in t["sample"] if s.get("scene_token") == record["token"]}
    channel_of = {}
    for cs in t["calibrated_sensor"]:
        sensor = by["sensor"].get(cs.get("sensor_token"))
        if sensor is None:
            raise InputError(tables_dir / "calibrated_sensor.json", f"{cs['token']}: unknown sensor_token")
        channel_of[cs["token"]] = (sensor["channel"], sensor.get("modality", ""))
    scene_data = [sd for sd in t["sample_data"] if sd.get("sample_token") in samples]
    for sd in scene_data:
        if sd.get("calibrated_sensor_token") not in channel_of or sd.get("ego_pose_token") not in by["ego_pose"]:
            raise InputError(sd_path, f"{sd['token']}: unknown calibrated_sensor_token or ego_pose_token")
    lidar = sorted((sd for sd in scene_data if channel_of[sd["calibrated_sensor_token"]][0] == LIDAR_CHANNEL),
                   key=lambda sd: int(sd["timestamp"]))
    if not lidar:
        raise InputError(sd_path, f"scene {record.get('name')}: no {LIDAR_CHANNEL} sample_data")
    ego_path, cs_path = tables_dir / "ego_pose.json", tables_dir / "calibrated_sensor.json"
    frames, ego_from_lidar = [], []
    for k, sd in enumerate(lidar):
        file = root / sd["filename"]
        frames.append(FrameInfo(index=k, timestamp_ns=int(sd["timestamp"]) * 1000,
                                world_from_ego=_pose(by["ego_pose"][sd["ego_pose_token"]], ego_path, f"ego_pose of {sd['token']}"),
                                points_path=file if file.is_file() else None, has_sweep=file.is_file()))
        ego_from_lidar.append(_pose(by["calibrated_sensor"][sd["calibrated_sensor_token"]], cs_path, f"{sd['token']}"))
    stamps = np.array([f.timestamp_ns for f in frames])
    if np.any(np.diff(stamps) <= 0):
        raise InputError(sd_path, f"scene {record.get('name')}: two {LIDAR_CHANNEL} sample_data share a timestamp")
    ann_path = tables_dir / "sample_annotation.json"
    by_sample: dict[str, list[BoxAnnotation]] = {}
    for ann in t["sample_annotation"]:
        if ann.get("sample_token") not in samples:
            continue
        instance = by["instance"].get(ann.get("instance_token"))
        if instance is None:
            raise InputError(ann_path, f"{ann['token']}: unknown instance_token")
        category = by["category"].get(instance.get("category_token"), {}).get("name", "")
        by_sample.setdefault(ann["sample_token"], []).append(
            BoxAnnotation(track_id=ann["instance_token"], label=category, box=annotation_box(ann, ann_path)))
    annotations = [by_sample.get(sd["sample_token"], []) if sd.get("is_key_frame") else [] for sd in lidar]
    cameras = _cameras(root, scene_data, channel_of, by, frames, tables_dir)

    def load(index: int) -> Sweep:
        return lidar_sweep_in_ego(frames[index].points_path, ego_from_lidar[index])

    return Sequence(id=str(record.get("name", record["token"])), root=root, format="nuscenes", frames=frames,
                    load_sweep=load, ego_from_lidar=ego_from_lidar[0], cameras=cameras, annotations=annotations)


def _cameras(root: Path, scene_data: list[dict], channel_of: dict, by: dict, frames: list[FrameInfo],
             tables_dir: Path) -> dict[str, Camera]:
    cameras: dict[str, Camera] = {}
    channels = sorted({ch for ch, modality in channel_of.values() if modality == "camera"})
    cs_path, ego_path = tables_dir / "calibrated_sensor.json", tables_dir / "ego_pose.json"
    for channel in channels:
        data = sorted((sd for sd in scene_data if channel_of[sd["calibrated_sensor_token"]][0] == channel),
                      key=lambda sd: int(sd["timestamp"]))
        if not data:
            continue
        cs = by["calibrated_sensor"][data[0]["calibrated_sensor_token"]]
        K = np.asarray(cs.get("camera_intrinsic") or [], dtype=np.float64)
        if K.shape != (3, 3):
            raise InputError(cs_path, f"{cs['token']}: camera_intrinsic of {channel} must be 3x3")
        ego_from_camera = _pose(cs, cs_path, cs["token"])
        stamps = np.array([int(sd["timestamp"]) * 1000 for sd in data], dtype=np.int64)
        cam_frames = []
        if all((root / sd["filename"]).is_file() for sd in data):
            for info in frames:
                sd = data[int(np.argmin(np.abs(stamps - info.timestamp_ns)))]
                world_from_ego = _pose(by["ego_pose"][sd["ego_pose_token"]], ego_path, f"ego_pose of {sd['token']}")
                cam_frames.append(CameraFrame(timestamp_ns=int(sd["timestamp"]) * 1000, image_path=root / sd["filename"],
                                              world_from_camera=world_from_ego @ ego_from_camera))
        cameras[channel] = Camera(name=channel, K=K, distortion=np.zeros(5), width=int(data[0].get("width") or 1600),
                                  height=int(data[0].get("height") or 900), frames=cam_frames,
                                  ego_from_camera=ego_from_camera)
    return cameras
