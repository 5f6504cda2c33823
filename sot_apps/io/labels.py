"""Writers of box labels (tracks of world-frame boxes per frame) in the formats official tools read.

One writer per format, shared by ``sot-apps convert --labels`` (a sequence's annotations) and
``sot-apps autolabel`` (auto-labels, with scores):

- :func:`write_kitti_tracking`: KITTI tracking ``label_02/NNNN.txt`` + ``calib/NNNN.txt``. The label frame
  is the chosen camera's frame (:func:`kitti_camera`: KITTI's camera 2, else the dataset's front camera by
  name, else the camera looking most along ego +x): ``P0..P3`` = [K | 0], ``R0_rect`` = identity, ``Tr_velo_to_cam`` = camera_from_lidar,
  ``Tr_imu_to_velo`` = lidar_from_ego. Each box becomes KITTI's (bottom centre, h w l, rotation_y about the
  camera's y); its 2D box is the 8 corners of that 3D box projected with P2 (the part in front of the
  camera, z >= 0.1 m), bounded and clipped to the image [0, width - 1] x [0, height - 1] as KITTI's are; a box
  whose projection misses the image is not written (KITTI labels only what the camera sees). ``truncated``
  (0/1/2, KITTI tracking's integer levels) is 0 when the projection lies inside the image, 2 when more than
  half its area is outside, else 1; ``occluded`` is 0 (unknown to us). With scores, an 18th column.
  Track ids that are all integers (a KITTI source) are kept; otherwise tracks are numbered 0, 1, ... in order.
- :func:`write_av2_annotations`: Argoverse 2 sensor ``annotations.feather`` (timestamp_ns int64,
  track_uuid, category, length_m .. tz_m float64, num_interior_pts int64), boxes in the EGO frame of each
  frame with their full rotation, AV2 category names (:mod:`.categories`), ``num_interior_pts`` counted
  from the frame's sweep (a frame without a sweep: the source's own count, else 0). Track ids that are
  UUIDs are kept; others become uuid5(sequence id, track id).
- :func:`write_av2_submission`: the AV2 3D detection submission table (tx_m .. qz, score, log_id,
  timestamp_ns, category), what ``av2.evaluation.detection.eval.evaluate`` takes as detections.

Boxes whose label has no name in the target format are left out; the writers return how many.
"""

from __future__ import annotations

import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tracker.geometry import Box, invert_transform, points_in_box, wrap_angle

from .atomic import atomic_path, write_text
from .categories import av2_category, kitti_type
from .object_track import ObjectTrack
from .sequence import Camera, Sequence

__all__ = ["LabelsWritten", "kitti_camera", "kitti_label_box",
           "kitti_box_corners", "image_box", "KITTI_CAMERA_NAMES", "write_kitti_tracking", "write_av2_annotations", "write_av2_submission",
           "AV2_ANNOTATION_COLUMNS", "AV2_SUBMISSION_COLUMNS"]

AV2_ANNOTATION_COLUMNS = ("timestamp_ns", "track_uuid", "category", "length_m", "width_m", "height_m", "qw", "qx",
                          "qy", "qz", "tx_m", "ty_m", "tz_m", "num_interior_pts")
AV2_SUBMISSION_COLUMNS = ("tx_m", "ty_m", "tz_m", "length_m", "width_m", "height_m", "qw", "qx", "qy", "qz", "score",
                          "log_id", "timestamp_ns", "category")
NEAR_M = 0.1   # the part of a box nearer the camera plane than this is cut off before projecting


@dataclass(frozen=True)
class LabelsWritten:
    path: Path
    boxes: int                       # rows written
    unmapped: dict[str, int]         # label -> boxes left out (no name in the format)
    outside_camera: int = 0          # KITTI: boxes the camera does not see


# ------------------------------------------------------------------------------------------ KITTI

# KITTI's camera 2, then the datasets' front cameras (PandaSet / synth, AV2, Waymo, nuScenes): PandaSet's ego
# frame looks along +y, so the direction alone does not find the front camera
KITTI_CAMERA_NAMES = ("image_02", "image_2", "front_camera", "ring_front_center", "FRONT", "CAM_FRONT")


