"""Detection files in, converted to the project's box convention (WORLD frame, heading of the length axis).

Three formats (``read_detections`` picks one from the content unless ``format`` is given):

- ``json``: the project's ``detections`` schema (data_schema/detections.schema.json): world boxes per frame.
- ``kitti``: KITTI label text with a score column: a tracking file (``frame track_id type trunc occ alpha
  l t r b h w l x y z rotation_y [score]``, frame numbers are our frame indices) or a directory of object
  files ``NNNNNN.txt`` (``type trunc occ alpha l t r b h w l x y z rotation_y [score]``, one file per frame).
  KITTI's convention (../shared/data/readers/kitti_tracking_labels/SOURCE.md): x y z is the BOTTOM centre in
  the rectified camera frame, rotation_y turns about camera +y with 0 = length along camera +x. The camera
  frame comes from a KITTI calib file (``R0_rect`` / ``R_rect`` and ``Tr_velo_to_cam`` / ``Tr_velo_cam``);
  without one, the camera sits at the LiDAR origin with KITTI's ideal axes (x right = -y_lidar, y down =
  -z_lidar, z forward = x_lidar). A missing score column means score 1. DontCare lines are skipped.
- ``nuscenes``: the nuScenes detection results JSON (``{"results": {sample_token: [{translation, size,
  rotation, detection_name, detection_score, ...}]}}``): translation = box centre in the global frame, size =
  (width, length, height), rotation = quaternion (w, x, y, z). The global frame is our world frame; a
  sample token is a frame index ("12") unless ``frame_tokens`` lists the sequence's tokens in frame order.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any
from typing import Sequence as Seq

import numpy as np

from tracker.detection import Detections, FrameDetections
from tracker.geometry import invert_transform, transform_points, wrap_angle

from ..errors import InputError
from ..schemas import load_json, validate
from .atomic import write_json

__all__ = ["DETECTION_FORMATS", "detect_detection_format", "read_detections", "read_kitti_calib",
           "KITTI_CAMERA_FROM_LIDAR", "kitti_to_lidar_boxes", "detections_to_json",
           "write_detections", "boxes_to_frame", "read_sequence_detections"]

DETECTION_FORMATS = ("json", "kitti", "nuscenes")

# KITTI's camera axes (x right, y down, z forward) for a LiDAR with x forward, y left, z up, same origin
KITTI_CAMERA_FROM_LIDAR = np.array([[0.0, -1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [1.0, 0.0, 0.0, 0.0],
                                    [0.0, 0.0, 0.0, 1.0]])


def detect_detection_format(path: str | Path) -> str:
    """``json``, ``kitti`` or ``nuscenes`` from the file's content (a directory is KITTI object files)."""
    path = Path(path)
    if not path.exists():
        raise InputError(path, "no such file or directory")
    if path.is_dir():
        return "kitti"
    if path.suffix.lower() == ".json":
        doc = load_json(path)
        if isinstance(doc, dict) and "results" in doc:
            return "nuscenes"
        return "json"
    return "kitti"


# ------------------------------------------------------------------------------------------- KITTI

def read_kitti_calib(path: str | Path) -> np.ndarray:
    """``rect_from_lidar`` (4x4: R0_rect @ Tr_velo_to_cam) of a KITTI calib file; both key spellings."""
    path = Path(path)
    values: dict[str, np.ndarray] = {}
    try:
        text = path.read_text()
    except OSError as exc:
        raise InputError(path, f"cannot read calib ({exc.strerror})") from exc
    for line in text.replace("\r", "\n").splitlines():
        if ":" not in line:
            continue
        key, _, rest = line.partition(":")
        try:
            values[key.strip()] = np.array([float(v) for v in rest.split()])
        except ValueError as exc:
            raise InputError(path, f"calib key {key.strip()}: not numbers") from exc
    rect = values.get("R0_rect", values.get("R_rect"))
    velo = values.get("Tr_velo_to_cam", values.get("Tr_velo_cam"))
    if velo is None or velo.size != 12:
        raise InputError(path, "calib needs Tr_velo_to_cam (or Tr_velo_cam) with 12 numbers")
    cam_from_lidar = np.eye(4)
    cam_from_lidar[:3, :] = velo.reshape(3, 4)
    rect_from_cam = np.eye(4)
    if rect is not None:
        if rect.size != 9:
            raise InputError(path, "calib R0_rect (or R_rect) needs 9 numbers")
        rect_from_cam[:3, :3] = rect.reshape(3, 3)
    return rect_from_cam @ cam_from_lidar


