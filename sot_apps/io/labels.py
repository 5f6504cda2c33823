"""Writers of box labels (tracks of boxes per frame) in the formats people train on.

- :func:`write_kitti_tracking`: KITTI tracking ``label_02/NNNN.txt`` (+ ``calib/NNNN.txt``). Boxes go to the
  LiDAR frame of each sweep and then to a KITTI camera with ideal axes at the LiDAR origin (written as the
  calib's ``Tr_velo_to_cam``, ``R0_rect`` = identity), so :func:`sot_apps.io.detections.read_detections`
  with that calib gives the boxes back. No camera image: the 2D box columns are -1; a score column is added.
- :func:`write_av2_annotations`: Argoverse 2 sensor ``annotations.feather`` (timestamp_ns, track_uuid, category,
  length_m, width_m, height_m, qw, qx, qy, qz, tx_m, ty_m, tz_m, num_interior_pts), boxes in the EGO frame of
  each sweep, as AV2 stores them; track uuids are deterministic (uuid5 of the sequence and track id).
"""

from __future__ import annotations

import uuid
from pathlib import Path
from typing import Mapping

import numpy as np

from tracker.geometry import Box, invert_transform, wrap_angle

from .atomic import atomic_path, write_text
from .detections import KITTI_CAMERA_FROM_LIDAR, lidar_to_kitti_boxes

__all__ = ["LabelTrack", "write_kitti_tracking", "write_av2_annotations"]

# a label track: (track id, category, score, {frame: world Box})
LabelTrack = tuple[str, str, float, Mapping[int, Box]]


def _to_frame(box: Box, frame_from_world: np.ndarray) -> np.ndarray:
    return box.transformed(frame_from_world).to_array()


def write_kitti_tracking(out_dir: str | Path, tracks: list[LabelTrack], world_from_lidar: list[np.ndarray],
                         sequence_number: int = 0) -> Path:
    """``out_dir/label_02/NNNN.txt`` and ``out_dir/calib/NNNN.txt``; returns the label file."""
    out_dir = Path(out_dir)
    rows = []
    for number, (_, category, score, boxes) in enumerate(tracks):
        for k, box in boxes.items():
            lidar = _to_frame(box, invert_transform(world_from_lidar[k]))
            hwl, xyz, ry = lidar_to_kitti_boxes(lidar[None], KITTI_CAMERA_FROM_LIDAR)
            x, y, z = xyz[0]
            alpha = wrap_angle(ry[0] - np.arctan2(x, z))
            h, w, length = hwl[0]
            rows.append((k, number, f"{k} {number} {category} 0 0 {alpha:.6f} -1 -1 -1 -1 {h:.6f} {w:.6f} "
                                    f"{length:.6f} {x:.6f} {y:.6f} {z:.6f} {wrap_angle(ry[0]):.6f} {score:.6f}"))
    rows.sort(key=lambda r: (r[0], r[1]))
    label = out_dir / "label_02" / f"{sequence_number:04d}.txt"
    write_text(label, "".join(r[2] + "\n" for r in rows))
    identity = "1 0 0 0 0 1 0 0 0 0 1 0"
    velo = " ".join(f"{v:.6e}" for v in KITTI_CAMERA_FROM_LIDAR[:3].ravel())
    calib = [f"P{i}: {identity}" for i in range(4)] + ["R0_rect: 1 0 0 0 1 0 0 0 1", f"Tr_velo_to_cam: {velo}",
                                                      f"Tr_imu_to_velo: {identity}"]
    write_text(out_dir / "calib" / f"{sequence_number:04d}.txt", "\n".join(calib) + "\n")
    return label


def write_av2_annotations(path: str | Path, tracks: list[LabelTrack], world_from_ego: list[np.ndarray],
                          timestamps_ns: list[int], sequence_id: str,
                          interior_points: Mapping[tuple[str, int], int] | None = None) -> Path:
    """An AV2 ``annotations.feather`` of ``tracks`` (boxes in the ego frame of each sweep)."""
    import pyarrow as pa
    import pyarrow.feather as feather

    cols: dict[str, list] = {name: [] for name in ("timestamp_ns", "track_uuid", "category", "length_m", "width_m",
                                                   "height_m", "qw", "qx", "qy", "qz", "tx_m", "ty_m", "tz_m",
                                                   "num_interior_pts")}
    for track_id, category, _, boxes in tracks:
        track_uuid = str(uuid.uuid5(uuid.NAMESPACE_URL, f"sot-apps:{sequence_id}:{track_id}"))
        for k in sorted(boxes):
            b = _to_frame(boxes[k], invert_transform(world_from_ego[k]))
            cols["timestamp_ns"].append(int(timestamps_ns[k]))
            cols["track_uuid"].append(track_uuid)
            cols["category"].append(category)
            cols["length_m"].append(float(b[4]))
            cols["width_m"].append(float(b[5]))
            cols["height_m"].append(float(b[6]))
            cols["qw"].append(float(np.cos(b[3] / 2)))
            cols["qx"].append(0.0)
            cols["qy"].append(0.0)
            cols["qz"].append(float(np.sin(b[3] / 2)))
            cols["tx_m"].append(float(b[0]))
            cols["ty_m"].append(float(b[1]))
            cols["tz_m"].append(float(b[2]))
            cols["num_interior_pts"].append(int((interior_points or {}).get((track_id, k), 0)))
    types = {"timestamp_ns": pa.int64(), "track_uuid": pa.string(), "category": pa.string(),
             "num_interior_pts": pa.int64()}
    table = pa.table({name: pa.array(values, type=types.get(name, pa.float64())) for name, values in cols.items()})
    path = Path(path)
    with atomic_path(path) as tmp:
        feather.write_feather(table, str(tmp))
    return path