def kitti_camera(seq: Sequence) -> Camera | None:
    """The camera KITTI labels are written for: the first of :data:`KITTI_CAMERA_NAMES` the sequence has, else
    the camera whose optical axis points most along ego +x; None without a camera with a pose."""
    for name in KITTI_CAMERA_NAMES:
        if name in seq.cameras:
            return seq.cameras[name]
    best, best_dot = None, -np.inf
    for cam in seq.cameras.values():
        if cam.ego_from_camera is None and not cam.frames:
            continue  # no pose: cannot be used
        axis = _ego_from_camera(seq, cam)[:3, 2]
        if axis[0] > best_dot:
            best, best_dot = cam, axis[0]
    return best


def _ego_from_camera(seq: Sequence, cam: Camera) -> np.ndarray:
    """The camera's mounting; a camera posed per image gets its first image's pose relative to the ego."""
    if cam.ego_from_camera is not None:
        return np.asarray(cam.ego_from_camera)
    return invert_transform(seq.frames[0].world_from_ego) @ np.asarray(cam.frames[0].world_from_camera)


def kitti_label_box(box_camera: Box) -> tuple[float, float, float, float, float, float, float]:
    """(h, w, l, x, y, z, rotation_y) of a box given in camera axes (x right, y down, z forward): (x, y, z) is
    the bottom centre, rotation_y the angle about +y that takes +x to the length axis' projection."""
    direction = box_camera.rotation()[:, 0]
    ry = float(wrap_angle(np.arctan2(-direction[2], direction[0])))
    return (box_camera.height, box_camera.width, box_camera.length, box_camera.x, box_camera.y + box_camera.height / 2,
            box_camera.z, ry)


def kitti_box_corners(h: float, w: float, l: float, x: float, y: float, z: float, ry: float) -> np.ndarray:
    """(8, 3) corners of a KITTI label box in camera coordinates (the devkit's compute_box_3d)."""
    xs = np.array([l, l, -l, -l, l, l, -l, -l]) / 2
    ys = np.array([0, 0, 0, 0, -h, -h, -h, -h], dtype=np.float64)
    zs = np.array([w, -w, -w, w, w, -w, -w, w]) / 2
    c, s = np.cos(ry), np.sin(ry)
    return np.stack([c * xs + s * zs + x, ys + y, -s * xs + c * zs + z], axis=1)


_EDGES = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4], [0, 4], [1, 5], [2, 6], [3, 7]])


def image_box(corners_camera: np.ndarray, K: np.ndarray, width: int, height: int
              ) -> tuple[np.ndarray, np.ndarray] | None:
    """(clipped [left, top, right, bottom], unclipped box) of the projection of a box's corners (camera axes),
    cut at z = NEAR_M; None when nothing of it is in front of the camera or its projection misses the image."""
    z = corners_camera[:, 2]
    front = corners_camera[z >= NEAR_M]
    a, b = corners_camera[_EDGES[:, 0]], corners_camera[_EDGES[:, 1]]
    crossing = (a[:, 2] - NEAR_M) * (b[:, 2] - NEAR_M) < 0
    t = (NEAR_M - a[crossing, 2]) / (b[crossing, 2] - a[crossing, 2])
    points = np.vstack([front, a[crossing] + t[:, None] * (b[crossing] - a[crossing])])
    if len(points) == 0:
        return None
    uvw = points @ np.asarray(K, dtype=np.float64).T
    uv = uvw[:, :2] / uvw[:, 2:3]
    raw = np.array([uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()])
    right, bottom = width - 1, height - 1   # KITTI's boxes end at the last pixel (1241, 374 in 1242 x 375)
    clipped = np.array([np.clip(raw[0], 0, right), np.clip(raw[1], 0, bottom),
                        np.clip(raw[2], 0, right), np.clip(raw[3], 0, bottom)])
    if clipped[2] <= clipped[0] or clipped[3] <= clipped[1]:
        return None
    return clipped, raw