def kitti_to_lidar_boxes(hwl: np.ndarray, xyz_bottom: np.ndarray, rotation_y: np.ndarray,
                         rect_from_lidar: np.ndarray = KITTI_CAMERA_FROM_LIDAR) -> np.ndarray:
    """(N, 7) LiDAR-frame boxes [x, y, z (centre), heading, l, w, h] from KITTI camera-frame values."""
    hwl = np.asarray(hwl, dtype=np.float64).reshape(-1, 3)
    lidar_from_rect = invert_transform(rect_from_lidar)
    bottom = transform_points(lidar_from_rect, xyz_bottom)
    ry = np.asarray(rotation_y, dtype=np.float64).reshape(-1)
    forward_cam = np.stack([np.cos(ry), np.zeros_like(ry), -np.sin(ry)], axis=1)  # length axis (rotation about +y)
    forward = forward_cam @ lidar_from_rect[:3, :3].T
    heading = np.arctan2(forward[:, 1], forward[:, 0])
    centre = bottom + np.outer(hwl[:, 0] / 2.0, [0.0, 0.0, 1.0])  # upright box: half its height above the bottom
    return np.column_stack([centre, heading, hwl[:, 2], hwl[:, 1], hwl[:, 0]])


def _parse_kitti_lines(path: Path, text: str, has_frame: bool, frame: int | None) -> list[tuple[int, str, list[float]]]:
    rows = []
    base = 17 if has_frame else 15
    for number, line in enumerate(text.splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        if len(parts) not in (base, base + 1):
            raise InputError(path, f"line {number}: {len(parts)} fields, expected {base} or {base + 1} (with score)")
        try:
            k = int(parts[0]) if has_frame else int(frame)  # type: ignore[arg-type]
            label = parts[2] if has_frame else parts[0]
            numbers = [float(v) for v in parts[(3 if has_frame else 1):]]
        except ValueError as exc:
            raise InputError(path, f"line {number}: not a KITTI label line ({exc})") from exc
        if label == "DontCare":
            continue
        rows.append((k, label, numbers))
    return rows


def _text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path, f"cannot read as text ({exc})") from exc


def _read_kitti(path: Path, world_from_lidar: Seq[np.ndarray], rect_from_lidar: np.ndarray) -> dict[int, FrameDetections]:
    rows: list[tuple[int, str, list[float]]] = []
    if path.is_dir():
        files = sorted(path.glob("*.txt"))
        if not files:
            raise InputError(path, "no KITTI label files (NNNNNN.txt) in the directory")
        for f in files:
            if not f.stem.isdigit():
                raise InputError(f, "KITTI object file names are frame numbers (000012.txt)")
            rows += _parse_kitti_lines(f, _text(f), False, int(f.stem))
    else:
        rows = _parse_kitti_lines(path, _text(path), True, None)
    by_frame: dict[int, list[tuple[str, list[float]]]] = {}
    for k, label, numbers in rows:
        by_frame.setdefault(k, []).append((label, numbers))
    out: dict[int, FrameDetections] = {}
    for k, items in sorted(by_frame.items()):
        _check_frame(path, k, len(world_from_lidar))
        vals = np.array([n[:14] for _, n in items])  # trunc occ alpha (bbox x4) h w l x y z rotation_y
        scores = np.array([n[14] if len(n) > 14 else 1.0 for _, n in items])
        if np.any(vals[:, 7:10] <= 0) or not np.isfinite(vals).all():
            raise InputError(path, f"frame {k}: box sizes must be positive and values finite")
        boxes = kitti_to_lidar_boxes(vals[:, 7:10], vals[:, 10:13], vals[:, 13], rect_from_lidar)
        out[k] = boxes_to_frame(_lidar_to_world(boxes, world_from_lidar[k]), scores, tuple(lbl for lbl, _ in items))
    return out


