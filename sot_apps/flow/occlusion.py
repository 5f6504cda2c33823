"""Occluders from the frame's LiDAR points: a densified depth map in camera pixels.

The points are projected with a z-buffer (nearest depth per pixel) and densified with a min
filter (grey erosion) of ``dilate_px`` pixels: the Pandar64's beams are about 0.2 deg apart, i.e.
6-7 px at PandaSet's focal length, so a 7 px window closes the gaps between neighbouring returns.
Points inside tracked objects and ground points (below the object's bottom + ``ground_clearance``)
are not occluders of that object.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .camera import CameraModel, apply_transform, project

__all__ = ["ProjectedPoints", "project_lidar", "depth_map", "lookup_depth", "NO_DEPTH"]

NO_DEPTH = np.float32(1e9)


@dataclass(frozen=True)
class ProjectedPoints:
    """LiDAR points seen by a camera: pixel coordinates (N, 2), depth (N,), world height (N,)."""

    uv: np.ndarray
    depth: np.ndarray
    world_z: np.ndarray

    @classmethod
    def empty(cls) -> "ProjectedPoints":
        return cls(np.zeros((0, 2)), np.zeros(0), np.zeros(0))


def project_lidar(points_world: np.ndarray, camera_from_world: np.ndarray, model: CameraModel,
                  min_depth: float = 0.5) -> ProjectedPoints:
    """Project world points into the image; keeps those in front of the camera and inside the image."""
    pts = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
    cam = apply_transform(camera_from_world, pts)
    front = cam[:, 2] > min_depth
    uv, depth = project(cam[front], model)
    inside = (uv[:, 0] > -0.5) & (uv[:, 0] < model.width - 0.5) & (uv[:, 1] > -0.5) & (uv[:, 1] < model.height - 0.5)
    return ProjectedPoints(uv[inside], depth[inside], pts[front][inside, 2])


def depth_map(points: ProjectedPoints, roi: tuple[int, int, int, int], dilate_px: int = 7,
              min_world_z: float = -np.inf) -> np.ndarray:
    """Densified LiDAR depth (float32, NO_DEPTH where empty) over ``roi`` = (x0, y0, x1, y1)."""
    x0, y0, x1, y1 = roi
    h, w = y1 - y0, x1 - x0
    out = np.full((max(h, 0), max(w, 0)), NO_DEPTH, dtype=np.float32)
    if h <= 0 or w <= 0 or len(points.depth) == 0:
        return out
    pix = np.rint(points.uv).astype(np.int64)
    sel = ((pix[:, 0] >= x0) & (pix[:, 0] < x1) & (pix[:, 1] >= y0) & (pix[:, 1] < y1)
           & (points.world_z > min_world_z))
    if not sel.any():
        return out
    flat = (pix[sel, 1] - y0) * w + (pix[sel, 0] - x0)
    np.minimum.at(out.reshape(-1), flat, points.depth[sel].astype(np.float32))
    if dilate_px > 1:
        out = cv2.erode(out, np.ones((dilate_px, dilate_px), np.uint8), borderType=cv2.BORDER_CONSTANT,
                        borderValue=float(NO_DEPTH))
    return out


def lookup_depth(depth: np.ndarray, roi: tuple[int, int, int, int], uv: np.ndarray) -> np.ndarray:
    """Depth-map values at pixel coordinates ``uv`` (rounded; integer pixels are used as they are); NO_DEPTH
    outside the ROI (and for NaN coordinates)."""
    x0, y0, x1, y1 = roi
    uv = np.asarray(uv)
    u, v = uv[:, 0], uv[:, 1]
    if uv.dtype.kind not in "iu":   # each column rounded on its own (contiguous: faster comparisons below)
        u, v = np.rint(u), np.rint(v)   # a NaN stays NaN and fails every comparison: outside
    inside = np.flatnonzero((u >= x0) & (u < x1) & (v >= y0) & (v < y1))
    out = np.full(len(uv), NO_DEPTH, dtype=np.float32)
    if len(inside):
        # u, v are whole numbers inside the ROI here: the integer conversion is exact
        flat = (v[inside].astype(np.int64) - y0) * (x1 - x0) + (u[inside].astype(np.int64) - x0)
        out[inside] = np.ascontiguousarray(depth).reshape(-1)[flat]
    return out