def _truncation(clipped: np.ndarray, raw: np.ndarray) -> int:
    area = (raw[2] - raw[0]) * (raw[3] - raw[1])
    inside = (clipped[2] - clipped[0]) * (clipped[3] - clipped[1])
    if inside >= area * (1 - 1e-9):
        return 0
    return 2 if inside < 0.5 * area else 1


def _kitti_rows(seq: Sequence, tracks: list[ObjectTrack], cam: Camera, camera_from_ego: np.ndarray
                ) -> tuple[list[tuple[int, int, str]], dict[str, int], int]:
    rows, unmapped, outside = [], {}, 0
    K = np.asarray(cam.K, dtype=np.float64)
    camera_from_world = [camera_from_ego @ invert_transform(f.world_from_ego) for f in seq.frames]
    numeric = all(t.object_id.isdigit() for t in tracks)   # KITTI's own ids are kept, others are numbered
    for n, track in enumerate(tracks):
        number = int(track.object_id) if numeric else n
        kind = kitti_type(track.label)
        if kind is None:
            unmapped[track.label] = unmapped.get(track.label, 0) + len(track.boxes)
            continue
        for i, k in enumerate(track.frames.tolist()):
            box = track.box(i)
            h, w, length, x, y, z, ry = kitti_label_box(box.transformed(camera_from_world[k], keep_tilt=True))
            projected = image_box(kitti_box_corners(h, w, length, x, y, z, ry), K, cam.width, cam.height)
            if projected is None:
                outside += 1
                continue
            (left, top, right, bottom), raw = projected
            alpha = wrap_angle(ry - np.arctan2(x, z))
            line = (f"{k} {number} {kind} {_truncation(projected[0], raw)} 0 {alpha:.6f} {left:.6f} {top:.6f} "
                    f"{right:.6f} {bottom:.6f} {h:.6f} {w:.6f} {length:.6f} {x:.6f} {y:.6f} {z:.6f} {ry:.6f}")
            if track.scores is not None:
                line += f" {track.scores[i]:.6f}"
            rows.append((k, number, line))
    rows.sort(key=lambda r: (r[0], r[1]))
    return rows, unmapped, outside


def write_kitti_tracking(out_dir: str | Path, seq: Sequence, tracks: list[ObjectTrack], sequence_number: int = 0,
                         camera: Camera | None = None) -> LabelsWritten:
    """``out_dir/label_02/NNNN.txt`` and ``out_dir/calib/NNNN.txt`` (see the module docstring).

    ``camera`` defaults to :func:`kitti_camera`; ValueError if the sequence has none (KITTI's 2D boxes need one).
    """
    out_dir = Path(out_dir)
    cam = camera or kitti_camera(seq)
    if cam is None:
        raise ValueError("KITTI labels need a camera for their 2D boxes and the sequence has none")
    ego_from_camera = _ego_from_camera(seq, cam)
    camera_from_ego = invert_transform(ego_from_camera)
    rows, unmapped, outside = _kitti_rows(seq, tracks, cam, camera_from_ego)
    label = out_dir / "label_02" / f"{sequence_number:04d}.txt"
    write_text(label, "".join(r[2] + "\n" for r in rows))
    projection = np.hstack([np.asarray(cam.K, dtype=np.float64), np.zeros((3, 1))])
    ego_from_lidar = np.asarray(seq.ego_from_lidar, dtype=np.float64)
    camera_from_lidar = camera_from_ego @ ego_from_lidar

    def numbers(matrix: np.ndarray) -> str:
        return " ".join(f"{v:.12e}" for v in np.asarray(matrix).ravel())

    calib = [f"P{i}: {numbers(projection)}" for i in range(4)] + [
        f"R0_rect: {numbers(np.eye(3))}", f"Tr_velo_to_cam: {numbers(camera_from_lidar[:3])}",
        f"Tr_imu_to_velo: {numbers(invert_transform(ego_from_lidar)[:3])}"]
    write_text(out_dir / "calib" / f"{sequence_number:04d}.txt", "\n".join(calib) + "\n")
    return LabelsWritten(label, len(rows), unmapped, outside)


# -------------------------------------------------------------------------------------------- AV2

