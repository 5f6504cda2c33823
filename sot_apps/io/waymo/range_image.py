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

import numpy as np
from scipy.spatial.transform import Rotation

from .wire import WireError, fields, varint

__all__ = ["decode_matrix_float", "row_inclinations", "column_azimuths", "range_image_points"]


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


def range_image_points(image: np.ndarray, vehicle_from_lidar: np.ndarray, inclinations: np.ndarray,
                       pixel_pose: np.ndarray | None = None,
                       vehicle_from_world: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 3) float64 in the frame's vehicle frame and their intensities (N,) float32.

    ``pixel_pose`` ([H, W, 6], TOP lidar) moves each point with the vehicle pose of its own pixel and
    then into the frame's vehicle frame with ``vehicle_from_world`` (inverse of the frame pose).
    """
    height, width = image.shape[:2]
    rng = image[..., 0].astype(np.float64)
    rows, cols = np.nonzero(rng > 0)
    r = rng[rows, cols]
    inc = inclinations[rows]
    az = column_azimuths(width, vehicle_from_lidar)[cols]
    cos_inc = np.cos(inc)
    lidar = np.stack([r * cos_inc * np.cos(az), r * cos_inc * np.sin(az), r * np.sin(inc)], axis=1)
    vehicle = lidar @ vehicle_from_lidar[:3, :3].T + vehicle_from_lidar[:3, 3]
    if pixel_pose is not None:
        if pixel_pose.shape[:2] != (height, width):
            raise WireError(f"pixel pose image {pixel_pose.shape} does not match range image {image.shape}")
        if vehicle_from_world is None:
            raise ValueError("vehicle_from_world is needed with a pixel pose")
        pose = pixel_pose[rows, cols].astype(np.float64)
        rotation = Rotation.from_euler("ZYX", pose[:, [2, 1, 0]]).as_matrix()  # Rz(yaw) Ry(pitch) Rx(roll)
        world = np.einsum("nij,nj->ni", rotation, vehicle) + pose[:, 3:6]
        # subtract the translation first: world coordinates are large
        vehicle = (world - vehicle_from_world[:3, :3].T @ -vehicle_from_world[:3, 3]) @ vehicle_from_world[:3, :3].T
    intensity = image[rows, cols, 1].astype(np.float32) if image.shape[2] > 1 else np.zeros(len(r), np.float32)
    return vehicle, intensity