# ---------------------------------------------------------------------------------------- nuScenes

def _quaternion_yaw(q: np.ndarray) -> np.ndarray:
    """Yaw (angle of the rotated +x from +x in the xy plane) of (N, 4) quaternions (w, x, y, z)."""
    w, x, y, z = q.T
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _read_nuscenes(path: Path, doc: Any, n_frames: int, frame_tokens: Seq[str] | None) -> dict[int, FrameDetections]:
    results = doc.get("results") if isinstance(doc, dict) else None
    if not isinstance(results, dict):
        raise InputError(path, "nuScenes results: expected an object with 'results': {sample_token: [boxes]}")
    index = {str(t): k for k, t in enumerate(frame_tokens)} if frame_tokens is not None else None
    out: dict[int, FrameDetections] = {}
    for token, items in results.items():
        if index is not None:
            if token not in index:
                raise InputError(path, f"sample token {token!r} is not a frame of the sequence")
            k = index[token]
        elif str(token).isdigit():
            k = int(token)
        else:
            raise InputError(path, f"sample token {token!r}: give the sequence's tokens (frame_tokens) or use frame "
                                   "indices as tokens")
        _check_frame(path, k, n_frames)
        try:
            t = np.array([d["translation"] for d in items], dtype=np.float64).reshape(-1, 3)
            wlh = np.array([d["size"] for d in items], dtype=np.float64).reshape(-1, 3)
            q = np.array([d["rotation"] for d in items], dtype=np.float64).reshape(-1, 4)
            scores = np.array([d["detection_score"] for d in items], dtype=np.float64)
            labels = tuple(str(d.get("detection_name", "")) for d in items)
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(path, f"sample {token}: a box needs translation[3], size[3], rotation[4] and "
                                   f"detection_score ({exc})") from exc
        if np.any(wlh <= 0) or not np.isfinite(np.concatenate([t.ravel(), wlh.ravel(), q.ravel(), scores])).all():
            raise InputError(path, f"sample {token}: sizes must be positive and values finite")
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
        boxes = np.column_stack([t, _quaternion_yaw(q), wlh[:, 1], wlh[:, 0], wlh[:, 2]])
        out[k] = boxes_to_frame(boxes, scores, labels)
    return out


# ----------------------------------------------------------------------------------- our JSON

def _read_json(path: Path, doc: Any, n_frames: int) -> dict[int, FrameDetections]:
    validate("detections", doc, path)
    out: dict[int, FrameDetections] = {}
    for entry in doc["frames"]:
        k = int(entry["frame"])
        _check_frame(path, k, n_frames)
        boxes = np.array([[b["x"], b["y"], b["z"], b["heading"], b["length"], b["width"], b["height"]]
                          for b in entry["boxes"]], dtype=np.float64).reshape(-1, 7)
        scores = np.array([b.get("score", 1.0) for b in entry["boxes"]], dtype=np.float64)
        labels = tuple(str(b.get("label", "")) for b in entry["boxes"])
        if k in out:
            old = out[k]
            boxes, scores = np.vstack([old.boxes, boxes]), np.concatenate([old.scores, scores])
            labels = old.labels + labels
        out[k] = boxes_to_frame(boxes, scores, labels)
    return out


