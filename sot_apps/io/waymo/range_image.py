"""Waymo range images to points (shared by the v1 and v2 readers).

Conventions (Waymo Open Dataset documentation): a range image is [H, W, C] with channels range (m),
intensity, elongation, in-no-label-zone; a pixel with range <= 0 has no return. Row 0 is the beam
with the HIGHEST inclination: the calibration lists inclinations in increasing order, either per
beam or, when the list is empty, uniformly between ``min`` and ``max`` at pixel centres. Column c
looks along azimuth ``pi * (1 - (2c + 1) / W)`` in the vehicle's heading convention, i.e. the lidar
frame's azimuth minus the extrinsic's yaw; column 0 looks backwards (+pi) and azimuth decreases to
the right. A point is ``r (cos i cos a, cos i sin a, sin i)`` in the lidar frame, then
``vehicle_from_lidar`` (the calibration's extrinsic). The TOP lidar's first return carries a
per-pixel pose image [H, W, 6] = (roll, pitch, yaw, x, y, z): world_from_vehicle at that pixel's
capture time, rotation Rz(yaw) Ry(pitch) Rx(roll); the second return shares it.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from .wire import WireError, fields, varint

__all__ = ["decode_matrix_float", "row_inclinations", "column_azimuths", "LaserCalibration", "LidarGeometry",
           "lidar_points", "range_image_points"]


def decode_matrix_float(compressed: bytes) -> np.ndarray:
    """A zlib-compressed serialized MatrixFloat (data = 1 packed float, shape = 2 {dims = 1}) as an array."""
    raw = memoryview(zlib.decompress(compressed))
    data: list[np.ndarray] = []
    dims: list[int] = []
    for number, wire_type, _, start, end in fields(raw):
        if number == 1 and wire_type in (2, 5):  # packed, or one float per field
            data.append(np.frombuffer(raw[start:end], dtype="<f4"))
        elif number == 2 and wire_type == 2:
            for dnum, dtype_, _, ds, de in fields(raw, start, end):
                if dnum == 1 and dtype_ == 0:
                    dims.append(varint(raw, ds, de)[0])
                elif dnum == 1 and dtype_ == 2:  # packed dims
                    pos = ds
                    while pos < de:
                        value, pos = varint(raw, pos, de)
                        dims.append(value)
    values = np.concatenate(data) if data else np.zeros(0, dtype=np.float32)
    if not dims or int(np.prod(dims)) != values.size:
        raise WireError(f"MatrixFloat has {values.size} values but shape {dims}")
    return values.reshape(dims)


@dataclass(frozen=True)
class LaserCalibration:
    """One lidar's calibration: ``vehicle_from_lidar`` and beam inclinations (per beam, or None = uniform)."""

    name: str
    vehicle_from_lidar: np.ndarray
    inclinations: np.ndarray | None
    inclination_min: float
    inclination_max: float

    def rows(self, height: int) -> np.ndarray:
        return row_inclinations(height, self.inclinations, self.inclination_min, self.inclination_max)


def row_inclinations(height: int, inclinations: np.ndarray | None, inc_min: float, inc_max: float) -> np.ndarray:
    """Inclination (rad) of each range image row, row 0 the highest."""
    if inclinations is not None and len(inclinations):
        values = np.asarray(inclinations, dtype=np.float64)
        if values.size != height:
            raise WireError(f"{values.size} beam inclinations for a range image of {height} rows")
    else:
        values = inc_min + (np.arange(height) + 0.5) / height * (inc_max - inc_min)
    return values[::-1].copy()


def column_azimuths(width: int, vehicle_from_lidar: np.ndarray) -> np.ndarray:
    """Azimuth (rad, lidar frame) of each range image column."""
    yaw = np.arctan2(vehicle_from_lidar[1, 0], vehicle_from_lidar[0, 0])
    return np.pi * (1.0 - (2.0 * np.arange(width) + 1.0) / width) - yaw


def _pixel_rotations(pose: np.ndarray) -> np.ndarray:
    """(..., 3, 3) Rz(yaw) Ry(pitch) Rx(roll) from (..., 6) [roll, pitch, yaw, x, y, z]."""
    cr, sr = np.cos(pose[..., 0]), np.sin(pose[..., 0])
    cp, sp = np.cos(pose[..., 1]), np.sin(pose[..., 1])
    cy, sy = np.cos(pose[..., 2]), np.sin(pose[..., 2])
    return np.stack([np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
                     np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
                     np.stack([-sp, cp * sr, cp * cr], -1)], -2)


