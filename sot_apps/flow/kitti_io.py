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

__all__ = ["encode_kitti_flow", "decode_kitti_flow", "write_kitti_flow", "read_kitti_flow"]


def encode_kitti_flow(flow: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint16 array in cv2 (BGR) order: [valid, v, u]."""
    flow = np.asarray(flow)
    valid = np.asarray(valid, dtype=bool)
    out = np.zeros(flow.shape[:2] + (3,), dtype=np.uint16)
    out[..., 1:] = 2 ** 15
    values = flow[valid].astype(np.float64)
    finite = np.isfinite(values).all(axis=1)
    vs, us = np.nonzero(valid)
    vs, us, values = vs[finite], us[finite], values[finite]
    scaled = np.clip(np.rint(values * 64.0 + 2.0 ** 15), 0, 65535).astype(np.uint16)
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


def write_kitti_flow(path: str | Path, flow: np.ndarray, valid: np.ndarray) -> None:
    ok, data = cv2.imencode(".png", encode_kitti_flow(flow, valid))
    if not ok:
        raise RuntimeError(f"cannot encode {path}")
    write_bytes(path, data.tobytes())


def read_kitti_flow(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None or image.dtype != np.uint16 or image.ndim != 3 or image.shape[2] != 3:
        raise InputError(path, "not a 16-bit 3-channel KITTI flow PNG")
    return decode_kitti_flow(image)
