"""Pinhole camera with OpenCV lens distortion: projection, pixel rays, camera timing.

Pixel convention (OpenCV's): the centre of the pixel in column ``i`` and row ``j`` is at
``(u, v) = (i, j)``. Camera axes: x right, y down, z forward.

``project`` is a vectorised numpy version of ``cv2.projectPoints`` for the distortion vector
``(k1, k2, p1, p2[, k3[, k4, k5, k6]])`` (radial, tangential and rational terms); ``pixel_rays``
inverts it with ``cv2.undistortPoints``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..io.sequence import Camera

__all__ = ["CameraModel", "project", "pixel_rays", "grid_pixels", "apply_transform"]


@dataclass(frozen=True)
class CameraModel:
    """Intrinsics of one camera: 3x3 ``K``, OpenCV ``distortion`` (k1, k2, p1, p2[, k3, ...]), image size."""

    K: np.ndarray
    distortion: np.ndarray
    width: int
    height: int

    @classmethod
    def from_camera(cls, camera: Camera) -> "CameraModel":
        return cls(np.asarray(camera.K, dtype=np.float64), np.asarray(camera.distortion, dtype=np.float64).ravel(),
                   int(camera.width), int(camera.height))

    @property
    def has_distortion(self) -> bool:
        return bool(np.any(self.distortion != 0.0))


def apply_transform(target_from_source: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N, 3) float64 points mapped by a 4x4 transform (cv2.transform: ~10x faster than ``p @ R.T``)."""
    p = np.ascontiguousarray(points, dtype=np.float64).reshape(1, -1, 3)
    if p.shape[1] == 0:
        return np.zeros((0, 3))
    return cv2.transform(p, np.ascontiguousarray(target_from_source[:3], dtype=np.float64)).reshape(-1, 3)


def _coefficients(distortion: np.ndarray) -> np.ndarray:
    d = np.zeros(8)
    dist = np.asarray(distortion, dtype=np.float64).ravel()
    if dist.size > 8:
        raise ValueError("only the distortion terms k1, k2, p1, p2, k3, k4, k5, k6 are supported")
    d[: dist.size] = dist
    return d


def project(points_camera: np.ndarray, model: CameraModel) -> tuple[np.ndarray, np.ndarray]:
    """Project (N, 3) camera-frame points: returns ((N, 2) pixel coordinates, (N,) depth z).

    Points with z <= 0 get NaN pixel coordinates. Matches ``cv2.projectPoints`` (rvec = tvec = 0).
    """
    p = np.asarray(points_camera, dtype=np.float64).reshape(-1, 3)
    z = p[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = p[:, 0] / z
        y = p[:, 1] / z
    k1, k2, p1, p2, k3, k4, k5, k6 = _coefficients(model.distortion)
    if model.has_distortion:
        r2 = x * x + y * y
        radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    else:
        xd, yd = x, y
    K = model.K
    uv = np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=1)
    uv[~(z > 0.0)] = np.nan
    return uv, z


def pixel_rays(uv: np.ndarray, model: CameraModel) -> np.ndarray:
    """(N, 3) ray directions ``(x, y, 1)`` in the camera frame through pixel coordinates ``uv`` (N, 2).

    The z component is 1, so a point at ray parameter ``t`` has depth ``z = t``.
    """
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    if model.has_distortion:
        undist = cv2.undistortPoints(uv.reshape(-1, 1, 2), model.K, model.distortion, None, None, None,
                                     (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12))
        xy = undist.reshape(-1, 2)
    else:
        K = model.K
        y = (uv[:, 1] - K[1, 2]) / K[1, 1]
        x = (uv[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        xy = np.stack([x, y], axis=1)
    return np.concatenate([xy, np.ones((len(xy), 1))], axis=1)


def grid_pixels(x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
    """(M, 2) integer pixel coordinates (u, v) of the rectangle [x0, x1) x [y0, y1), row-major."""
    vs, us = np.mgrid[y0:y1, x0:x1]
    return np.stack([us.ravel(), vs.ravel()], axis=1)