class LidarGeometry:
    """Everything that maps one lidar's range image pixels to points of a frame, computed once per frame.

    Per pixel: the ray direction in the vehicle frame, and with a pixel pose image the transform from
    that pixel's vehicle frame to the frame's vehicle frame.
    """

    def __init__(self, height: int, width: int, vehicle_from_lidar: np.ndarray, inclinations: np.ndarray,
                 pixel_pose: np.ndarray | None = None, vehicle_from_world: np.ndarray | None = None) -> None:
        self.shape = (height, width)
        inc = np.asarray(inclinations, dtype=np.float64)
        az = column_azimuths(width, vehicle_from_lidar)
        rays = np.stack([np.cos(inc)[:, None] * np.cos(az)[None, :], np.cos(inc)[:, None] * np.sin(az)[None, :],
                         np.broadcast_to(np.sin(inc)[:, None], (height, width))], -1)
        self.directions = rays @ vehicle_from_lidar[:3, :3].T  # (H, W, 3) vehicle frame
        self.origin = vehicle_from_lidar[:3, 3].copy()
        self.rotation = self.translation = None
        if pixel_pose is not None:
            if pixel_pose.shape[:2] != (height, width) or pixel_pose.shape[-1] != 6:
                raise WireError(f"pixel pose image {pixel_pose.shape} does not match range image {self.shape}")
            if vehicle_from_world is None:
                raise ValueError("vehicle_from_world is needed with a pixel pose")
            pose = pixel_pose.astype(np.float64)
            r_frame = vehicle_from_world[:3, :3]
            world_from_frame_t = -r_frame.T @ vehicle_from_world[:3, 3]
            # frame_from_pixel = vehicle_from_world @ world_from_pixel; subtract before rotating (large world values)
            self.rotation = r_frame @ _pixel_rotations(pose)
            self.translation = (pose[..., 3:6] - world_from_frame_t) @ r_frame.T

    def points(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points (N, 3) float64 in the frame's vehicle frame and intensities (N,) float32 of a [H, W, C] image."""
        if image.ndim != 3 or image.shape[:2] != self.shape:
            raise WireError(f"range image of shape {image.shape}, expected [{self.shape[0]}, {self.shape[1]}, 4]")
        rng = image[..., 0]
        rows, cols = np.nonzero(rng > 0)
        r = rng[rows, cols].astype(np.float64)[:, None]
        xyz = self.origin + r * self.directions[rows, cols]
        if self.rotation is not None:
            xyz = np.einsum("nij,nj->ni", self.rotation[rows, cols], xyz) + self.translation[rows, cols]
        intensity = image[rows, cols, 1].astype(np.float32) if image.shape[2] > 1 else np.zeros(len(r), np.float32)
        return xyz, intensity


def range_image_points(image: np.ndarray, vehicle_from_lidar: np.ndarray, inclinations: np.ndarray,
                       pixel_pose: np.ndarray | None = None,
                       vehicle_from_world: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 3) float64 in the frame's vehicle frame and their intensities (N,) float32.

    ``pixel_pose`` ([H, W, 6], TOP lidar) moves each point with the vehicle pose of its own pixel and
    then into the frame's vehicle frame with ``vehicle_from_world`` (inverse of the frame pose).
    """
    return LidarGeometry(image.shape[0], image.shape[1], vehicle_from_lidar, inclinations, pixel_pose,
                         vehicle_from_world).points(image)


def lidar_points(images: list[np.ndarray], calibration: LaserCalibration, pixel_pose: np.ndarray | None,
                 vehicle_from_world: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Points and intensities of each return image of one lidar (all share the pixel geometry)."""
    xyz, intensity = [], []
    geometry = None
    for image in images:
        if image.ndim != 3 or image.shape[2] < 1:
            raise WireError(f"range image of shape {image.shape}, expected [H, W, 4]")
        if geometry is None:
            geometry = LidarGeometry(image.shape[0], image.shape[1], calibration.vehicle_from_lidar,
                                     calibration.rows(image.shape[0]), pixel_pose, vehicle_from_world)
        points, values = geometry.points(image)
        xyz.append(points)
        intensity.append(values)
    return xyz, intensity
