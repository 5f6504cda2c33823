"""KITTI readers: the tracking layout (one sequence) and the object layout (single frames, e.g. View-of-Delft).

Tracking layout (``training/`` or ``testing/``)::

    velodyne/SSSS/NNNNNN.bin   float32 x, y, z, reflectance (velodyne frame)
    label_02/SSSS.txt          frame track_id type truncated occluded alpha l t r b h w l x y z rotation_y [score]
    calib/SSSS.txt             P0..P3, R0_rect | R_rect, Tr_velo_to_cam | Tr_velo_cam, Tr_imu_to_velo | Tr_imu_velo
    oxts/SSSS.txt              30 values per frame: lat lon alt roll pitch yaw ... (GPS/IMU)
    image_02/SSSS/NNNNNN.png

A sequence is named by one of its files or folders (``label_02/0001.txt``, ``velodyne/0001``) or by
``training#0001``. Object layout: ``velodyne/NNNNNN.bin``, ``label_2/NNNNNN.txt``, ``calib/NNNNNN.txt``,
``image_2/NNNNNN.{png,jpg}`` and, for View-of-Delft, ``pose/NNNNNN.json``; every frame is one frame
of the sequence (the frames need not be consecutive).

Conversion to the project's conventions:

- the velodyne frame is the ego frame (``ego_from_lidar`` identity); points keep their reflectance
  as intensity; KITTI has no per-point times;
- tracking poses: each oxts line becomes the IMU pose in a local east/north/up world (Mercator
  projection with the scale cos(latitude of the first frame), rotation Rz(yaw) Ry(pitch) Rx(roll),
  origin at the first frame's IMU position); ``world_from_ego = world_from_imu @ inv(Tr_imu_to_velo)``.
  Without oxts every ``world_from_ego`` is the identity (the ego motion is unknown);
- frame times: frame number x 100 ms (the tracking and object releases give no timestamps);
- labels (rectified camera-0 frame, x right, y down, z forward): (x, y, z) is the bottom centre, so
  the centre is (x, y - h/2, z); ``velo_from_rect = inv(R0_rect @ Tr_velo_to_cam)``; the box is level in
  the rectified camera frame (up = -y), so in the velodyne frame it keeps that frame's small tilt: the
  heading is the yaw of the length direction (cos ry, 0, -sin ry), roll and pitch the rest (boxes go to
  the world with the full ego pose, as the other readers'); length, width, height =
  l, w, h; the track id column is the track id (object layout: ``NNNNNN-i``, no identity over
  frames); DontCare rows are dropped, but the frames they name are frames of the sequence (the
  devkit's sequence length is the label file's last frame + 1: 447 for 0001, whose frames 426-446 hold
  only DontCare rows; its seqmap says ``0001 empty 000000 000447``);
- View-of-Delft (object layout with ``pose/``): its rotation is about the lidar's -z axis, so the
  heading is ``-rotation - pi/2`` and the centre is ``inv(Tr_velo_to_cam) @ (x, y, z) + (0, 0, h/2)``;
  ``world_from_ego = odomToCamera @ Tr_velo_to_cam`` (the odometry frame; despite its name the
  matrix takes camera coordinates to odometry coordinates: only this way round is the world z up);
- camera ``image_02`` / ``image_2``: K = P2[:, :3], ``camera_from_ego = T(K^-1 P2[:, 3]) @ R0_rect @
  Tr_velo_to_cam`` (rotations re-orthonormalised), so K @ camera_from_ego reproduces P2 @ R0 @ Tr;
  images per frame only when every frame has one (else calibration only), image time = frame time.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from tracker.geometry import Box, invert_transform, make_transform, transform_points, wrap_angle, zyx_angles

from ..errors import InputError
from .convert_util import read_float32_records, read_text_lines, split_selector
from .sequence import BoxAnnotation, Camera, CameraFrame, FrameInfo, Sequence, Sweep

__all__ = ["kitti_tracking_parts", "is_kitti_object", "read_kitti_tracking", "read_kitti_object", "read_calib",
           "KittiCalib", "parse_label_line", "label_box_in_velo", "oxts_to_world_from_imu", "read_velodyne_bin",
           "FRAME_DT_NS"]

FRAME_DT_NS = 100_000_000  # KITTI and View-of-Delft record at 10 Hz
EARTH_RADIUS_M = 6378137.0
_KEY_SPELLINGS = {"R0_rect": ("R0_rect", "R_rect"), "Tr_velo_to_cam": ("Tr_velo_to_cam", "Tr_velo_cam"),
                  "Tr_imu_to_velo": ("Tr_imu_to_velo", "Tr_imu_velo"), "P2": ("P2",)}


# ------------------------------------------------------------------------------------------ files

def read_velodyne_bin(path: Path) -> Sweep:
    """A KITTI velodyne ``.bin`` (float32 x, y, z, reflectance)."""
    data = read_float32_records(path, 4)
    return Sweep(xyz=np.ascontiguousarray(data[:, :3]), intensity=np.ascontiguousarray(data[:, 3]))


class KittiCalib:
    """The matrices of a KITTI calib file (either spelling of the keys), as 4x4 / 3x4 arrays."""

    def __init__(self, values: dict[str, np.ndarray], path: Path) -> None:
        self.values = values
        self.path = path

    def get(self, key: str, required: bool = True) -> np.ndarray | None:
        for name in _KEY_SPELLINGS.get(key, (key,)):
            if name in self.values:
                return self.values[name]
        if required:
            raise InputError(self.path, f"calibration key {' / '.join(_KEY_SPELLINGS.get(key, (key,)))} is missing")
        return None

    @property
    def rect_from_velo(self) -> np.ndarray:
        """4x4 rectified-camera-0 from velodyne: R0_rect @ Tr_velo_to_cam (as stored)."""
        r0 = np.eye(4)
        r0[:3, :3] = self.get("R0_rect").reshape(3, 3)
        return r0 @ _rigid(self.get("Tr_velo_to_cam"), orthonormalise=False)

    @property
    def velo_from_imu(self) -> np.ndarray | None:
        tr = self.get("Tr_imu_to_velo", required=False)
        return None if tr is None else _rigid(tr, orthonormalise=True)

    def camera(self, name: str, width: int, height: int, frames: list[CameraFrame]) -> Camera:
        """Camera 2 (left colour) with P2: ego_from_camera such that K @ camera_from_ego = P2 @ R0 @ Tr."""
        p2 = self.get("P2").reshape(3, 4)
        K = p2[:, :3].copy()
        offset = np.linalg.solve(K, p2[:, 3])
        camera_from_velo = make_transform(np.eye(3), offset) @ _orthonormal(self.rect_from_velo)
        return Camera(name=name, K=K, distortion=np.zeros(5), width=width, height=height, frames=frames,
                      ego_from_camera=invert_transform(camera_from_velo))


def _orthonormal(transform: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(transform[:3, :3])
    out = transform.copy()
    out[:3, :3] = u @ vt
    return out


def _rigid(values: np.ndarray, orthonormalise: bool) -> np.ndarray:
    out = np.eye(4)
    out[:3, :] = values.reshape(3, 4)
    return _orthonormal(out) if orthonormalise else out


def read_calib(path: Path) -> KittiCalib:
    """Parse ``KEY: v1 v2 ...`` / ``KEY v1 v2 ...`` lines (empty values, as VoD's ``Tr_imu_to_velo:``, are absent)."""
    sizes = {"P": 12, "R": 9, "T": 12}
    values: dict[str, np.ndarray] = {}
    for n, line in enumerate(read_text_lines(path), start=1):
        parts = line.replace(":", " ", 1).split()
        if not parts:
            continue
        key, numbers = parts[0], parts[1:]
        if not numbers:
            continue
        try:
            array = np.array([float(v) for v in numbers])
        except ValueError as exc:
            raise InputError(path, f"line {n} ({key}): not a number ({exc})") from exc
        expected = sizes.get(key[0])
        if expected and key in {s for spellings in _KEY_SPELLINGS.values() for s in spellings} | {"P0", "P1", "P3"} \
                and len(array) != expected:
            raise InputError(path, f"line {n} ({key}): expected {expected} numbers, got {len(array)}")
        if not np.isfinite(array).all():
            raise InputError(path, f"line {n} ({key}): non-finite number")
        values[key] = array
    return KittiCalib(values, path)


def parse_label_line(line: str, path: Path, n: int, tracking: bool) -> dict | None:
    """One label line -> dict (frame, track_id, type, bbox, h, w, l, x, y, z, ry); None for DontCare."""
    parts = line.split()
    head = 2 if tracking else 0
    if len(parts) < head + 15:
        raise InputError(path, f"line {n}: expected {head + 15} fields ({'frame track_id ' if tracking else ''}type "
                               f"truncated occluded alpha bbox(4) h w l x y z rotation_y), got {len(parts)}")
    kind = parts[head]
    if kind == "DontCare":
        return None
    try:
        numbers = [float(v) for v in parts[head + 1:head + 15]]
        frame, track = (int(parts[0]), int(parts[1])) if tracking else (None, None)
    except ValueError as exc:
        raise InputError(path, f"line {n}: not a number ({exc})") from exc
    if not all(math.isfinite(v) for v in numbers):
        raise InputError(path, f"line {n}: non-finite number")
    h, w, l, x, y, z, ry = numbers[7:14]
    if min(h, w, l) <= 0:
        raise InputError(path, f"line {n}: box size h={h} w={w} l={l} must be positive")
    return {"frame": frame, "track_id": track, "type": kind, "bbox": numbers[3:7], "h": h, "w": w, "l": l,
            "x": x, "y": y, "z": z, "ry": ry}


def _label_frame(line: str, path: Path, n: int) -> int:
    """The frame number of a tracking label line (any type, DontCare included)."""
    try:
        frame = int(line.split()[0])
    except ValueError as exc:
        raise InputError(path, f"line {n}: frame number is not an integer ({exc})") from exc
    if frame < 0:
        raise InputError(path, f"line {n}: negative frame number {frame}")
    return frame


def label_box_in_velo(label: dict, calib: KittiCalib, vod: bool = False) -> Box:
    """The label's box in the velodyne (= ego) frame (conventions in the module docstring)."""
    velo_from_rect = invert_transform(calib.rect_from_velo) if not vod else invert_transform(
        _rigid(calib.get("Tr_velo_to_cam"), orthonormalise=False))
    h, w, l = label["h"], label["w"], label["l"]
    if vod:
        centre = transform_points(velo_from_rect, np.array([[label["x"], label["y"], label["z"]]]))[0] + [0.0, 0.0, h / 2]
        heading = -label["ry"] - math.pi / 2
        return Box(float(centre[0]), float(centre[1]), float(centre[2]), float(wrap_angle(heading)), l, w, h)
    centre = transform_points(velo_from_rect, np.array([[label["x"], label["y"] - h / 2, label["z"]]]))[0]
    # object axes in the rectified camera frame: length (cos ry, 0, -sin ry), left (sin ry, 0, cos ry), up -y
    c, s = math.cos(label["ry"]), math.sin(label["ry"])
    rect_from_object = np.array([[c, s, 0.0], [0.0, 0.0, -1.0], [-s, c, 0.0]])
    u, _, vt = np.linalg.svd(velo_from_rect[:3, :3] @ rect_from_object)   # R0_rect @ Tr is rigid only to ~1e-6
    heading, pitch, roll = zyx_angles(u @ vt)
    return Box(float(centre[0]), float(centre[1]), float(centre[2]), heading, l, w, h, roll=roll, pitch=pitch)


def oxts_to_world_from_imu(oxts: np.ndarray) -> np.ndarray:
    """(N, >=6) oxts rows (lat, lon, alt, roll, pitch, yaw, ...) -> (N, 4, 4) world_from_imu.

    World: east/north/up from the Mercator projection with the scale cos(lat_0), origin at frame 0.
    """
    lat, lon, alt, roll, pitch, yaw = (oxts[:, i] for i in range(6))
    scale = math.cos(math.radians(float(lat[0])))
    tx = scale * np.radians(lon) * EARTH_RADIUS_M
    ty = scale * EARTH_RADIUS_M * np.log(np.tan(np.radians(90.0 + lat) / 2.0))
    t = np.stack([tx, ty, alt], axis=1)
    t -= t[0]
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    out = np.tile(np.eye(4), (len(oxts), 1, 1))
    # Rz(yaw) @ Ry(pitch) @ Rx(roll)
    out[:, 0, 0], out[:, 0, 1], out[:, 0, 2] = cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr
    out[:, 1, 0], out[:, 1, 1], out[:, 1, 2] = sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr
    out[:, 2, 0], out[:, 2, 1], out[:, 2, 2] = -sp, cp * sr, cp * cr
    out[:, :3, 3] = t
    return out


def _read_oxts(path: Path) -> np.ndarray:
    rows = []
    for n, line in enumerate(read_text_lines(path), start=1):
        if not line.strip():
            continue
        try:
            row = [float(v) for v in line.split()]
        except ValueError as exc:
            raise InputError(path, f"line {n}: not a number ({exc})") from exc
        if len(row) < 6 or not all(math.isfinite(v) for v in row[:6]):
            raise InputError(path, f"line {n}: expected 30 numbers (lat lon alt roll pitch yaw ...), got {len(row)}")
        rows.append(row[:6])
    if not rows:
        raise InputError(path, "no oxts lines")
    return np.array(rows)


def _image_size(path: Path) -> tuple[int, int]:
    import cv2

    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise InputError(path, "cannot decode image")
    return int(image.shape[1]), int(image.shape[0])


def _numbered(directory: Path, suffixes: tuple[str, ...]) -> dict[int, Path]:
    if not directory.is_dir():
        return {}
    return {int(p.stem): p for p in directory.iterdir() if p.stem.isdigit() and p.suffix in suffixes}


def _camera_frames(images: dict[int, Path], frame_numbers: list[int], times: list[int],
                   world_from_ego: list[np.ndarray], ego_from_camera: np.ndarray) -> list[CameraFrame]:
    if not images or any(f not in images for f in frame_numbers):
        return []
    return [CameraFrame(timestamp_ns=t, image_path=images[f], world_from_camera=w @ ego_from_camera)
            for f, t, w in zip(frame_numbers, times, world_from_ego, strict=True)]


def _camera(calib: KittiCalib, name: str, images: dict[int, Path], frame_numbers: list[int], times: list[int],
            world_from_ego: list[np.ndarray]) -> Camera:
    width, height = _image_size(next(iter(images.values()))) if images else (1242, 375)
    cam = calib.camera(name, width, height, [])
    frames = _camera_frames(images, frame_numbers, times, world_from_ego, cam.ego_from_camera)
    return Camera(cam.name, cam.K, cam.distortion, cam.width, cam.height, frames, cam.ego_from_camera)


# ------------------------------------------------------------------------------------- tracking

def _tracking_sequences(root: Path) -> list[str]:
    names = {p.stem for p in (root / "label_02").glob("*.txt")} | {p.name for p in (root / "velodyne").glob("*")
                                                                    if p.is_dir()}
    return sorted(n for n in names if n.isdigit())


def kitti_tracking_parts(path: str | Path) -> tuple[Path, str | None] | None:
    """(layout root, sequence name or None) if ``path`` names a KITTI tracking sequence or layout, else None."""
    path, name = split_selector(path)
    if name is None and path.parent.name in ("label_02", "calib", "oxts", "velodyne") and path.stem.isdigit():
        root, name = path.parent.parent, path.stem
    else:
        root = path
    if not root.is_dir() or not (root / "calib").is_dir():
        return None
    if not ((root / "label_02").is_dir() or any(p.is_dir() for p in (root / "velodyne").glob("*"))):
        return None
    return root, name


def read_kitti_tracking(path: str | Path) -> Sequence:
    """Open one KITTI tracking sequence (``label_02/SSSS.txt``, ``velodyne/SSSS`` or ``DIR#SSSS``)."""
    parts = kitti_tracking_parts(path)
    if parts is None:
        raise InputError(path, "not a KITTI tracking layout (calib/ and label_02/ or velodyne/SSSS/)")
    root, name = parts
    if name is None:
        names = _tracking_sequences(root)
        if len(names) != 1:
            raise InputError(root, f"{len(names)} sequences ({', '.join(names[:8])}); name one: {root}#{names[0] if names else 'SSSS'}")
        name = names[0]
    calib = read_calib(root / "calib" / f"{name}.txt")
    sweeps = _numbered(root / "velodyne" / name, (".bin",))
    labels_path = root / "label_02" / f"{name}.txt"
    labels = []
    last_labelled = -1  # the last frame of the label file, DontCare rows included (they are frames too)
    if labels_path.is_file():
        for n, line in enumerate(read_text_lines(labels_path), start=1):
            if line.strip():
                label = parse_label_line(line, labels_path, n, tracking=True)
                if label is not None:
                    labels.append(label)
                last_labelled = max(last_labelled, _label_frame(line, labels_path, n))
    oxts_path = root / "oxts" / f"{name}.txt"
    oxts = _read_oxts(oxts_path) if oxts_path.is_file() else None
    last = max([*sweeps, last_labelled, -1 if oxts is None else len(oxts) - 1])
    if last < 0:
        raise InputError(root, f"sequence {name}: no velodyne files, labels or oxts")
    count = last + 1
    if oxts is not None:
        if len(oxts) < count:
            raise InputError(oxts_path, f"{len(oxts)} oxts lines but the sequence has {count} frames")
        velo_from_imu = calib.velo_from_imu
        if velo_from_imu is None:
            raise InputError(calib.path, "calibration key Tr_imu_to_velo / Tr_imu_velo is missing (needed with oxts)")
        world_from_ego = list(oxts_to_world_from_imu(oxts[:count]) @ invert_transform(velo_from_imu))
    else:
        world_from_ego = [np.eye(4) for _ in range(count)]
    times = [k * FRAME_DT_NS for k in range(count)]
    frames = [FrameInfo(index=k, timestamp_ns=times[k], world_from_ego=world_from_ego[k], points_path=sweeps.get(k),
                        has_sweep=k in sweeps) for k in range(count)]
    annotations = None
    if labels_path.is_file():
        annotations = [[] for _ in range(count)]
        for lab in labels:
            box = label_box_in_velo(lab, calib).transformed(world_from_ego[lab["frame"]], keep_tilt=True)
            annotations[lab["frame"]].append(BoxAnnotation(track_id=str(lab["track_id"]), label=lab["type"], box=box))
    images = _numbered(root / "image_02" / name, (".png", ".jpg"))
    cameras = {"image_02": _camera(calib, "image_02", images, list(range(count)), times, world_from_ego)}

    def load(index: int) -> Sweep:
        return read_velodyne_bin(frames[index].points_path)

    return Sequence(id=f"kitti_tracking_{name}", root=root, format="kitti_tracking", frames=frames, load_sweep=load,
                    ego_from_lidar=np.eye(4), cameras=cameras, annotations=annotations)


# --------------------------------------------------------------------------------------- object

def _object_root(path: Path) -> Path | None:
    for candidate in (path, path / "lidar" / "training", path / "training"):
        if (candidate / "calib").is_dir() and any((candidate / "velodyne").glob("*.bin")):
            return candidate
    return None


def is_kitti_object(path: str | Path) -> bool:
    path = Path(path)
    return path.is_dir() and _object_root(path) is not None


def _vod_world_from_ego(path: Path, calib: KittiCalib) -> np.ndarray:
    lines = [line for line in read_text_lines(path) if line.strip()]
    try:
        docs = [json.loads(line) for line in lines]
        odom_from_camera = np.array(next(d["odomToCamera"] for d in docs if "odomToCamera" in d), dtype=np.float64)
    except (json.JSONDecodeError, StopIteration, TypeError, ValueError) as exc:
        raise InputError(path, f"expected JSON lines with an 'odomToCamera' 4x4 ({type(exc).__name__})") from exc
    if odom_from_camera.shape != (16,) or not np.isfinite(odom_from_camera).all():
        raise InputError(path, "'odomToCamera' must be 16 finite numbers")
    return _orthonormal(odom_from_camera.reshape(4, 4) @ _rigid(calib.get("Tr_velo_to_cam"), False))


def read_kitti_object(path: str | Path) -> Sequence:
    """Open a KITTI object-layout folder (every velodyne file one frame; View-of-Delft when ``pose/`` exists)."""
    path = Path(path)
    root = _object_root(path)
    if root is None:
        raise InputError(path, "not a KITTI object layout (velodyne/*.bin and calib/)")
    sweeps = _numbered(root / "velodyne", (".bin",))
    numbers = sorted(sweeps)
    vod = (root / "pose").is_dir()
    calibs = [read_calib(root / "calib" / f"{sweeps[f].stem}.txt") for f in numbers]
    if vod:
        world_from_ego = [_vod_world_from_ego(root / "pose" / f"{sweeps[f].stem}.json", c)
                          for f, c in zip(numbers, calibs, strict=True)]
    else:
        world_from_ego = [np.eye(4) for _ in numbers]
    times = [f * FRAME_DT_NS for f in numbers]
    frames = [FrameInfo(index=k, timestamp_ns=times[k], world_from_ego=world_from_ego[k], points_path=sweeps[f])
              for k, f in enumerate(numbers)]
    annotations = None
    if (root / "label_2").is_dir():
        annotations = []
        for k, f in enumerate(numbers):
            label_path = root / "label_2" / f"{sweeps[f].stem}.txt"
            boxes = []
            lines = read_text_lines(label_path) if label_path.is_file() else []
            for n, line in enumerate(lines, start=1):
                label = parse_label_line(line, label_path, n, tracking=False) if line.strip() else None
                if label is not None:
                    box = label_box_in_velo(label, calibs[k], vod=vod).transformed(world_from_ego[k], keep_tilt=True)
                    boxes.append(BoxAnnotation(track_id=f"{sweeps[f].stem}-{len(boxes)}", label=label["type"], box=box))
            annotations.append(boxes)
    images = _numbered(root / "image_2", (".png", ".jpg"))
    cameras = {"image_2": _camera(calibs[0], "image_2", images, numbers, times, world_from_ego)} if numbers else {}

    def load(index: int) -> Sweep:
        return read_velodyne_bin(frames[index].points_path)

    return Sequence(id=path.resolve().name, root=root,
                    format="kitti_object", frames=frames, load_sweep=load, ego_from_lidar=np.eye(4), cameras=cameras,
                    annotations=annotations)
