"""KITTI flow PNGs: 16-bit, 3 channels (R, G, B) = (u, v, valid), value = flow * 64 + 2**15.

OpenCV reads and writes BGR, so the array handed to cv2 is ``[valid, v, u]``. Flow is rounded to
1/64 px and clipped to the representable range (-512, +512) px. Invalid pixels store u = v = 0
(i.e. 2**15) and valid = 0.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError
from ..io.atomic import write_bytes
from .png import encode_rows_png

__all__ = ["encode_kitti_flow", "decode_kitti_flow", "kitti_flow_png", "write_kitti_flow", "read_kitti_flow"]

_INVALID_RGB = (2 ** 15, 2 ** 15, 0)   # an invalid pixel in PNG channel order (u, v, valid)


def _kitti_values(flow: np.ndarray) -> np.ndarray:
    """(..., 2) flow -> (..., 2) uint16 u, v as stored (1/64 px, offset 2**15, clipped)."""
    return np.clip(np.rint(flow.astype(np.float64) * 64.0 + 2.0 ** 15), 0, 65535).astype(np.uint16)


def encode_kitti_flow(flow: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint16 array in cv2 (BGR) order: [valid, v, u]."""
    flow = np.asarray(flow)
    valid = np.asarray(valid, dtype=bool)
    out = np.zeros(flow.shape[:2] + (3,), dtype=np.uint16)
    out[..., 1:] = 2 ** 15
    valid = valid & np.isfinite(flow).all(axis=-1)
    vs, us = np.nonzero(valid)
    scaled = _kitti_values(flow[vs, us])
    out[vs, us, 0] = 1
    out[vs, us, 1] = scaled[:, 1]
    out[vs, us, 2] = scaled[:, 0]
    return out


def decode_kitti_flow(bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`encode_kitti_flow`: ((H, W, 2) float32 flow (u, v), (H, W) bool valid)."""
    bgr = np.asarray(bgr)
    flow = (np.stack([bgr[..., 2], bgr[..., 1]], axis=-1).astype(np.float32) - 2.0 ** 15) / 64.0
    valid = bgr[..., 0] > 0
    flow[~valid] = 0.0
    return flow, valid


def kitti_flow_png(flow: np.ndarray, valid: np.ndarray) -> bytes:
    """The KITTI flow PNG's bytes (decoded: exactly :func:`encode_kitti_flow`). Only the rows that hold valid
    pixels are encoded (:mod:`.png`), so the cost follows the object pixels, not the image size."""
    flow = np.asarray(flow)
    valid = np.asarray(valid, dtype=bool)
    rows = np.flatnonzero(valid.any(axis=1))
    candidates = np.flatnonzero(valid[rows])           # flat indices into the (len(rows), W) block
    values = flow[rows].reshape(-1, 2)[candidates]
    finite = np.isfinite(values).all(axis=1)
    candidates, values = candidates[finite], values[finite]
    pixels = np.empty((len(rows), flow.shape[1], 3), dtype=np.uint16)
    pixels[:] = _INVALID_RGB                            # invalid pixels: u = v = 0 px, valid = 0
    flat = pixels.reshape(-1, 3)
    flat[candidates, :2] = _kitti_values(values)
    flat[candidates, 2] = 1
    row_valid = np.zeros(pixels.shape[:2], dtype=bool)
    row_valid.reshape(-1)[candidates] = True
    return encode_rows_png(pixels, rows, flow.shape[0], _INVALID_RGB, row_valid)


def write_kitti_flow(path: str | Path, flow: np.ndarray, valid: np.ndarray) -> None:
    write_bytes(path, kitti_flow_png(flow, valid))


def read_kitti_flow(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    with open(path, "rb") as handle:   # not cv2.imread: any path the OS takes (non-UTF-8 names too)
        image = cv2.imdecode(np.frombuffer(handle.read(), np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None or image.dtype != np.uint16 or image.ndim != 3 or image.shape[2] != 3:
        raise InputError(path, "not a 16-bit 3-channel KITTI flow PNG")
    return decode_kitti_flow(image)