def detections_to_json(detections: Detections, sequence_id: str | None = None) -> dict[str, Any]:
    """The ``detections`` schema document of ``detections`` (frames in order)."""
    frames = []
    for k in sorted(detections):
        det = detections[k]
        boxes = []
        for i, b in enumerate(det.boxes):
            entry: dict[str, Any] = dict(zip(("x", "y", "z", "heading", "length", "width", "height"),
                                             (float(v) for v in b), strict=True))
            entry["score"] = float(np.clip(det.scores[i], 0.0, 1.0))
            if det.labels and det.labels[i]:
                entry["label"] = det.labels[i]
            boxes.append(entry)
        frames.append({"frame": int(k), "boxes": boxes})
    doc: dict[str, Any] = {"version": 1}
    if sequence_id:
        doc["sequence"] = sequence_id
    doc["frames"] = frames
    return doc


def write_detections(path: str | Path, detections: Detections, sequence_id: str | None = None) -> Path:
    """Write ``detections`` as a ``detections`` schema file (atomically, validated)."""
    doc = detections_to_json(detections, sequence_id)
    validate("detections", doc, path)
    write_json(path, doc)
    return Path(path)


# ------------------------------------------------------------------------------------------ common

def boxes_to_frame(boxes: np.ndarray, scores: np.ndarray, labels: tuple[str, ...] = ()) -> FrameDetections:
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 7).copy()
    boxes[:, 3] = wrap_angle(boxes[:, 3]) if len(boxes) else boxes[:, 3]
    return FrameDetections(boxes, np.asarray(scores, dtype=np.float64), labels)


def _lidar_to_world(boxes: np.ndarray, world_from_lidar: np.ndarray) -> np.ndarray:
    out = boxes.copy()
    out[:, :3] = transform_points(world_from_lidar, boxes[:, :3])
    out[:, 3] = boxes[:, 3] + np.arctan2(world_from_lidar[1, 0], world_from_lidar[0, 0])
    return out


def _check_frame(path: Path, k: int, n_frames: int) -> None:
    if not 0 <= k < n_frames:
        raise InputError(path, f"detections for frame {k}, but the sequence has frames 0..{n_frames - 1}")


def read_detections(path: str | Path, world_from_lidar: Seq[np.ndarray], format: str | None = None,
                    kitti_calib: str | Path | np.ndarray | None = None,
                    frame_tokens: Seq[str] | None = None) -> dict[int, FrameDetections]:
    """Detections of a sequence (one ``world_from_lidar`` 4x4 per frame) as WORLD boxes per frame index.

    ``kitti_calib``: a KITTI calib file or a ``rect_from_lidar`` 4x4 (default: KITTI's ideal axes at the
    LiDAR origin). ``frame_tokens``: the nuScenes sample token of each frame (default: tokens are indices).
    Bad content: InputError naming the file.
    """
    path = Path(path)
    fmt = format or detect_detection_format(path)
    n = len(world_from_lidar)
    if fmt == "kitti":
        if kitti_calib is None:
            rect = KITTI_CAMERA_FROM_LIDAR
        elif isinstance(kitti_calib, np.ndarray):
            rect = kitti_calib
        else:
            rect = read_kitti_calib(kitti_calib)
        if not path.exists():
            raise InputError(path, "no such file or directory")
        return _read_kitti(path, world_from_lidar, rect)
    if fmt == "nuscenes":
        return _read_nuscenes(path, load_json(path), n, frame_tokens)
    if fmt == "json":
        return _read_json(path, load_json(path), n)
    raise InputError(path, f"unknown detections format {fmt!r}; known: {', '.join(DETECTION_FORMATS)}")


def read_sequence_detections(path: str | Path, sequence: Any, format: str | None = None,
                             kitti_calib: str | Path | None = None) -> dict[int, FrameDetections]:
    """:func:`read_detections` for a :class:`~sot_apps.io.sequence.Sequence` (its poses and LiDAR mount)."""
    world_from_lidar = [np.asarray(f.world_from_ego) @ np.asarray(sequence.ego_from_lidar) for f in sequence.frames]
    return read_detections(path, world_from_lidar, format, kitti_calib)
