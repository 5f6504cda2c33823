"""An independent writer of small Waymo v1 (TFRecord) and v2 (parquet) files from an analytic scene.

It shares no code with ``sot_apps.io.waymo``: its own protobuf wire encoder, CRC32C, range image
encoder (ray casting against planes) and Euler rotations, all written from the format's
documentation. Each writer returns the ground truth: points in the frame's ego frame, world boxes,
camera poses.

Scene (world frame): a ground plane through the first frame's ego origin, a wall 25 m ahead of the
first frame's ego and a second wall 32 m ahead; a ray that first hits the near wall also gets a
second return from whatever it hits next.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field

import numpy as np

# ----------------------------------------------------------------------------- protobuf wire encoding


def varint(value: int) -> bytes:
    value &= (1 << 64) - 1
    out = bytearray()
    while True:
        byte = value & 0x7F
        value >>= 7
        if value:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


def f_varint(number: int, value: int) -> bytes:
    return varint(number << 3) + varint(int(value))


def f_double(number: int, value: float) -> bytes:
    return varint(number << 3 | 1) + struct.pack("<d", float(value))


def f_bytes(number: int, data: bytes) -> bytes:
    return varint(number << 3 | 2) + varint(len(data)) + data


def f_doubles(number: int, values) -> bytes:
    """Repeated double, unpacked (proto2's default)."""
    return b"".join(f_double(number, v) for v in values)


def transform_msg(matrix: np.ndarray) -> bytes:
    return f_doubles(1, np.asarray(matrix, dtype=np.float64).reshape(16))


def matrix_float(array: np.ndarray) -> bytes:
    """zlib(serialized MatrixFloat{data = 1 packed float, shape = 2 {dims = 1}})."""
    array = np.asarray(array, dtype=np.float32)
    shape = b"".join(f_varint(1, d) for d in array.shape)
    return zlib.compress(f_bytes(1, array.astype("<f4").tobytes()) + f_bytes(2, shape))


# ----------------------------------------------------------------------------- TFRecord framing

_TABLE = []
for _n in range(256):
    _c = _n
    for _ in range(8):
        _c = (_c >> 1) ^ 0x82F63B78 if _c & 1 else _c >> 1
    _TABLE.append(_c)


def crc32c(data: bytes) -> int:
    crc = 0xFFFFFFFF
    table = _TABLE
    for byte in data:
        crc = table[(crc ^ byte) & 0xFF] ^ (crc >> 8)
    return crc ^ 0xFFFFFFFF


def masked(crc: int) -> int:
    return ((((crc >> 15) | (crc << 17)) & 0xFFFFFFFF) + 0xA282EAD8) & 0xFFFFFFFF


def tfrecord(payloads: list[bytes]) -> bytes:
    out = bytearray()
    for payload in payloads:
        length = struct.pack("<Q", len(payload))
        out += length + struct.pack("<I", masked(crc32c(length))) + payload
        out += struct.pack("<I", masked(crc32c(payload)))
    return bytes(out)


# ----------------------------------------------------------------------------- geometry


def rot_x(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def rigid(rotation: np.ndarray, translation) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = rotation
    m[:3, 3] = translation
    return m


@dataclass(frozen=True)
class Lidar:
    code: int                      # LaserName: TOP = 1, FRONT = 2
    height: int
    width: int
    vehicle_from_lidar: np.ndarray
    inclinations: np.ndarray | None  # per beam, increasing; None = uniform between min and max
    inc_min: float
    inc_max: float
    pixel_poses: bool              # the TOP lidar's per-pixel vehicle poses

    def row_inclinations(self) -> np.ndarray:
        """Row 0 = highest beam (documented convention)."""
        if self.inclinations is not None:
            return np.sort(self.inclinations)[::-1]
        step = (self.inc_max - self.inc_min) / self.height
        return self.inc_max - step * (np.arange(self.height) + 0.5)

    def column_azimuths(self) -> np.ndarray:
        """Column c looks at pi*(W - 2c - 1)/W in the vehicle's heading, minus the mounting yaw."""
        yaw = np.arctan2(self.vehicle_from_lidar[1, 0], self.vehicle_from_lidar[0, 0])
        return np.pi * (self.width - 2 * np.arange(self.width) - 1) / self.width - yaw


TOP = Lidar(1, 12, 120, rigid(rot_z(0.05) @ rot_y(0.02), [1.4, 0.1, 2.1]),
            np.array([-0.30, -0.26, -0.21, -0.17, -0.14, -0.11, -0.08, -0.06, -0.04, -0.02, 0.0, 0.04]),
            -0.30, 0.04, True)
FRONT = Lidar(2, 6, 48, rigid(rot_z(-0.04) @ rot_x(0.01), [3.9, 0.0, 0.8]), None, -0.6, 0.1, False)
LIDARS = (TOP, FRONT)


@dataclass(frozen=True)
class Scene:
    """Planes (point, normal) in the world frame, built from the first frame's pose."""

    planes: list[tuple[np.ndarray, np.ndarray]]

    @classmethod
    def around(cls, world_from_ego0: np.ndarray) -> "Scene":
        r, t = world_from_ego0[:3, :3], world_from_ego0[:3, 3]
        up, forward = np.array([0.0, 0.0, 1.0]), r @ np.array([1.0, 0.0, 0.0])
        return cls([(t.copy(), up), (t + 25.0 * forward, -forward), (t + 32.0 * forward, -forward)])

    def hits(self, origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """(N, len(planes)) ray parameter of each plane hit (inf where none within 0.5..90 m)."""
        out = np.full((len(origin), len(self.planes)), np.inf)
        for j, (point, normal) in enumerate(self.planes):
            denom = direction @ normal
            with np.errstate(divide="ignore", invalid="ignore"):
                t = ((point - origin) @ normal) / denom
            ok = (np.abs(denom) > 1e-9) & (t > 0.5) & (t < 90.0)
            out[ok, j] = t[ok]
        return out


def euler_pose_image(poses: np.ndarray) -> np.ndarray:
    """(H, W, 4, 4) world_from_vehicle -> float32 (H, W, 6) roll, pitch, yaw, x, y, z (R = Rz Ry Rx)."""
    r = poses[..., :3, :3]
    yaw = np.arctan2(r[..., 1, 0], r[..., 0, 0])
    pitch = np.arcsin(-np.clip(r[..., 2, 0], -1, 1))
    roll = np.arctan2(r[..., 2, 1], r[..., 2, 2])
    return np.stack([roll, pitch, yaw, poses[..., 0, 3], poses[..., 1, 3], poses[..., 2, 3]], -1).astype(np.float32)


def pose_from_euler(values: np.ndarray) -> np.ndarray:
    roll, pitch, yaw, x, y, z = (float(v) for v in values)
    return rigid(rot_z(yaw) @ rot_y(pitch) @ rot_x(roll), [x, y, z])


@dataclass
class LidarTruth:
    range_images: list[np.ndarray]          # return 1, return 2: float32 (H, W, 4)
    pose_image: np.ndarray | None           # float32 (H, W, 6) (TOP only)
    points_ego: np.ndarray                  # (N, 3) truth points in the frame's ego frame
    intensity: np.ndarray


def cast_lidar(lidar: Lidar, scene: Scene, world_from_ego: np.ndarray, motion: tuple[float, float]) -> LidarTruth:
    """Range images of ``lidar`` at a frame; with per-pixel poses the vehicle moves ``motion`` =
    (metres forward, radians of yaw) across the scan, centred on the frame pose."""
    h, w = lidar.height, lidar.width
    inc, az = lidar.row_inclinations(), lidar.column_azimuths()
    rows, cols = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    d_lidar = np.stack([np.cos(inc[rows]) * np.cos(az[cols]), np.cos(inc[rows]) * np.sin(az[cols]),
                        np.sin(inc[rows]) * np.ones_like(az[cols])], -1).reshape(-1, 3)
    pose_image = None
    if lidar.pixel_poses:
        frac = (cols.reshape(-1) + 0.5) / w - 0.5
        poses = np.stack([world_from_ego @ rigid(rot_z(motion[1] * f), [motion[0] * f, 0, 0]) for f in frac])
        pose_image = euler_pose_image(poses.reshape(h, w, 4, 4))
        poses = np.stack([pose_from_euler(v) for v in pose_image.reshape(-1, 6)])  # what the file says
    else:
        poses = np.broadcast_to(world_from_ego, (h * w, 4, 4))
    world_from_lidar = poses @ lidar.vehicle_from_lidar
    origin = world_from_lidar[:, :3, 3]
    direction = np.einsum("nij,nj->ni", world_from_lidar[:, :3, :3], d_lidar)
    hits = scene.hits(origin, direction)
    order = np.argsort(hits, axis=1)
    first = np.take_along_axis(hits, order[:, :1], 1)[:, 0]
    second = np.where(order[:, 0] == 1, np.take_along_axis(hits, order[:, 1:2], 1)[:, 0], np.inf)
    images, points, intensities = [], [], []
    ego_from_world = np.linalg.inv(world_from_ego)
    for t in (first, second):
        valid = np.isfinite(t)
        rng = np.where(valid, t, -1.0).astype(np.float32)
        intensity = np.where(valid, 0.01 * np.arange(h * w) % 1.0, 0.0).astype(np.float32)
        image = np.stack([rng, intensity, np.zeros_like(rng), np.zeros_like(rng)], -1).reshape(h, w, 4)
        images.append(image)
        world = origin[valid] + direction[valid] * rng[valid, None].astype(np.float64)
        points.append(world @ ego_from_world[:3, :3].T + ego_from_world[:3, 3])
        intensities.append(intensity[valid])
    return LidarTruth(images, pose_image, np.concatenate(points), np.concatenate(intensities))


# ----------------------------------------------------------------------------- boxes and cameras

@dataclass(frozen=True)
class BoxTruth:
    track_id: str
    type_code: int
    world: tuple[float, float, float, float, float, float, float]  # x, y, z, heading, length, width, height
    ego: tuple[float, float, float, float]                        # x, y, z, heading in the frame's ego frame


def boxes_at(k: int, world_from_ego: np.ndarray, world_from_ego0: np.ndarray) -> list[BoxTruth]:
    """A car driving along the first frame's x axis and a pedestrian crossing, in world coordinates."""
    out = []
    for track_id, type_code, start, velocity, size in (
            ("car-7", 1, (12.0, 3.0, 0.8), (1.5, 0.2), (4.6, 1.9, 1.6)),
            ("ped-2", 2, (9.0, -6.0, 0.9), (0.1, 0.6), (0.7, 0.5, 1.8))):
        local = np.array([start[0] + velocity[0] * k, start[1] + velocity[1] * k, start[2], 1.0])
        centre = world_from_ego0 @ local
        heading = np.arctan2(velocity[1], velocity[0]) + np.arctan2(world_from_ego0[1, 0], world_from_ego0[0, 0])
        ego_centre = np.linalg.solve(world_from_ego, centre)
        ego_heading = heading - np.arctan2(world_from_ego[1, 0], world_from_ego[0, 0])
        ego_heading = (ego_heading + np.pi) % (2 * np.pi) - np.pi
        out.append(BoxTruth(track_id, type_code, (*centre[:3], heading, *size), (*ego_centre[:3], ego_heading)))
    return out


CAMERA_INTRINSIC = [400.0, 410.0, 160.0, 100.0, 0.0, 0.0, 0.0, 0.0, 0.0]  # f_u f_v c_u c_v k1 k2 p1 p2 k3
CAMERA_SIZE = (320, 200)
CAMERA_EXTRINSIC = rigid(rot_z(0.1) @ rot_y(0.05), [1.5, -0.1, 1.6])  # camera -> vehicle, camera x forward


def waymo_project(world_point: np.ndarray, world_from_vehicle: np.ndarray) -> tuple[float, float]:
    """Pixel of a world point in Waymo's camera convention (x forward, y left, z up; no distortion)."""
    p = np.linalg.solve(world_from_vehicle @ CAMERA_EXTRINSIC, np.append(world_point, 1.0))
    f_u, f_v, c_u, c_v = CAMERA_INTRINSIC[:4]
    return c_u - f_u * p[1] / p[0], c_v - f_v * p[2] / p[0]


def jpeg(k: int) -> bytes:
    import cv2

    image = np.full((CAMERA_SIZE[1], CAMERA_SIZE[0], 3), 40 * k % 255, np.uint8)
    ok, data = cv2.imencode(".jpg", image)
    assert ok
    return data.tobytes()


# ----------------------------------------------------------------------------- v1 writer

@dataclass
class SegmentTruth:
    context: str
    timestamps_us: list[int]
    world_from_ego: list[np.ndarray]
    points: dict[int, np.ndarray] = field(default_factory=dict)       # frame -> (N, 3) ego
    intensity: dict[int, np.ndarray] = field(default_factory=dict)
    boxes: dict[int, list[BoxTruth]] = field(default_factory=dict)
    image_times_s: dict[int, float] = field(default_factory=dict)
    image_world_from_vehicle: dict[int, np.ndarray] = field(default_factory=dict)


def synthetic_poses(n: int) -> list[np.ndarray]:
    return [rigid(rot_z(0.4 + 0.02 * k) @ rot_x(0.01), [1200.0 + 1.0 * k, -3400.0 + 0.3 * k, 12.0]) for k in range(n)]


def _lidar_calibration(lidar: Lidar) -> bytes:
    parts = [f_varint(1, lidar.code)]
    if lidar.inclinations is not None:
        parts.append(f_doubles(2, lidar.inclinations))
    parts += [f_double(3, lidar.inc_min), f_double(4, lidar.inc_max), f_bytes(5, transform_msg(lidar.vehicle_from_lidar))]
    return b"".join(parts)


def _camera_calibration() -> bytes:
    return (f_varint(1, 1) + f_doubles(2, CAMERA_INTRINSIC) + f_bytes(3, transform_msg(CAMERA_EXTRINSIC))
            + f_varint(4, CAMERA_SIZE[0]) + f_varint(5, CAMERA_SIZE[1]) + f_varint(6, 2))


def _label(box: BoxTruth) -> bytes:
    x, y, z, heading = box.ego
    length, width, height = box.world[4:]
    msg_box = (f_double(1, x) + f_double(2, y) + f_double(3, z) + f_double(4, width) + f_double(5, length)
               + f_double(6, height) + f_double(7, heading))
    return f_bytes(1, msg_box) + f_varint(3, box.type_code) + f_bytes(4, box.track_id.encode()) + f_varint(7, 123)


def write_v1(path, num_frames: int = 3, motion: tuple[float, float] = (1.0, 0.03),
             context: str = "1234567890_1000_000_1020_000") -> SegmentTruth:
    """A v1 segment: frames with TOP (per-beam inclinations, per-pixel poses) and FRONT (uniform) lidars,
    both returns, two labelled objects and one FRONT camera."""
    poses = synthetic_poses(num_frames)
    scene = Scene.around(poses[0])
    truth = SegmentTruth(context, [1_600_000_000_000_000 + 100_000 * k for k in range(num_frames)], poses)
    records = []
    context_msg = (f_bytes(1, context.encode()) + f_bytes(2, _camera_calibration())
                   + b"".join(f_bytes(3, _lidar_calibration(lidar)) for lidar in LIDARS))
    for k, pose in enumerate(poses):
        lasers, points, intensity = [], [], []
        for lidar in LIDARS:
            cast = cast_lidar(lidar, scene, pose, motion)
            returns = []
            for r, image in enumerate(cast.range_images):
                ri = f_bytes(2, matrix_float(image))
                if r == 0 and cast.pose_image is not None:
                    ri += f_bytes(4, matrix_float(cast.pose_image))
                returns.append(f_bytes(2 + r, ri))
            lasers.append(f_varint(1, lidar.code) + b"".join(returns))
            points.append(cast.points_ego)
            intensity.append(cast.intensity)
        truth.points[k], truth.intensity[k] = np.concatenate(points), np.concatenate(intensity)
        truth.boxes[k] = boxes_at(k, pose, poses[0])
        image_time = truth.timestamps_us[k] * 1e-6 + 0.05
        image_pose = pose @ rigid(np.eye(3), [0.5, 0.0, 0.0])
        truth.image_times_s[k], truth.image_world_from_vehicle[k] = image_time, image_pose
        image = (f_varint(1, 1) + f_bytes(2, jpeg(k)) + f_bytes(3, transform_msg(image_pose)) + f_double(5, image_time)
                 + f_double(6, 0.002) + f_double(7, image_time - 0.01) + f_double(8, image_time + 0.02))
        frame = (f_bytes(1, context_msg) + f_varint(2, truth.timestamps_us[k]) + f_bytes(3, transform_msg(pose))
                 + f_bytes(4, image) + b"".join(f_bytes(5, laser) for laser in lasers)
                 + b"".join(f_bytes(6, _label(b)) for b in truth.boxes[k]))
        records.append(frame)
    with open(path, "wb") as handle:
        handle.write(tfrecord(records))
    return truth


# ----------------------------------------------------------------------------- v2 writer

def write_v2(root, vehicle_pose_parquet, lidar_frames=(0, 1, 50), camera_frames: int = 2,
             motion: tuple[float, float] = (1.0, 0.03)) -> SegmentTruth:
    """v2 component files under ``root`` for the segment of a REAL ``vehicle_pose`` parquet: its poses
    are the trajectory; lidar, lidar_pose, lidar_calibration, lidar_box at ``lidar_frames``; camera
    images at frames 0..camera_frames-1."""
    import shutil

    import pyarrow as pa
    import pyarrow.parquet as pq

    root = __import__("pathlib").Path(root)
    segment = __import__("pathlib").Path(vehicle_pose_parquet).stem
    (root / "vehicle_pose").mkdir(parents=True, exist_ok=True)
    shutil.copyfile(vehicle_pose_parquet, root / "vehicle_pose" / f"{segment}.parquet")
    table = pq.read_table(vehicle_pose_parquet)
    stamps = np.asarray(table.column("key.frame_timestamp_micros").to_pylist(), dtype=np.int64)
    order = np.argsort(stamps)
    transforms = table.column("[VehiclePoseComponent].world_from_vehicle.transform").to_pylist()
    poses = [np.asarray(transforms[i], dtype=np.float64).reshape(4, 4) for i in order]
    stamps = [int(stamps[i]) for i in order]
    truth = SegmentTruth(segment, stamps, poses)
    scene = Scene.around(poses[0])

    def write(component: str, columns: dict) -> None:
        (root / component).mkdir(parents=True, exist_ok=True)
        n = len(next(iter(columns.values())))
        pq.write_table(pa.table({"key.segment_context_name": [segment] * n, **columns}),
                       root / component / f"{segment}.parquet")

    lidar_rows = {"key.frame_timestamp_micros": [], "key.laser_name": []}
    for r in (1, 2):
        lidar_rows[f"[LiDARComponent].range_image_return{r}.values"] = []
        lidar_rows[f"[LiDARComponent].range_image_return{r}.shape"] = []
    pose_rows = {"key.frame_timestamp_micros": [], "key.laser_name": [],
                 "[LiDARPoseComponent].range_image_return1.values": [],
                 "[LiDARPoseComponent].range_image_return1.shape": []}
    box_rows: dict[str, list] = {k: [] for k in ["key.frame_timestamp_micros", "key.laser_object_id"] + [
        f"[LiDARBoxComponent].{f}" for f in ("box.center.x", "box.center.y", "box.center.z", "box.size.x", "box.size.y",
                                             "box.size.z", "box.heading", "type", "num_lidar_points_in_box")]}
    for k in lidar_frames:
        points, intensity = [], []
        for lidar in LIDARS:
            cast = cast_lidar(lidar, scene, poses[k], motion)
            lidar_rows["key.frame_timestamp_micros"].append(stamps[k])
            lidar_rows["key.laser_name"].append(lidar.code)
            for r, image in enumerate(cast.range_images, start=1):
                lidar_rows[f"[LiDARComponent].range_image_return{r}.values"].append(image.reshape(-1).tolist())
                lidar_rows[f"[LiDARComponent].range_image_return{r}.shape"].append(list(image.shape))
            if cast.pose_image is not None:
                pose_rows["key.frame_timestamp_micros"].append(stamps[k])
                pose_rows["key.laser_name"].append(lidar.code)
                pose_rows["[LiDARPoseComponent].range_image_return1.values"].append(cast.pose_image.reshape(-1).tolist())
                pose_rows["[LiDARPoseComponent].range_image_return1.shape"].append(list(cast.pose_image.shape))
            points.append(cast.points_ego)
            intensity.append(cast.intensity)
        truth.points[k], truth.intensity[k] = np.concatenate(points), np.concatenate(intensity)
        truth.boxes[k] = boxes_at(k, poses[k], poses[0])
        for b in truth.boxes[k]:
            values = (*b.ego[:3], *b.world[4:], b.ego[3], b.type_code, 55)
            box_rows["key.frame_timestamp_micros"].append(stamps[k])
            box_rows["key.laser_object_id"].append(b.track_id)
            for name, v in zip(list(box_rows)[2:], values, strict=True):
                box_rows[name].append(v)
    f32 = pa.list_(pa.float32())
    write("lidar", {k: (pa.array(v, f32) if k.endswith("values") else v) for k, v in lidar_rows.items()})
    write("lidar_pose", {k: (pa.array(v, f32) if k.endswith("values") else v) for k, v in pose_rows.items()})
    write("lidar_box", box_rows)
    write("lidar_calibration", {
        "key.laser_name": [lidar.code for lidar in LIDARS],
        "[LiDARCalibrationComponent].extrinsic.transform": [lidar.vehicle_from_lidar.reshape(-1).tolist() for lidar in LIDARS],
        "[LiDARCalibrationComponent].beam_inclination.min": [lidar.inc_min for lidar in LIDARS],
        "[LiDARCalibrationComponent].beam_inclination.max": [lidar.inc_max for lidar in LIDARS],
        "[LiDARCalibrationComponent].beam_inclination.values": pa.array(
            [None if lidar.inclinations is None else lidar.inclinations.tolist() for lidar in LIDARS],
            pa.list_(pa.float64()))})
    names = ["f_u", "f_v", "c_u", "c_v", "k1", "k2", "p1", "p2", "k3"]
    write("camera_calibration", {
        "key.camera_name": [1],
        **{f"[CameraCalibrationComponent].intrinsic.{n}": [v] for n, v in zip(names, CAMERA_INTRINSIC, strict=True)},
        "[CameraCalibrationComponent].extrinsic.transform": [CAMERA_EXTRINSIC.reshape(-1).tolist()],
        "[CameraCalibrationComponent].width": [CAMERA_SIZE[0]], "[CameraCalibrationComponent].height": [CAMERA_SIZE[1]],
        "[CameraCalibrationComponent].rolling_shutter_direction": [2]})
    images = {"key.frame_timestamp_micros": [], "key.camera_name": [], "[CameraImageComponent].image": [],
              "[CameraImageComponent].pose.transform": [], "[CameraImageComponent].pose_timestamp": []}
    for k in range(camera_frames):
        truth.image_times_s[k] = stamps[k] * 1e-6 + 0.05
        truth.image_world_from_vehicle[k] = poses[k]
        images["key.frame_timestamp_micros"].append(stamps[k])
        images["key.camera_name"].append(1)
        images["[CameraImageComponent].image"].append(jpeg(k))
        images["[CameraImageComponent].pose.transform"].append(poses[k].reshape(-1).tolist())
        images["[CameraImageComponent].pose_timestamp"].append(truth.image_times_s[k])
    write("camera_image", images)
    return truth
