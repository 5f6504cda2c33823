"""Middlebury ``.flo`` files: ``b"PIEH"`` (the float 202021.25), int32 width, int32 height, then
height x width x (u, v) float32, all little-endian. Written and read with numpy (the format is that small), so any
path the OS takes works (``cv2.writeOpticalFlow`` crashes on a non-UTF-8 path); OpenCV's
``cv2.readOpticalFlow`` reads the files back identically (tests).

Pixels without flow hold ``UNKNOWN_FLOW`` (1e10; Middlebury tools treat |value| > 1e9 as unknown).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.atomic import atomic_path

__all__ = ["write_flo", "read_flo", "flo_arrays", "UNKNOWN_FLOW"]

UNKNOWN_FLOW = np.float32(1e10)
_TAG = b"PIEH"


def flo_arrays(flow: np.ndarray, valid: np.ndarray | None = None) -> tuple[bytes, np.ndarray]:
    """(header, (H, W, 2) little-endian float32 data) of the .flo file of ``flow`` (unknown where not ``valid``)."""
    flow = np.asarray(flow)
    if flow.ndim != 3 or flow.shape[2] != 2:
        raise ValueError(f"flow must be (H, W, 2), got {flow.shape}")
    if valid is None:
        data = np.ascontiguousarray(flow, dtype="<f4")
    else:   # fill and scatter the (few) valid pixels, each as one 8-byte item (bits copied as they are)
        data = np.full(flow.shape, UNKNOWN_FLOW, dtype="<f4")
        known = np.flatnonzero(np.asarray(valid, dtype=bool))
        source = np.ascontiguousarray(flow, dtype="<f4").reshape(-1, 2).view(np.uint64).reshape(-1)
        data.reshape(-1, 2).view(np.uint64).reshape(-1)[known] = source[known]
    header = _TAG + np.array([flow.shape[1], flow.shape[0]], dtype="<i4").tobytes()
    return header, data


def write_flo(path: str | Path, flow: np.ndarray, valid: np.ndarray | None = None) -> None:
    header, data = flo_arrays(flow, valid)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            handle.write(header)
            handle.write(memoryview(data).cast("B"))   # no copy of the 16 MB
            handle.flush()
            os.fsync(handle.fileno())


def read_flo(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """((H, W, 2) float32 flow with unknown pixels set to 0, (H, W) bool known)."""
    try:
        with open(path, "rb") as handle:
            raw = handle.read()
    except IsADirectoryError:
        raise InputError(path, "not a Middlebury .flo file (a directory)") from None
    if len(raw) < 12 or raw[:4] != _TAG:
        raise InputError(path, "not a Middlebury .flo file")
    width, height = (int(v) for v in np.frombuffer(raw, dtype="<i4", count=2, offset=4))
    if width <= 0 or height <= 0 or len(raw) != 12 + 8 * width * height:
        raise InputError(path, f"not a Middlebury .flo file ({width}x{height} does not match {len(raw)} bytes)")
    flow = np.frombuffer(raw, dtype="<f4", offset=12).reshape(height, width, 2).astype(np.float32)
    known = (np.abs(flow) < 1e9).all(axis=-1)
    flow[~known] = 0.0
    return flow, known
