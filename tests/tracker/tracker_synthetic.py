"""A synthetic LiDAR sequence with a known rigid vehicle trajectory (numpy only).

The vehicle is a car-like solid (a body box with a cabin box on top, set back from the front) whose
surfaces are sampled with points (80 per m^2: ~1000 points per view, like the near cars of PandaSet
002); only faces turned towards the sensor are kept (a convex-part visibility model of a LiDAR view). Ground points (optionally sloped) surround it; the ego moves along +x.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracker.frames import LidarFrame
from tracker.geometry import Box, invert_transform, make_transform, rotation_z, transform_points

# parts in the object frame: (centre, size); the box of the whole car is 4.5 x 1.8 x 1.5 centred at 0
BOX_SIZE = (4.5, 1.8, 1.5)
PARTS = (
    (np.array([0.0, 0.0, -0.3]), np.array([4.5, 1.8, 0.9])),     # body: z in [-0.75, 0.15]
    (np.array([-0.4, 0.0, 0.45]), np.array([2.4, 1.6, 0.6])),    # cabin: z in [0.15, 0.75]
)


def car_points(rng: np.random.Generator, box: Box, sensor: np.ndarray, per_m2: float = 80.0,
               lidar_density: float = 0.0) -> np.ndarray:
    """World points on the faces of the car's parts that face ``sensor``. ``lidar_density`` > 0: as a LiDAR
    samples them instead, lidar_density x cos(incidence) / range^2 points per m^2 of each face (from its
    centre): a face seen at a grazing angle or far away gets few points."""
    out = []
    world_from_object = box.world_from_object()
    sensor_obj = transform_points(invert_transform(world_from_object), sensor[None])[0]
    for centre, size in PARTS:
        half = size / 2.0
        for axis in range(3):
            for sign in (-1.0, 1.0):
                if axis == 2 and sign < 0:
                    continue  # the underside is never seen
                face_centre = centre.copy()
                face_centre[axis] += sign * half[axis]
                if sign * (sensor_obj[axis] - face_centre[axis]) <= 0:
                    continue
                others = [a for a in range(3) if a != axis]
                area = size[others[0]] * size[others[1]]
                density = per_m2
                if lidar_density > 0:
                    ray = sensor_obj - face_centre
                    distance = float(np.linalg.norm(ray))
                    density = lidar_density * abs(ray[axis]) / distance ** 3
                n = int(rng.poisson(area * density))
                n = max(1, n) if lidar_density <= 0 else n
                pts = np.repeat(face_centre[None], n, axis=0)
                for a in others:
                    pts[:, a] += rng.uniform(-half[a], half[a], n)
                out.append(pts)
    pts = np.vstack(out) if out else np.zeros((0, 3))
    # points hidden inside the other part (body top under the cabin) are dropped
    keep = np.ones(len(pts), dtype=bool)
    for centre, size in PARTS:
        inside = np.all(np.abs(pts - centre) < size / 2.0 - 1e-6, axis=1)
        keep &= ~inside
    return transform_points(world_from_object, pts[keep])


def ground_points(rng: np.random.Generator, centre_xy: np.ndarray, half: float, slope: float = 0.0,
                  per_m2: float = 8.0, ground_z: float = -0.75) -> np.ndarray:
    """Ground around ``centre_xy``: z = ground_z + slope * x."""
    n = int((2 * half) ** 2 * per_m2)
    xy = centre_xy + rng.uniform(-half, half, (n, 2))
    z = ground_z + slope * xy[:, 0] + rng.normal(0.0, 0.02, n)
    return np.column_stack([xy, z])


def trajectory(n_frames: int, speed: float = 1.0, yaw_rate: float = 0.06, turn_after: int = 10,
               ramp_frames: int = 4, start: tuple[float, float, float] = (12.0, 4.0, 0.3)) -> list[Box]:
    """Constant velocity along the heading, then a turn: the yaw rate ramps up over ``ramp_frames``
    (steering takes a moment, as in a real turn) to ``yaw_rate`` per frame (0.06 rad/frame = 34 deg/s)."""
    x, y, heading = start
    boxes = []
    for k in range(n_frames):
        boxes.append(Box(x, y, 0.0, heading, *BOX_SIZE))
        if k >= turn_after:
            heading += yaw_rate * min(1.0, (k - turn_after + 1) / max(ramp_frames, 1))
        x += speed * np.cos(heading)
        y += speed * np.sin(heading)
    return boxes


@dataclass
class SyntheticSequence:
    """A FrameSource with known boxes."""

    frames: list[LidarFrame]
    boxes: list[Box]

    def __len__(self) -> int:
        return len(self.frames)

    def lidar_frame(self, index: int) -> LidarFrame:
        return self.frames[index]


def make_sequence(n_frames: int = 24, seed: int = 0, noise: float = 0.01, ego_speed: float = 0.5,
                  empty_frames: tuple[int, ...] = (), nan_frames: tuple[int, ...] = (),
                  boxes: list[Box] | None = None, lidar_density: float = 0.0, ego_yaw_rate: float = 0.02
                  ) -> SyntheticSequence:
    """``boxes``: the vehicle's trajectory (default: ``trajectory(n_frames)``); ``lidar_density``: see
    :func:`car_points`; ``ego_yaw_rate``: the ego's turn per frame (rad)."""
    rng = np.random.default_rng(seed)
    boxes = trajectory(n_frames) if boxes is None else boxes
    frames = []
    for k, box in enumerate(boxes):
        world_from_ego = make_transform(rotation_z(ego_yaw_rate * k), np.array([ego_speed * k, 0.0, 1.0]))
        sensor = world_from_ego[:3, 3]
        car = car_points(rng, box, sensor, lidar_density=lidar_density)
        pts = np.vstack([car, ground_points(rng, box.center[:2], 12.0)])
        pts += rng.normal(0.0, noise, pts.shape)
        if k in empty_frames:
            pts = np.zeros((0, 3))
        ego = transform_points(invert_transform(world_from_ego), pts).astype(np.float32)
        if k in nan_frames:
            ego[::7] = np.nan
        frames.append(LidarFrame(index=k, timestamp_ns=1_000_000_000 + k * 100_000_000, points_ego=ego,
                                 world_from_ego=world_from_ego))
    return SyntheticSequence(frames, boxes)