def _track_uuid(sequence_id: str, track_id: str) -> str:
    try:
        return str(uuid.UUID(track_id))
    except ValueError:
        return str(uuid.uuid5(uuid.NAMESPACE_URL, f"sot-apps:{sequence_id}:{track_id}"))


def _quaternion_wxyz(rotation: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(rotation).as_quat()
    q = np.array([w, x, y, z])
    return -q if w < 0 else q


def _av2_rows(seq: Sequence, tracks: list[ObjectTrack], count_points: bool) -> tuple[dict[str, list], dict[str, int]]:
    """Columns of the AV2 rows (ego-frame boxes), sorted by time then track; ``num_interior_pts`` when asked."""
    entries, unmapped = [], {}
    for track in tracks:
        category = av2_category(track.label)
        if category is None:
            unmapped[track.label] = unmapped.get(track.label, 0) + len(track.boxes)
            continue
        for i, k in enumerate(track.frames.tolist()):
            entries.append((k, _track_uuid(seq.id, track.object_id), category, track, i))
    entries.sort(key=lambda e: (e[0], e[1]))
    cols: dict[str, list] = {name: [] for name in AV2_ANNOTATION_COLUMNS + ("score",)}
    sweep_frame, sweep_xyz = None, None
    for k, track_uuid, category, track, i in entries:
        ego = track.box(i).transformed(invert_transform(seq.frames[k].world_from_ego), keep_tilt=True)
        q = _quaternion_wxyz(ego.rotation())
        for name, value in zip(("timestamp_ns", "track_uuid", "category", "length_m", "width_m", "height_m", "qw", "qx",
                                "qy", "qz", "tx_m", "ty_m", "tz_m"),
                               (int(seq.frames[k].timestamp_ns), track_uuid, category, ego.length, ego.width, ego.height,
                                *q, ego.x, ego.y, ego.z), strict=True):
            cols[name].append(value)
        cols["score"].append(float(track.scores[i]) if track.scores is not None else 1.0)
        if count_points:
            if seq.frames[k].has_sweep:
                if sweep_frame != k:
                    sweep_frame, sweep_xyz = k, seq.sweep(k).xyz
                cols["num_interior_pts"].append(int(points_in_box(sweep_xyz, ego).sum()))
            else:
                count = -1 if track.num_points is None else int(track.num_points[i])
                cols["num_interior_pts"].append(max(count, 0))   # -1: the source has no count
    return cols, unmapped


def _write_feather(path: Path, columns: dict[str, Any]) -> None:
    import pyarrow as pa
    import pyarrow.feather as feather

    with atomic_path(path) as tmp:
        feather.write_feather(pa.table(columns), str(tmp))


def write_av2_annotations(path: str | Path, seq: Sequence, tracks: list[ObjectTrack]) -> LabelsWritten:
    """An AV2 ``annotations.feather`` of ``tracks`` (see the module docstring)."""
    import pyarrow as pa

    cols, unmapped = _av2_rows(seq, tracks, count_points=True)
    types = {"timestamp_ns": pa.int64(), "track_uuid": pa.string(), "category": pa.string(),
             "num_interior_pts": pa.int64()}
    path = Path(path)
    _write_feather(path, {name: pa.array(cols[name], type=types.get(name, pa.float64()))
                          for name in AV2_ANNOTATION_COLUMNS})
    return LabelsWritten(path, len(cols["timestamp_ns"]), unmapped)


def write_av2_submission(path: str | Path, seq: Sequence, tracks: list[ObjectTrack]) -> LabelsWritten:
    """The AV2 detection submission table of ``tracks`` (``score`` = the track's score, 1 without one)."""
    import pyarrow as pa

    cols, unmapped = _av2_rows(seq, tracks, count_points=False)
    cols["log_id"] = [seq.id] * len(cols["timestamp_ns"])
    types = {"timestamp_ns": pa.int64(), "log_id": pa.string(), "category": pa.string()}
    path = Path(path)
    _write_feather(path, {name: pa.array(cols[name], type=types.get(name, pa.float64()))
                          for name in AV2_SUBMISSION_COLUMNS})
    return LabelsWritten(path, len(cols["timestamp_ns"]), unmapped)
